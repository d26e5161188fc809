"""Write ``docs/cli.md``, the command reference, from the parser itself: each command's
purpose and examples (below, :data:`COMMANDS`) and its ``--help`` (and its subcommands'),
as ``raplas-hdl`` prints it at 100 columns.

Usage::

    python tools/cli_reference.py            # rewrite docs/cli.md
    python tools/cli_reference.py --check    # exit 1 if docs/cli.md is not what --help gives

``tests/project/test_cli_reference.py`` runs the check, so the reference cannot drift from
``--help``.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "cli.md"
WIDTH = 100

#: Per command: what it is for (Markdown) and example command lines.
COMMANDS = {
    "demo": (
        "The main job (`make demo`): emits the Verilog of every unit into `build/verilog/` "
        "(with manifests) and renders the default scene, a Cornell box with 3x3 soft-shadow "
        "bundles, through the FP24 golden model and the float64 reference, with the "
        "difference image and a JSON summary under `build/demo/`.",
        ["raplas-hdl demo", "raplas-hdl demo --size 128x128 --scene stanford-bunny"]),
    "verilog": (
        "Deterministic Verilog of a unit plus a JSON manifest (ports, widths, latency, "
        "parameters). An option the unit does not take is an error; `--help` gives each "
        "option's range and default per unit. `--target virtex4` builds the significand "
        "multiplies as Virtex-4 `DSP48` primitives (one cycle more per multiply at FP24, "
        "`latency` says so), `--adder virtex4` every FP adder of a unit on two DSP48; both "
        "co-simulate bit-exact with Yosys's `DSP48` model. `board-top` is the intersection "
        "unit behind a 32-bit Wishbone slave ([board-top.md](board-top.md)).",
        ["raplas-hdl verilog fp-add --format FP24/rne -o build/fp_add.v",
         "raplas-hdl verilog ray-triangle --mode certified -o build/rt.v",
         "raplas-hdl verilog intersection-unit --rows 8 --cols 8 --reduce -o build/iu.v"]),
    "cosim": (
        "Co-simulation of a unit against the golden model at full clock rate in a generated "
        "harness (Icarus or Verilator): prints cases, mismatches field by field and cases "
        "per second, and exits non-zero on any mismatch. A vectors file "
        "([cosim.md](cosim.md)) is checked whole, its header's unit, format and parameters "
        "included, before the simulator starts; `--waves` writes an FST.",
        ["raplas-hdl cosim fp-mul --sim verilator --random 100000",
         "raplas-hdl cosim ray-triangle --sim icarus --mode certified --random 2000",
         "raplas-hdl cosim intersection-unit --sim verilator --random 20"]),
    "render": (
        "Renders a scene (procedural, a mesh file or a TOML scene file, "
        "[scenes.md](scenes.md)) through the float64 reference, the golden model or the RTL "
        "(live Icarus or Verilator simulations, two per unit configuration on two cores). "
        "Secondary rays "
        "(`--depth`, `--glossy`, `--ao`: [secondary-rays.md](secondary-rays.md)) go through "
        "every backend as bundles. `--mode certified` gives the exact reference's nearest "
        "triangle and shadow visibility on every pixel ([certified-render.md]"
        "(certified-render.md)); `--reduce` runs the unit with the on-chip reduction. Prints "
        "rays, bundles, plane tests, pairs against brute force, hits, time per stage and "
        "arithmetic events.",
        ["raplas-hdl render --scene cornell --size 256x256 --backend model -o cornell.png",
         "raplas-hdl render --scene stanford-bunny --size 256x256 --shadow 3x3 -o bunny.png",
         "raplas-hdl render --scene showcase --size 128x128 --backend rtl --sim verilator "
         "-o showcase.png"]),
    "bench": (
        "Run time against error: formats x roundings x scenes x bundle sizes x backends x "
        "modes, error against float64 and the exact reference, cost in seconds and in Yosys "
        "resources, the Pareto front; CSV/JSON, plots and a report under `build/bench/` "
        "([bench.md](bench.md)). `--dask-workers` / `--scheduler` run it on Dask "
        "([cluster.md](cluster.md)).",
        ["raplas-hdl bench --quick", "raplas-hdl bench --format FP16 FP24 --dask-workers 4"]),
    "stress": (
        "`stress ray-triangle`: the seeded numerical stress families of the ray-triangle "
        "test against the exact reference. `stress campaign`: the families and the "
        "plane-culling proof at scale (48.5 M cases by default) over FP16-FP32, all "
        "roundings and both modes, sharded over the cores or a Dask cluster, seeded and "
        "resumable ([stress-campaign.md](stress-campaign.md)).",
        ["raplas-hdl stress ray-triangle --format FP24/rtz,FP16/rne",
         "raplas-hdl stress campaign --jobs 2 --out build/campaign"]),
    "synth": (
        "Yosys resource estimates (`synth_xilinx -family xc4v`, or xc7) beside the paper's "
        "table; `synth capacity`: units per device and the sustained pairs per second of "
        "each configuration, with ECP5 rows from place and route "
        "([synthesis.md](synthesis.md)). These are estimates: clocks come from `pnr`.",
        ["raplas-hdl synth fp-add --format FP24", "raplas-hdl synth capacity"]),
    "constraints": (
        "The board top's UCF (XC4VSX35-10FF668) and XDC (7-series) generated from the "
        "emitted top's ports; `--check` fails on any port the committed files miss.",
        ["raplas-hdl constraints --check"]),
    "fusesoc": (
        "A unit's Verilog and manifest with a FuseSoC CAPI2 core and a `.f` filelist "
        "([integration.md](integration.md)).",
        ["raplas-hdl fusesoc ray-triangle -o build/core"]),
    "pnr": (
        "Place and route on a Lattice ECP5 with the PyPI YoWASP tools (`synth_ecp5`, "
        "out-of-context `nextpnr-ecp5`, one run per seed, cached): utilisation, Fmax as "
        "median / min / max over the seeds, the critical path in the unit's own signal "
        "names, tool time, the command and tool versions ([pnr.md](pnr.md)). `--copies N` "
        "places N units in one design; `--bitstream` writes a ULX3S bitstream of the unit "
        "behind a serial wrapper ([pnr-bitstream.md](pnr-bitstream.md)).",
        ["raplas-hdl pnr fp-add --speed 6 --seeds 3",
         "raplas-hdl pnr intersection-unit --speed 6 --seeds 3 -o build/pnr-iu",
         "raplas-hdl pnr fp-mul --bitstream -o build/board"]),
    "bitstream": (
        "Builds the board design for the ULX3S: a PLL from its 25 MHz oscillator to the "
        "unit's clock, the UARTBone bridge on its FTDI serial port, the board top and its "
        "whole unit (certified, 8x8, with the on-chip reduction), reset on FIRE 1, status on "
        "LEDs 0-5; synthesis, place and route on the board's pins and a `.bit` and `.svf` "
        "(about an hour; refused when the routed design misses the clock). Prints how to "
        "load it (`openFPGALoader -b ulx3s DIR/board-top-ulx3s.bit`, not a dependency; "
        "[board-top.md](board-top.md)).",
        ["raplas-hdl bitstream --board ulx3s-85f -o build/bitstream",
         "raplas-hdl render --scene cornell --size 64x64 --backend board --port /dev/ttyUSB0 "
         "--baud 3000000 -o cornell.png"]),
    "prove": (
        "Proves the emitted Verilog equal to the arithmetic contract for every input, every "
        "output bit and flag (Yosys `write_smt2`, z3): `proved`, a counterexample or "
        "`unknown after S s`, exit 0 / 1 / 3 ([formal.md](formal.md)). `--method "
        "netlist-ecp5` / `netlist-xc4v` proves the synthesised netlist equal to the RTL.",
        ["raplas-hdl prove fp-add --format FP24/rne",
         "raplas-hdl prove fp-mul --format FP16 --method netlist-ecp5"]),
    "board-sim": (
        "Simulates the board design (the UARTBone bridge, the board top and its unit) under "
        "Verilator with its UART pins driven bit by bit from a pseudo-terminal, and prints "
        "the terminal's name: `render --backend board --port PORT` renders through it as "
        "through a board's serial port, and LiteX's `litex_server --uart` reads its "
        "registers ([board-top.md](board-top.md)). The default build is certified, 8x8, "
        "with the on-chip reduction.",
        ["raplas-hdl board-sim",
         "raplas-hdl render --scene cornell --size 8x8 --shadow 8x8 --backend board "
         "--port /dev/pts/3 --baud 10000 -o cornell.png"]),
}

HEAD = """# Command reference

