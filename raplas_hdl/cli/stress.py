"""``raplas-hdl stress ray-triangle``: the seeded numerical stress suite of the ray-triangle
unit (golden model) against the exact reference R, as a table per format and mode.

``raplas-hdl stress campaign``: the same families and the plane-culling proof at scale,
sharded over the machine's cores, resumable (:mod:`raplas_hdl.verify.campaign`)."""

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
    p.add_argument("target", choices=["ray-triangle", "campaign"],
                   help="the unit to stress, or the whole campaign (both units, every format, "
                        "rounding and mode)")
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
    g = p.add_argument_group("campaign options")
    g.add_argument("--formats", dest="campaign_formats", default="FP16,FP20,FP24,FP32",
                   help="campaign: comma-separated formats (FP24 = every rounding of "
                        "--roundings; FP24/rne = that one). Default FP16,FP20,FP24,FP32")
    g.add_argument("--roundings", default="rtz,rne,chop",
                   help="campaign: roundings of the formats given without one")
    g.add_argument("--rays-per-family", type=int, default=50000, metavar="N",
                   help="campaign: rays per family, format and rounding (default 50000)")
    g.add_argument("--shard-rays", type=int, default=5000, metavar="N",
                   help="campaign: rays per ray-triangle shard (default 5000)")
    g.add_argument("--bundles", type=int, default=5000, metavar="N",
                   help="campaign: culling bundles per sphere kind, format and rounding "
                        "(default 5000)")
    g.add_argument("--shard-bundles", type=int, default=250, metavar="N",
                   help="campaign: bundles per culling shard (default 250)")
    g.add_argument("--spheres", type=int, default=16, metavar="N",
                   help="campaign: spheres per bundle (default 16)")
    g.add_argument("--campaign-seed", type=int, default=2026, metavar="S",
                   help="campaign: seed (default 2026)")
    g.add_argument("--out-dir", default="build/campaign", metavar="DIR",
                   help="campaign: shard directory (default build/campaign)")
    g.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="campaign: worker processes (default: os.cpu_count())")
    g.add_argument("--max-shards", type=int, default=None, metavar="K",
                   help="campaign: run at most K new shards, then stop (no merge)")
    g.add_argument("--results", default="docs/results/stress_campaign.json", metavar="FILE",
                   help="campaign: merged JSON (default docs/results/stress_campaign.json)")
    g.add_argument("--report", default="docs/stress-campaign.md", metavar="FILE",
                   help="campaign: markdown summary (default docs/stress-campaign.md)")
    g.add_argument("--no-progress", action="store_true", help="campaign: no progress bar")
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


def _split(text):
    return tuple(x.strip() for x in text.split(",") if x.strip())


def run_campaign(args) -> int:
    """``stress campaign``: run the missing shards, then merge and write the reports."""
    import sys
    import time

    from ..verify import campaign

    params = campaign.CampaignParams(
        formats=_split(args.campaign_formats), roundings=_split(args.roundings),
        families=() if args.families is None else _split(args.families),
        rays_per_family=args.rays_per_family, shard_rays=args.shard_rays,
        bundles=args.bundles, shard_bundles=args.shard_bundles,
        spheres_per_bundle=args.spheres, seed=args.campaign_seed)
    t0 = time.perf_counter()
    try:
        info = campaign.run_campaign(params, args.out_dir, args.jobs, args.max_shards,
                                     progress=not args.no_progress)
    except KeyboardInterrupt:
        print("\ninterrupted: finished shards are kept; run the same command to resume",
              file=sys.stderr)
        return 130
    print(f"{info['run']} shards run, {info['reused']} reused, {info['pending']} of "
          f"{info['shards']} missing ({info['wall_s']:.1f} s)")
    if info["pending"]:
        print("campaign incomplete: run the same command again to resume; not merged")
        return 0
    command = " ".join(["raplas-hdl stress campaign", "--formats", args.campaign_formats,
                        "--roundings", args.roundings]
                       + (["--families", args.families] if args.families else [])
                       + ["--rays-per-family", str(args.rays_per_family),
                          "--shard-rays", str(args.shard_rays), "--bundles", str(args.bundles),
                          "--shard-bundles", str(args.shard_bundles),
                          "--spheres", str(args.spheres),
                          "--campaign-seed", str(args.campaign_seed),
                          "--out-dir", args.out_dir]
                       + (["--jobs", str(args.jobs)] if args.jobs else []))
    doc = campaign.merge(params, args.out_dir, command,
                         {"wall_s": time.perf_counter() - t0, "shards_run": info["run"],
                          "shards_reused": info["reused"]})
    campaign.write_outputs(doc, args.results, args.report)
    tot, g = doc["totals"], doc["guarantees"]
    print(f"{tot['cases']:,} cases ({tot['raytri_pairs']:,} ray-triangle pairs x 2 modes, "
          f"{tot['sphere_tests']:,} culling sphere tests); CPU {doc['cpu_s']:.0f} s")
    print(f"in-domain culling false rejections {g['culling_false_rejections']}; conservative "
          f"false misses {g['conservative_false_misses']}, leaks {g['conservative_leaks']}")
    print(f"written {args.results} and {args.report}")
    if not g["ok"]:
        print("GUARANTEE VIOLATED (see the report)")
        return 1
    return 0


def run(args) -> int:
    if args.target == "campaign":
        return run_campaign(args)
    from ..fp import parse_format
    from ..verify import stress

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
