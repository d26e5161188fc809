"""Stress table of the ray-triangle unit and the bisection of the conservative margin scale.

For FP24 in all three roundings and FP32 (rtz, rne, chop), both modes, every stress family:
false hits, false misses and leaks against the exact reference R, and the relative error
of t. For the conservative mode, the smallest margin scale ``s`` that still gives zero
false misses (pooled over the families, bisection in log2 s) and the false hits at s = 1
against that minimum.

Usage::

    python benchmarks/bench_ray_triangle_stress.py [--per-family N] [--seed S] [--out FILE]

Results: ``docs/results/ray_triangle_stress.json`` (and a markdown table on stdout).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from raplas_hdl.fp import FP24, FP32
from raplas_hdl.model import stress_cases
from raplas_hdl.verify import stress

FORMATS = [FP24.with_rounding(r) for r in ("rtz", "rne", "chop")] + \
          [FP32.with_rounding(r) for r in ("rtz", "rne", "chop")]
OUT = Path(__file__).resolve().parent.parent / "docs" / "results" / "ray_triangle_stress.json"


def markdown(results) -> str:
    lines = ["| format | mode | pairs in domain | R hits | false hits | false misses | "
             "leaks / edge rays | rel. err. t: median (random) / worst median (family) | "
             "s_min | false hits s=1 / s_min |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        p = r["pooled"]
        fam = r["families"]
        worst = max(fam, key=lambda k: fam[k]["t_rel_median"])
        b = r.get("bisection")
        lines.append(
            f"| {r['format']} | {r['mode']} | {p['pairs'] - p['unguaranteed'] - p['skipped']} "
            f"| {p['r_hits']} | {p['false_hits']} | {p['false_misses']} | "
            f"{p['leaks']} / {p['edge_rays']} | {fam['random']['t_rel_median']:.2e} / "
            f"{fam[worst]['t_rel_median']:.2e} ({worst}) | "
            + (f"{b['s_min']:.4g} | {b['false_hits_1']} / {b['false_hits_min']} = "
               f"{b['ratio']:.2f} |" if b else "- | - |"))
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--table-only", action="store_true",
                    help="print the markdown table of an existing results file")
    args = ap.parse_args(argv)
    if args.table_only:
        print(markdown(json.loads(args.out.read_text())["results"]))
        return
    results = []
    t0 = time.monotonic()
    for fmt in FORMATS:
        cases = stress_cases.generate(fmt, args.per_family, args.seed)
        enc = stress.reference(cases, fmt)
        for mode in ("paper", "conservative"):
            table = stress.evaluate(cases, enc, mode)
            entry = {"format": str(fmt), "mode": mode, "seed": args.seed,
                     "per_family": args.per_family, "margin_scale": 1.0,
                     "families": table, "pooled": stress.pooled(table)}
            if mode == "conservative":
                entry["bisection"] = stress.bisect_scale(cases, enc)
            results.append(entry)
        print(f"{fmt}: {len(cases)} pairs, {time.monotonic() - t0:.1f} s", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"command": "python benchmarks/bench_ray_triangle_stress.py "
                                               f"--per-family {args.per_family} --seed {args.seed}",
                                    "results": results}, indent=1, sort_keys=True) + "\n")
    print(markdown(results))
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
