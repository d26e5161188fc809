"""``raplas-hdl cosim``: run an FP unit's Verilog under Icarus or Verilator, check every result.

Vectors file format (--vectors / --write-vectors): one case per line, fields in hex
separated by white space, # starts a comment:

  fp-mul:  A B EXPECTED [FLAGS]
  fp-add:  A B SUB EXPECTED [FLAGS]   (SUB 1 selects A - B)

A, B and EXPECTED are bit patterns of the format; FLAGS is the event-flag mask (0 to 7:
1 overflow, 2 underflow, 4 invalid) and is checked when present. A header comment
"# fp-add e7m16-rtz: ..." (what --write-vectors writes) names the unit and the format the
file is for; a file for another unit or format is refused. With --random N the expected
results come from the golden model. The batch harness (the default) runs at full clock
rate with gaps in valid and stalls on en; --mode percycle uses the per-cycle cocotb driver
instead.
"""

from __future__ import annotations

import re
import time

from . import grammar as g

__all__ = ["add_parser", "check", "run", "read_vectors", "write_vectors"]

UNITS = ("fp-add", "fp-mul")
STAGES = {"fp-add": (1, 7, 4), "fp-mul": (1, 5, 3)}
#: Most cases of one run (--random, or the lines of a vectors file).
MAX_CASES = 10_000_000
#: Most cases of a --mode percycle run (a Python call per cycle).
MAX_PERCYCLE = 200_000
_HEADER = re.compile(r"#\s*(fp-add|fp-mul)\b\s*([^\s:]*)\s*:")


def add_parser(subparsers):
    p = subparsers.add_parser(
        "cosim", help="co-simulate an FP unit's Verilog against the golden model",
        description=__doc__.split("\n\n", 1)[1])
    p.add_argument("unit", type=g.choice(*UNITS, what="unit"), metavar="UNIT",
                   help="fp-add | fp-mul")
    p.add_argument("--sim", type=g.choice("icarus", "verilator", what="simulator"),
                   default="verilator", metavar="{icarus,verilator}",
                   help="simulator (default verilator)")
    g.add_format_option(p, field_widths=True)
    src = p.add_mutually_exclusive_group()
    src.add_argument("--vectors", metavar="FILE",
                     help="cases with expected results (format above)")
    src.add_argument("--random", type=g.int_range(1, MAX_CASES), metavar="N", default=None,
                     help=f"N seeded random cases checked against the model, 1 to "
                          f"{MAX_CASES:,} (default 100,000)")
    p.add_argument("--stages", type=g.int_range(1, 7), default=None, metavar="N",
                   help="pipeline stages: fp-add 1 to 7 (default 4), fp-mul 1 to 5 "
                        "(default 3)")
    p.add_argument("--seed", type=int, default=1, metavar="S",
                   help="seed of the random cases and of the valid/stall patterns "
                        "(default 1)")
    p.add_argument("--mode", type=g.choice("batch", "percycle", what="mode"), default="batch",
                   metavar="{batch,percycle}",
                   help="batch: the Verilog harness streams the cases at full clock rate; "
                        f"percycle: the cocotb driver, at most {MAX_PERCYCLE:,} cases "
                        "(default batch)")
    p.add_argument("--valid-density", type=g.float_range(0.0, 1.0, lo_open=True), default=0.9,
                   metavar="P", help="probability that i_valid is high in a cycle, in (0, 1] "
                                     "(default 0.9)")
    p.add_argument("--stall-density", type=g.float_range(0.0, 1.0, hi_open=True), default=0.1,
                   metavar="P", help="probability that en is low in a cycle, in [0, 1) "
                                     "(default 0.1)")
    p.add_argument("--write-vectors", metavar="FILE",
                   help="also write the cases with the model's results to FILE")
    p.add_argument("--show", type=g.int_range(0), default=5, metavar="N",
                   help="mismatches printed in full (default 5)")
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

    if unit not in UNITS:
        raise ValueError(f"unit must be one of {', '.join(UNITS)}, not {unit!r}")
    nops = 3 if unit == "fp-add" else 2
    names = ["A", "B"] + (["SUB"] if unit == "fp-add" else []) + ["EXPECTED", "FLAGS"]
    rows = []
    width = None
    try:
        fh = open(path, encoding="utf-8", errors="strict")
    except OSError as exc:
        raise ValueError(f"vectors file {str(path)!r} cannot be read "
                         f"({exc.strerror or exc})") from None
    with fh:
        try:
            lines = fh.readlines()
        except UnicodeDecodeError:
            raise ValueError(f"{path}: not a text file") from None
    for lineno, line in enumerate(lines, 1):
        m = _HEADER.match(line.strip())
        if m:
            if m.group(1) != unit:
                raise ValueError(f"{path}:{lineno}: the file holds {m.group(1)} vectors, "
                                 f"not {unit}")
            if fmt is not None and m.group(2):
                from ..fp import parse_format

                try:
                    ffmt = parse_format(m.group(2))
                except ValueError:
                    ffmt = None
                if ffmt is not None and ffmt != fmt:
                    raise ValueError(f"{path}:{lineno}: the file holds {ffmt.name} vectors, "
                                     f"not {fmt.name} (give --format {ffmt.name})")
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
        try:
            values = [int(f, 16) for f in fields]
        except ValueError:
            raise ValueError(f"{path}:{lineno}: not a hex number in {line.strip()!r}") from None
        for name, v in zip(names, values):
            if v < 0:
                raise ValueError(f"{path}:{lineno}: {name} is negative")
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
    lo, hi, _ = STAGES[args.unit]
    if args.stages is not None and not lo <= args.stages <= hi:
        raise g.UsageError(f"--stages of {args.unit} must be {lo} to {hi}, not {args.stages}")
    if args.write_vectors:
        g.check_output_file(args.write_vectors, (), "--write-vectors")
        if args.vectors:
            g.check_distinct(**{"--vectors": args.vectors,
                                "--write-vectors": args.write_vectors})
    if args.vectors:
        g.check_input_file(args.vectors, "vectors file")
        args.cases = read_vectors(args.vectors, args.unit, args.fmt)
        n = len(args.cases[0])
    else:
        n = 100_000 if args.random is None else args.random
        args.cases = None
    if args.mode == "percycle" and n > MAX_PERCYCLE:
        raise g.UsageError(f"--mode percycle runs at most {MAX_PERCYCLE:,} cases, not {n:,} "
                           "(use --mode batch)")
    g.check_waves(args, args.sim)
    g.require_simulator(args.sim)


