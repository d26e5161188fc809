"""``raplas-hdl cosim``: run a unit's Verilog under Icarus or Verilator, check every result.

Units: fp-add, fp-mul, plane-sphere-tester, plane-sphere, ray-triangle, intersection-unit.
Each runs at full clock rate in a generated Verilog harness (no Python per clock) with
random gaps in valid (held until taken) and random stalls; every output bit is compared
with the golden model. The unit options (--stages, --rows, --cols, --testers,
--tris-per-sphere, --lanes, --mode, --target, --adder, --reduce) are those of raplas-hdl
verilog; intersection-unit --reduce puts a random window on every run and compares every
ANSWER beat (--random only); intersection-unit --mode certified compares each beat's
outcome too (with --reduce: the runs' uncertain pairs, then their answers).

Cases: --random N draws N seeded cases and takes the expected results from the model (an
intersection-unit case is one run: a bundle against a list of spheres of a random scene);
--vectors FILE reads cases with their expected results, checked whole before the simulator
starts; --write-vectors FILE writes the cases with the model's results. Formats
(docs/cosim.md):

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

__all__ = ["add_parser", "check", "read_vectors", "run", "write_vectors"]

FP_UNITS = ("fp-add", "fp-mul")
UNITS = FP_UNITS + ("plane-sphere-tester", "plane-sphere", "ray-triangle",
                    "intersection-unit")
STAGES = {"fp-add": (1, 7, 4), "fp-mul": (1, 5, 3)}
#: Most cases of one run (--random, or the lines of a vectors file).
MAX_CASES = 10_000_000
#: Most runs of an intersection-unit cosim (each is a bundle against many spheres).
MAX_RUNS = 100_000
#: Most cases of a --mode percycle run (a Python call per cycle).
MAX_PERCYCLE = 200_000
#: --random when not given.
DEFAULT_CASES = {"fp-add": 100_000, "fp-mul": 100_000, "plane-sphere-tester": 100_000,
                 "plane-sphere": 20_000, "ray-triangle": 20_000, "intersection-unit": 32}
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
                          f"{MAX_CASES:,} (intersection-unit: runs, at most {MAX_RUNS:,}); "
                          "default " + ", ".join(f"{u} {n:,}" for u, n in DEFAULT_CASES.items()))
    add_unit_options(p, UNITS, only=("stages", "rows", "cols", "testers", "tris_per_sphere",
                                     "lanes", "target", "adder", "reduce"))
    p.add_argument("--mode", type=_mode_or_driver, default=None,
                   metavar="{" + ",".join(MODES) + "}",
                   help="ray-triangle mode (default paper); ray-triangle, intersection-unit. "
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
                                     "in (0, 1] (default 0.9; not intersection-unit)")
    p.add_argument("--stall-density", type=g.float_range(0.0, 1.0, hi_open=True), default=None,
                   metavar="P", help="probability that en (FP units, tester) or the output's "
                                     "ready is low in a cycle, in [0, 1) (default 0.1)")
    p.add_argument("--write-vectors", metavar="FILE",
                   help="also write the cases with the model's results to FILE")
    p.add_argument("--show", type=g.int_range(0), default=5, metavar="N",
                   help="mismatches printed in full, field by field (default 5)")
    g.add_waves_option(p, "the simulation")
    return p


def read_vectors(path, unit: str, fmt=None):
    """``(a, b, sub or None, expected, flags or None)`` from a vectors file.

    Checks everything before returning: the field count of ``unit`` (and the same on every
    line), hex numbers, ``SUB`` 0 or 1, ``FLAGS`` 0 to 7, and with ``fmt`` that ``A``, ``B``
    and ``EXPECTED`` fit its width; a header naming another unit or format is refused.

    Raises
    ------
    ValueError
        One line naming the file, the line and the problem.
    """
    import numpy as np

    if unit not in FP_UNITS:
        raise ValueError(f"unit must be one of {', '.join(FP_UNITS)}, not {unit!r}")
    nops = 3 if unit == "fp-add" else 2
    names = ["A", "B"] + (["SUB"] if unit == "fp-add" else []) + ["EXPECTED", "FLAGS"]
    from ..sim.cosim.vectors import check_header, hex_fields, match_header, text_lines

    rows = []
    width = None
    for lineno, line in enumerate(text_lines(path), 1):
        m = match_header(line.strip())
        if m:
            check_header(path, lineno, m, unit, fmt)
            continue
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        if len(fields) not in (nops + 1, nops + 2):
            raise ValueError(f"{path}:{lineno}: expected {nops + 1} or {nops + 2} hex fields "
                             f"for {unit} ({' '.join(names[:-1])} [FLAGS]), got {len(fields)}")
        if width is None:
            width = len(fields)
        elif len(fields) != width:
            raise ValueError(f"{path}:{lineno}: {len(fields)} fields where line 1 has "
                             f"{width} (FLAGS on all lines or on none)")
        values = hex_fields(path, lineno, fields, names)
        for name, v in zip(names, values):
            if name == "SUB" and v > 1:
                raise ValueError(f"{path}:{lineno}: SUB must be 0 or 1, not {v:#x}")
            if name == "FLAGS" and v > 7:
                raise ValueError(f"{path}:{lineno}: FLAGS must be 0 to 7 (1 overflow, "
                                 f"2 underflow, 4 invalid), not {v:#x}")
            if fmt is not None and name in ("A", "B", "EXPECTED") and v > fmt.mask:
                raise ValueError(f"{path}:{lineno}: {name} {v:#x} is wider than the "
                                 f"{fmt.width} bits of {fmt.name}")
            if v >= 1 << 32:
                raise ValueError(f"{path}:{lineno}: {name} {v:#x} is wider than 32 bits")
        rows.append(values)
        if len(rows) > MAX_CASES:
            raise ValueError(f"{path}: more than {MAX_CASES:,} cases")
    if not rows:
        raise ValueError(f"{path}: no cases")
    arr = np.array(rows, dtype=np.uint64)
    a, b = arr[:, 0].astype(np.uint32), arr[:, 1].astype(np.uint32)
    sub = arr[:, 2].astype(np.uint32) if unit == "fp-add" else None
    exp = arr[:, nops].astype(np.uint32)
    flags = arr[:, nops + 1].astype(np.uint8) if arr.shape[1] == nops + 2 else None
    return a, b, sub, exp, flags


def write_vectors(path, unit: str, a, b, sub, expected, flags=None, fmt=None) -> None:
    """Write cases in the vectors-file format (see the module docstring); the header
    names the unit and, when given, the format."""
    import numpy as np

    cols = [a, b] + ([sub] if unit == "fp-add" else []) + [expected]
    if flags is not None:
        cols.append(flags)
    spec = "%x"
    tag = f"{unit} {fmt.name}" if fmt is not None else unit
    np.savetxt(path, np.stack([np.asarray(c, dtype=np.uint64) for c in cols], axis=1),
               fmt=" ".join([spec] * len(cols)),
               header=f"{tag}: A B {'SUB ' if unit == 'fp-add' else ''}EXPECTED FLAGS (hex)")


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
    fp = args.unit in FP_UNITS
    if args.driver == "percycle" and not fp:
        raise g.UsageError(f"--driver percycle applies to fp-add and fp-mul only ({args.unit} "
                           "runs in its batch harness)")
    if args.unit == "intersection-unit":
        g.reject(args, ("valid_density",), "to intersection-unit (its harness presents each "
                                           "command until taken; --stall-density sets the "
                                           "result back-pressure)")
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
    args.cases = args.expected = None
    if fp:
        args.unit_cosim = None
        if args.vectors:
            g.check_input_file(args.vectors, "vectors file")
            args.cases = read_vectors(args.vectors, args.unit, args.fmt)
            n = len(args.cases[0])
        else:
            n = DEFAULT_CASES[args.unit] if args.random is None else args.random
    else:
        from ..sim.cosim import unit_cosim

        _check_build(args)
        args.unit_cosim = unit_cosim(args.unit, args.fmt, args.options)
        if args.vectors:
            g.check_input_file(args.vectors, "vectors file")
            args.cases, args.expected = args.unit_cosim.read(args.vectors)
            n = args.unit_cosim.n_cases(args.cases)
        else:
            n = DEFAULT_CASES[args.unit] if args.random is None else args.random
        if args.unit == "intersection-unit" and n > MAX_RUNS:
            raise g.UsageError(f"--random of intersection-unit is at most {MAX_RUNS:,} runs, "
                               f"not {n:,}")
    args.n = n
    if args.driver == "percycle" and n > MAX_PERCYCLE:
        raise g.UsageError(f"--mode percycle runs at most {MAX_PERCYCLE:,} cases, not {n:,} "
                           "(use the batch driver)")
    g.check_waves(args, args.sim)
    g.require_simulator(args.sim)


def _check_build(args) -> None:
    """The unit's build parameters, checked by building it (no elaboration)."""
    if args.unit == "intersection-unit":
        from ..model.config import UnitConfig

        kw = {k: v for k, v in args.options.items()
              if v is not None and k not in ("target", "adder")}
        UnitConfig(fmt=args.fmt, **kw)        # ValueError names the parameter
        return
    from ..rtl.units import build_unit

    _, comp, _ = build_unit(args.unit, args.fmt, **args.options)
    comp._MustUse__silence = True             # built only to check the parameters


