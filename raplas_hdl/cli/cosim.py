"""``raplas-hdl cosim``: run an FP unit's Verilog under Icarus or Verilator, check every result.

Vectors file format (``--vectors``/``--write-vectors``): one case per line, fields in hex
separated by white space, ``#`` starts a comment:

- ``fp-mul``: ``A B EXPECTED [FLAGS]``
- ``fp-add``: ``A B SUB EXPECTED [FLAGS]`` (``SUB`` 1 selects ``A - B``)

``A``, ``B`` and ``EXPECTED`` are bit patterns of the format; ``FLAGS`` is the event-flag
mask (1 overflow, 2 underflow, 4 invalid) and is checked when present. With ``--random N``
the expected results come from the golden model (``raplas_hdl.fp.model``). The batch
harness (the default) runs at full clock rate with gaps in ``valid`` and stalls on ``en``;
``--mode percycle`` uses the per-cycle cocotb driver instead.
"""

from __future__ import annotations

import sys
import time

__all__ = ["add_parser", "run", "read_vectors", "write_vectors"]


def add_parser(subparsers):
    p = subparsers.add_parser(
        "cosim", help="co-simulate an FP unit's Verilog against the golden model",
        description=__doc__.split("\n\n", 1)[1],
        formatter_class=__import__("argparse").RawDescriptionHelpFormatter)
    p.add_argument("unit", choices=("fp-add", "fp-mul"))
    p.add_argument("--sim", choices=("icarus", "verilator"), default="verilator",
                   help="simulator (default verilator)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--vectors", metavar="FILE", help="cases with expected results")
    src.add_argument("--random", type=int, metavar="N", default=None,
                     help="N seeded random cases checked against the model (default 100000)")
    p.add_argument("--exp-bits", type=int, default=7)
    p.add_argument("--man-bits", type=int, default=16)
    p.add_argument("--rounding", default="rtz", help="rtz, rne or chop (default rtz)")
    p.add_argument("--stages", type=int, default=None, help="pipeline depth (unit default)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--mode", choices=("batch", "percycle"), default="batch")
    p.add_argument("--valid-density", type=float, default=0.9,
                   help="probability that i_valid is high in a cycle (default 0.9)")
    p.add_argument("--stall-density", type=float, default=0.1,
                   help="probability that en is low in a cycle (default 0.1)")
    p.add_argument("--write-vectors", metavar="FILE",
                   help="also write the cases with the model's results to FILE")
    p.add_argument("--show", type=int, default=5, help="mismatches printed in full")
    return p


def read_vectors(path, unit: str):
    """``(a, b, sub or None, expected, flags or None)`` from a vectors file."""
    import numpy as np

    nops = 3 if unit == "fp-add" else 2
    rows = []
    with open(path) as fh:
        for lineno, line in enumerate(fh, 1):
            fields = line.split("#", 1)[0].split()
            if not fields:
                continue
            if len(fields) not in (nops + 1, nops + 2):
                raise ValueError(f"{path}:{lineno}: expected {nops + 1} or {nops + 2} hex "
                                 f"fields for {unit}, got {len(fields)}")
            try:
                rows.append([int(f, 16) for f in fields])
            except ValueError:
                msg = f"{path}:{lineno}: not a hex number in {line.strip()!r}"
                raise ValueError(msg) from None
    if not rows:
        raise ValueError(f"{path}: no cases")
    widths = {len(r) for r in rows}
    if len(widths) != 1:
        raise ValueError(f"{path}: every line must have the same number of fields "
                         "(FLAGS on all lines or on none)")
    arr = np.array(rows, dtype=np.uint64)
    a, b = arr[:, 0].astype(np.uint32), arr[:, 1].astype(np.uint32)
    sub = arr[:, 2].astype(np.uint32) if unit == "fp-add" else None
    if sub is not None and np.any(sub > 1):
        raise ValueError(f"{path}: SUB must be 0 or 1")
    exp = arr[:, nops].astype(np.uint32)
    flags = arr[:, nops + 1].astype(np.uint8) if arr.shape[1] == nops + 2 else None
    return a, b, sub, exp, flags


def write_vectors(path, unit: str, a, b, sub, expected, flags=None) -> None:
    """Write cases in the vectors-file format (see the module docstring)."""
    import numpy as np

    cols = [a, b] + ([sub] if unit == "fp-add" else []) + [expected]
    if flags is not None:
        cols.append(flags)
    fmt = " ".join(["%x"] * len(cols))
    np.savetxt(path, np.stack([np.asarray(c, dtype=np.uint64) for c in cols], axis=1), fmt=fmt,
               header=f"{unit}: A B {'SUB ' if unit == 'fp-add' else ''}EXPECTED FLAGS (hex)")


def run(args) -> int:
    import numpy as np

    from raplas_hdl.fp import FPFormat
    from raplas_hdl.sim.runner import SimulatorNotFound
    from raplas_hdl.sim.tb_fp import fp_cosim, fp_expected

    fmt = FPFormat(args.exp_bits, args.man_bits, args.rounding)
    if args.vectors:
        a, b, sub, exp, flags = read_vectors(args.vectors, args.unit)
        for name, v in (("A", a), ("B", b), ("EXPECTED", exp)):
            if np.any(v > fmt.mask):
                raise ValueError(f"{args.vectors}: {name} values wider than {fmt.width} bits "
                                 f"({fmt.name})")
        source = args.vectors
    else:
        n = 100_000 if args.random is None else args.random
        if n < 1:
            raise ValueError(f"--random must be at least 1, not {n}")
        rng = np.random.default_rng(args.seed)
        a = rng.integers(0, fmt.mask + 1, n, dtype=np.uint32)
        b = rng.integers(0, fmt.mask + 1, n, dtype=np.uint32)
        sub = rng.integers(0, 2, n).astype(np.uint32) if args.unit == "fp-add" else None
        exp, flags = fp_expected(args.unit, fmt, a, b, sub)
        source = f"{n} random cases (seed {args.seed}) against the model"
    if args.write_vectors:
        wexp, wflags = fp_expected(args.unit, fmt, a, b, sub)
        write_vectors(args.write_vectors, args.unit, a, b, sub, wexp, wflags)
    t0 = time.monotonic()
    try:
        res = fp_cosim(args.unit, fmt, a, b, sub, simulator=args.sim, stages=args.stages,
                       mode=args.mode, valid_density=args.valid_density,
                       stall_density=args.stall_density, seed=args.seed,
                       expected=(exp, flags))
    except SimulatorNotFound as exc:
        print(f"raplas-hdl cosim: error: {exc}", file=sys.stderr)
        return 2
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
