"""``raplas-hdl cosim``: run a unit's Verilog under Icarus or Verilator, check every result.

Units: fp-add, fp-mul, plane-sphere-tester, plane-sphere, ray-triangle, intersection-unit,
reducer (the on-chip reduction alone), board-top (the unit behind its Wishbone port, driven
by the host's driver under cocotb). Each runs at full clock rate in a generated Verilog
harness (no Python per clock) with random gaps in valid (held until taken) and random
stalls; every output bit is compared with the golden model. The unit options (--stages,
--rows, --cols, --testers, --tris-per-sphere, --lanes, --mode, --target, --adder,
--reduce) are those of raplas-hdl verilog; intersection-unit --reduce puts a random window
on every run and compares every ANSWER beat (--random only); intersection-unit --mode
certified compares each beat's outcome too (with --reduce: the runs' uncertain pairs, then
their answers).

Cases: --random N draws N seeded cases and takes the expected results from the model (an
intersection-unit or board-top case is one run: a bundle against a list of spheres of a
random scene; a reducer case a random run: result beats and a window); --vectors FILE reads
cases with their expected results, checked whole before the simulator starts;
--write-vectors FILE writes the cases with the model's results (not reducer). Formats
(docs/cosim.md; board-top: those of intersection-unit):

  fp-mul:  A B EXPECTED [FLAGS]
  fp-add:  A B SUB EXPECTED [FLAGS]   (SUB 1 selects A - B)
  plane-sphere-tester:  P NX NY NZ P  then  S CX CY CZ R FLAG
  plane-sphere:  rows+cols lines P NX NY NZ P, then  S ID CX CY CZ R ROW_MASK COL_MASK
  ray-triangle:  RAY_ID TRI_ID O D V0 E1 E2 N (x y z each)  HIT T U V DET FLAGS
                 N_OVERFLOW N_UNDERFLOW N_INVALID

Fields are hex; # starts a comment. FP units: A, B and EXPECTED are bit patterns of the
format and FLAGS the event-flag mask (0 to 7: 1 overflow, 2 underflow, 4 invalid), checked
when present. The header comment that --write-vectors writes ("# fp-add e7m16-rtz: ...",
"# plane-sphere e7m16-rtz rows=4 cols=4: ...") names the unit, the format and the
parameters the file is for; a file for another one is refused. --mode percycle (FP units)
uses the per-cycle cocotb driver instead of the batch harness.
"""

from __future__ import annotations

import time

from ..model.modes import MODES
from . import grammar as g
from .verilog import add_unit_options, unit_options

__all__ = ["add_parser", "check", "run"]

FP_UNITS = ("fp-add", "fp-mul")
UNITS = FP_UNITS + ("plane-sphere-tester", "plane-sphere", "ray-triangle",
                    "intersection-unit", "reducer", "board-top")
STAGES = {"fp-add": (1, 7, 4), "fp-mul": (1, 5, 3)}
#: Most cases of one run (--random, or the lines of a vectors file).
MAX_CASES = 10_000_000
#: Most runs of an intersection-unit, reducer or board-top cosim (each is a bundle against
#: many spheres, or a result stream).
MAX_RUNS = 100_000
#: Most cases of a --mode percycle run (a Python call per cycle).
MAX_PERCYCLE = 200_000
#: --random when not given.
DEFAULT_CASES = {"fp-add": 100_000, "fp-mul": 100_000, "plane-sphere-tester": 100_000,
                 "plane-sphere": 20_000, "ray-triangle": 20_000, "intersection-unit": 32,
                 "reducer": 1_000, "board-top": 4}
DRIVERS = ("batch", "percycle")


def _mode_or_driver(text):
    """``--mode``: the ray-triangle mode, or (FP units, kept for compatibility) the driver."""
    if text in MODES or text in DRIVERS:
        return text
    import argparse

    raise argparse.ArgumentTypeError(f"mode must be one of {', '.join(MODES)} (or, for "
                                     f"fp-add and fp-mul, batch or percycle), not {text!r}")