def run(args) -> int:
    if args.unit in FP_UNITS:
        return _run_fp(args)
    u = args.unit_cosim
    if args.cases is not None:
        cases, expected = args.cases, args.expected
        source = args.vectors
    else:
        cases = u.random(args.n, args.seed)
        expected = u.expected(cases)
        source = f"{args.n} random {'runs' if args.unit == 'intersection-unit' else 'cases'} " \
                 f"(seed {args.seed}) against the model"
    if args.write_vectors:
        u.write(args.write_vectors, cases, u.expected(cases) if args.vectors else expected)
    t0 = time.monotonic()
    with g.waves(args):
        got, info = u.simulate(cases, args.sim, valid_density=args.valid_density,
                               stall_density=args.stall_density, seed=args.seed)
    total = time.monotonic() - t0
    if args.unit == "intersection-unit":
        shown = u.mismatches(expected, got)
        bad = [k for k, lines in enumerate(shown) if lines]
    else:
        from ..sim.cosim import compare

        bad = list(compare(expected, got, getattr(u, "compared", u.outputs)))
    opts = " ".join(f"{k}={v}" for k, v in u.options.items())
    lat = f" latency {info['latency']}" if info.get("latency") is not None else ""
    print(f"{args.unit} {args.fmt.name}{(' ' + opts) if opts else ''}{lat} under {args.sim} "
          f"(batch harness): {source}")
    print(f"cases: {info['n']}")
    print(f"mismatches: {len(bad)}")
    for i in bad[:args.show]:
        if args.unit == "intersection-unit":
            print(f"  {u.describe(cases, i)}")
            print("\n".join(shown[i]))
        else:
            print("\n".join(u.show(cases, expected, got, i)))
    _print_rate(info, total)
    return 1 if bad else 0


