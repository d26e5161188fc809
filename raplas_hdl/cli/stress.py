"""``raplas-hdl stress ray-triangle``: the seeded numerical stress suite of the ray-triangle
unit (golden model) against the exact reference R, as a table per format and mode."""

from __future__ import annotations

import json

__all__ = ["add_parser", "run", "format_table"]

COLUMNS = ("pairs", "unguaranteed", "r_hits", "unit_hits", "false_hits", "false_misses",
           "edge_rays", "leaks", "t_rel_median", "t_rel_max")


def add_parser(subparsers):
    p = subparsers.add_parser(
        "stress", help="numerical stress suites against exact references",
        description="Run a seeded stress suite and print false hits, false misses, leaks and "
                    "the relative error of t per case family, against the exact reference R.")
    p.add_argument("target", choices=["ray-triangle"], help="the unit to stress")
    p.add_argument("--format", action="append", dest="formats", metavar="FMT",
                   help="format, e.g. FP24/rtz, FP24/chop, FP32 (repeatable; default FP24/rtz)")
    p.add_argument("--mode", choices=["paper", "conservative", "both"], default="both")
    p.add_argument("--per-family", type=int, default=1000, metavar="N",
                   help="rays per family (default 1000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--families", default=None,
                   help="comma-separated subset of the families (default: all)")
    p.add_argument("--margin-scale", type=float, default=1.0, metavar="S",
                   help="scale s of the conservative margin (default 1: the derivation)")
    p.add_argument("--bisect", action="store_true",
                   help="also find the smallest s with zero false misses (conservative mode)")
    p.add_argument("--json", default=None, metavar="FILE", help="write the results as JSON")
    return p


def format_table(table: dict, pooled: dict) -> str:
    """A fixed-width text table of one evaluation (families, then the pooled row)."""
    head = f"{'family':14s}" + "".join(f"{c:>14s}" for c in COLUMNS)
    lines = [head, "-" * len(head)]
    for name, row in list(table.items()) + [("ALL", pooled)]:
        cells = []
        for c in COLUMNS:
            v = row.get(c, "")
            cells.append(f"{v:14.3e}" if isinstance(v, float) else f"{v!s:>14s}")
        lines.append(f"{name:14s}" + "".join(cells))
    return "\n".join(lines)


def run(args) -> int:
    from ..fp import parse_format
    from ..host import stress

    formats = [parse_format(f) for f in (args.formats or ["FP24/rtz"])]
    families = stress.FAMILIES if args.families is None else tuple(
        f.strip() for f in args.families.split(",") if f.strip())
    modes = ("paper", "conservative") if args.mode == "both" else (args.mode,)
    results = []
    status = 0
    for fmt in formats:
        cases = stress.generate(fmt, args.per_family, args.seed, families)
        enc = stress.reference(cases, fmt)
        for mode in modes:
            table = stress.evaluate(cases, enc, mode, args.margin_scale)
            tot = stress.pooled(table)
            print(f"\n{fmt} {mode}" + (f" s={args.margin_scale:g}" if mode == "conservative"
                                       else "") + f": {len(cases)} pairs, seed {args.seed}")
            print(format_table(table, tot))
            entry = {"format": str(fmt), "mode": mode, "seed": args.seed,
                     "per_family": args.per_family, "margin_scale": args.margin_scale,
                     "families": table, "pooled": tot}
            if mode == "conservative":
                if tot["false_misses"] or tot["leaks"]:
                    print("conservative mode: FALSE MISSES OR LEAKS INSIDE THE DOMAIN")
                    status = 1
                if args.bisect:
                    b = stress.bisect_scale(cases, enc)
                    entry["bisection"] = b
                    print(f"smallest s with zero false misses: {b['s_min']:.4g}; false hits "
                          f"{b['false_hits_1']} at s=1 against {b['false_hits_min']} there "
                          f"(ratio {b['ratio']:.2f})")
            results.append(entry)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1, sort_keys=True)
            fh.write("\n")
    return status