Every command of `raplas-hdl`, with what it is for, examples, and its `--help` as the
program prints it. Generated by `tools/cli_reference.py` from the parser (do not edit by
hand: `make test` fails when this file and `--help` differ).

Every command takes the format the same way (`--format FMT`: `FP24`, `FP24/rtz`, `e7m16`,
`e7m16-rne`; repeatable in the sweeps), checks outputs, inputs and sizes before any work,
and reports a bad input as one line `raplas-hdl CMD: error: ...` with exit code 2
(`--debug` adds the traceback).
"""


def _subparsers(parser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action
    return None


def _help(parser) -> str:
    return parser.format_help().rstrip() + "\n"


def render() -> str:
    """The text of ``docs/cli.md``."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(WIDTH + 2)      # argparse wraps at COLUMNS - 2
    try:
        return _render()
    finally:
        if saved is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = saved


def _render() -> str:
    from raplas_hdl.cli import SUBCOMMANDS, build_parser

    parser = build_parser()
    commands = _subparsers(parser).choices
    missing = [c for c in SUBCOMMANDS if c in commands and c not in COMMANDS]
    if missing:
        raise SystemExit(f"cli_reference: no description of {', '.join(missing)}")
    short = {a.dest: a.help for a in _subparsers(parser)._choices_actions}
    out = [HEAD, "| command | what it does (its line in `raplas-hdl --help`) |", "|---|---|"]
    for name in SUBCOMMANDS:
        if name in commands:
            out.append(f"| [`{name}`](#raplas-hdl-{name}) | {short[name]} |")
    out += ["", "```text", _help(parser).rstrip(), "```", ""]
    for name in SUBCOMMANDS:
        if name not in commands:
            continue
        what, examples = COMMANDS[name]
        sub = commands[name]
        out += [f"## raplas-hdl {name}", "", what, "", "```sh", *examples, "```", "",
                "```text", _help(sub).rstrip(), "```", ""]
        inner = _subparsers(sub)
        for child in (dict.fromkeys(inner.choices) if inner else ()):
            out += [f"### raplas-hdl {name} {child}", "", "```text",
                    _help(inner.choices[child]).rstrip(), "```", ""]
    return "\n".join(out).rstrip() + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--check", action="store_true",
                   help="exit 1 if docs/cli.md differs from what --help gives")
    args = p.parse_args(argv)
    text = render()
    if args.check:
        if not DOC.exists() or DOC.read_text() != text:
            print("docs/cli.md is not what --help gives: run python tools/cli_reference.py",
                  file=sys.stderr)
            return 1
        return 0
    DOC.write_text(text)
    print(f"wrote {DOC.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