def _rate(x: float) -> str:
    return f"{x:,.0f}" if x >= 100 else f"{x:.3g}"


def _print_rate(info, total) -> None:
    run_s = info["run_s"]
    cps = f", {_rate(info['cycles'] / run_s)} cycles/s" if run_s > 0 else ""
    print(f"cases/s: {_rate(info['vectors_per_s'])} (simulator run {run_s:.2f} s, "
          f"{info['cycles']} cycles{cps}; build {info['build_s']:.1f} s; total {total:.1f} s)")


def _run_fp(args) -> int:
    import numpy as np

    from raplas_hdl.sim.cosim.fp import fp_cosim, fp_expected

    fmt = args.fmt
    if args.cases is not None:
        a, b, sub, exp, flags = args.cases
        source = args.vectors
    else:
        n = args.n
        rng = np.random.default_rng(args.seed)
        a = rng.integers(0, fmt.mask + 1, n, dtype=np.uint32)
        b = rng.integers(0, fmt.mask + 1, n, dtype=np.uint32)
        sub = rng.integers(0, 2, n).astype(np.uint32) if args.unit == "fp-add" else None
        exp, flags = fp_expected(args.unit, fmt, a, b, sub)
        source = f"{n} random cases (seed {args.seed}) against the model"
    if args.write_vectors:
        wexp, wflags = fp_expected(args.unit, fmt, a, b, sub)
        write_vectors(args.write_vectors, args.unit, a, b, sub, wexp, wflags, fmt=fmt)
    target = args.options.get("target") or "generic"
    t0 = time.monotonic()
    with g.waves(args):
        res = fp_cosim(args.unit, fmt, a, b, sub, simulator=args.sim,
                       stages=args.options.get("stages"), mode=args.driver,
                       valid_density=args.valid_density, stall_density=args.stall_density,
                       seed=args.seed, expected=(exp, flags), multiplier=target)
    total = time.monotonic() - t0
    tgt = f" target={target}" if target != "generic" else ""
    print(f"{args.unit} {fmt.name}{tgt} latency {res['latency']} under {args.sim} "
          f"({args.driver}): {source}")
    print(f"cases: {res['n']}")
    print(f"mismatches: {res['mismatches']}")
    nd = (fmt.width + 3) // 4
    for i in res["bad"][:args.show]:
        print(f"  case {i}: a={int(a[i]):0{nd}x} b={int(b[i]):0{nd}x}"
              + (f" sub={int(sub[i])}" if sub is not None else ""))
        print(f"    {'o':12s} expected {int(exp[i]):0{nd}x}, got {int(res['got'][i]):0{nd}x}"
              + ("   <- differs" if int(exp[i]) != int(res['got'][i]) else ""))
        if flags is not None:
            e, gf = int(flags[i]), int(res["got_flags"][i])
            print(f"    {'flags':12s} expected {e}, got {gf}" + ("   <- differs" if e != gf
                                                                   else ""))
    _print_rate({**res, "n": res["n"]}, total)
    return 1 if res["mismatches"] else 0