def add_parser(subparsers):
    p = subparsers.add_parser(
        "cosim", help="co-simulate a unit's Verilog against the golden model",
        description=__doc__.split("\n\n", 1)[1])
    p.add_argument("unit", type=g.choice(*UNITS, what="unit"), metavar="UNIT",
                   help=" | ".join(UNITS))
    p.add_argument("--sim", type=g.choice("icarus", "verilator", what="simulator"),
                   default="verilator", metavar="{icarus,verilator}",
                   help="simulator (default verilator)")
    g.add_format_option(p, field_widths=True)
    src = p.add_mutually_exclusive_group()
    src.add_argument("--vectors", metavar="FILE",
                     help="cases with expected results (formats above)")
    src.add_argument("--random", type=g.int_range(1, MAX_CASES), metavar="N", default=None,
                     help=f"N seeded random cases checked against the model, 1 to "
                          f"{MAX_CASES:,} (intersection-unit, reducer, board-top: runs, at most "
                          f"{MAX_RUNS:,}); "
                          "default " + ", ".join(f"{u} {n:,}" for u, n in DEFAULT_CASES.items()))
    add_unit_options(p, UNITS, only=("stages", "rows", "cols", "testers", "tris_per_sphere",
                                     "lanes", "target", "adder", "reduce"))
    p.add_argument("--mode", type=_mode_or_driver, default=None,
                   metavar="{" + ",".join(MODES) + "}",
                   help="ray-triangle mode (default paper); ray-triangle, intersection-unit, "
                        "board-top. "
                        "For fp-add and fp-mul, --mode batch|percycle is the same as --driver")
    p.add_argument("--driver", type=g.choice(*DRIVERS, what="driver"), default=None,
                   metavar="{batch,percycle}",
                   help="batch: the Verilog harness streams the cases at full clock rate; "
                        f"percycle (fp-add, fp-mul): the cocotb driver, at most "
                        f"{MAX_PERCYCLE:,} cases (default batch)")
    p.add_argument("--seed", type=int, default=1, metavar="S",
                   help="seed of the random cases and of the valid/stall patterns "
                        "(default 1)")
    p.add_argument("--valid-density", type=g.float_range(0.0, 1.0, lo_open=True), default=None,
                   metavar="P", help="probability that the input valid is raised in a cycle, "
                                     "in (0, 1] (default 0.9; not intersection-unit, "
                                     "board-top)")
    p.add_argument("--stall-density", type=g.float_range(0.0, 1.0, hi_open=True), default=None,
                   metavar="P", help="probability that en (FP units, tester) or the output's "
                                     "ready is low in a cycle, in [0, 1) (default 0.1; not "
                                     "board-top, whose bus master idles at random)")
    p.add_argument("--write-vectors", metavar="FILE",
                   help="also write the cases with the model's results to FILE")
    p.add_argument("--show", type=g.int_range(0), default=5, metavar="N",
                   help="mismatches printed in full, field by field (default 5)")
    g.add_waves_option(p, "the simulation")
    return p