def run(args) -> int:
    import numpy as np

    from raplas_hdl.sim.tb_fp import fp_cosim, fp_expected

    fmt = args.fmt
    if args.cases is not None:
        a, b, sub, exp, flags = args.cases
        source = args.vectors
    else:
        n = 100_000 if args.random is None else args.random
        rng = np.random.default_rng(args.seed)
        a = rng.integers(0, fmt.mask + 1, n, dtype=np.uint32)
        b = rng.integers(0, fmt.mask + 1, n, dtype=np.uint32)
        sub = rng.integers(0, 2, n).astype(np.uint32) if args.unit == "fp-add" else None
        exp, flags = fp_expected(args.unit, fmt, a, b, sub)
        source = f"{n} random cases (seed {args.seed}) against the model"
    if args.write_vectors:
        wexp, wflags = fp_expected(args.unit, fmt, a, b, sub)
        write_vectors(args.write_vectors, args.unit, a, b, sub, wexp, wflags, fmt=fmt)
    t0 = time.monotonic()
    with g.waves(args):
        res = fp_cosim(args.unit, fmt, a, b, sub, simulator=args.sim, stages=args.stages,
                       mode=args.mode, valid_density=args.valid_density,
                       stall_density=args.stall_density, seed=args.seed,
                       expected=(exp, flags))
    total = time.monotonic() - t0
    print(f"{args.unit} {fmt.name} latency {res['latency']} under {args.sim} ({args.mode}): "
          f"{source}")
    print(f"cases: {res['n']}")
    print(f"mismatches: {res['mismatches']}")
    nd = (fmt.width + 3) // 4
    for i in res["bad"][:args.show]:
        s = f" sub={int(sub[i])}" if sub is not None else ""
        ef = f" flags {int(flags[i])}" if flags is not None else ""
        print(f"  case {i}: a={int(a[i]):0{nd}x} b={int(b[i]):0{nd}x}{s} expected "
              f"{int(exp[i]):0{nd}x}{ef}, got {int(res['got'][i]):0{nd}x} "
              f"flags {int(res['got_flags'][i])}")
    print(f"vectors/s: {res['vectors_per_s']:,.0f} (simulator run {res['run_s']:.2f} s, "
          f"{res['cycles']} cycles; build {res['build_s']:.1f} s; total {total:.1f} s)")
    return 1 if res["mismatches"] else 0