def check(args) -> None:
    args.fmt = g.format_from_args(args)
    if args.mode in DRIVERS:        # --mode batch|percycle: the driver (the first spelling)
        if args.driver is not None and args.driver != args.mode:
            raise g.UsageError(f"--mode {args.mode} and --driver {args.driver} disagree")
        if args.unit not in FP_UNITS:
            raise g.UsageError(f"--mode {args.mode} applies to fp-add and fp-mul only "
                               f"(the mode of {args.unit}: {', '.join(MODES)})")
        args.driver, args.mode = args.mode, None
    args.driver = args.driver or "batch"
    args.options = unit_options(args, args.unit)
    if args.driver == "percycle" and args.unit not in FP_UNITS:
        how = "under the host's driver" if args.unit == "board-top" else "in its batch harness"
        raise g.UsageError(f"--driver percycle applies to fp-add and fp-mul only ({args.unit} "
                           f"runs {how})")
    if args.unit == "intersection-unit":
        g.reject(args, ("valid_density",), "to intersection-unit (its harness presents each "
                                           "command until taken; --stall-density sets the "
                                           "result back-pressure)")
    if args.unit == "board-top":
        g.reject(args, ("valid_density", "stall_density"), "to board-top (the host's driver "
                                                           "paces its bus; its idle cycles "
                                                           "are random, seeded by --seed)")
    if args.unit == "reducer":
        g.reject(args, ("vectors", "write_vectors"), "to reducer (its cases are random result "
                                                     "streams; use --random)")
    if args.options.get("reduce"):
        g.reject(args, ("vectors", "write_vectors"), "with --reduce (vectors files hold "
                                                      "unreduced result beats; use --random)")
    args.valid_density = 0.9 if args.valid_density is None else args.valid_density
    args.stall_density = 0.1 if args.stall_density is None else args.stall_density
    if args.write_vectors:
        g.check_output_file(args.write_vectors, (), "--write-vectors")
        if args.vectors:
            g.check_distinct(**{"--vectors": args.vectors,
                                "--write-vectors": args.write_vectors})
    from ..sim.cosim import unit_cosim

    args.unit_cosim = u = unit_cosim(args.unit, args.fmt, args.options, args.driver)
    u.check()
    args.cases = args.expected = None
    if args.vectors:
        g.check_input_file(args.vectors, "vectors file")
        args.cases, args.expected = u.read(args.vectors)
        n = u.n_cases(args.cases)
    else:
        n = DEFAULT_CASES[args.unit] if args.random is None else args.random
    if u.case_name == "runs" and n > MAX_RUNS:
        raise g.UsageError(f"--random of {args.unit} is at most {MAX_RUNS:,} runs, not {n:,}")
    args.n = n
    if args.driver == "percycle" and n > MAX_PERCYCLE:
        raise g.UsageError(f"--mode percycle runs at most {MAX_PERCYCLE:,} cases, not {n:,} "
                           "(use the batch driver)")
    g.check_waves(args, args.sim)
    g.require_simulator(args.sim)


def run(args) -> int:
    u = args.unit_cosim
    if args.cases is not None:
        cases, expected = args.cases, args.expected
        source = args.vectors
    else:
        cases = u.random(args.n, args.seed)
        expected = u.expected(cases)
        source = f"{args.n} random {u.case_name} (seed {args.seed}) against the model"
    if args.write_vectors:
        u.write(args.write_vectors, cases, u.expected(cases) if args.vectors else expected)
    t0 = time.monotonic()
    with g.waves(args):
        got, info = u.simulate(cases, args.sim, valid_density=args.valid_density,
                               stall_density=args.stall_density, seed=args.seed)
    total = time.monotonic() - t0
    n_bad, shown = u.report(cases, expected, got, args.show)
    opts = u.label()
    lat = f" latency {info['latency']}" if info.get("latency") is not None else ""
    print(f"{args.unit} {args.fmt.name}{(' ' + opts) if opts else ''}{lat} under {args.sim} "
          f"({u.harness}): {source}")
    print(f"cases: {info['n']}")
    print(f"mismatches: {n_bad}")
    for line in shown:
        print(line)
    _print_rate(info, total)
    return 1 if n_bad else 0


def _rate(x: float) -> str:
    return f"{x:,.0f}" if x >= 100 else f"{x:.3g}"


def _print_rate(info, total) -> None:
    run_s = info["run_s"]
    cps = f", {_rate(info['cycles'] / run_s)} cycles/s" if run_s > 0 else ""
    print(f"cases/s: {_rate(info['vectors_per_s'])} (simulator run {run_s:.2f} s, "
          f"{info['cycles']} cycles{cps}; build {info['build_s']:.1f} s; total {total:.1f} s)")

