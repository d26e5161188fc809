"""``raplas-hdl stress ray-triangle``: the seeded numerical stress suite of the ray-triangle
unit (golden model) against the exact reference R, as a table per format and mode.

``raplas-hdl stress campaign``: the same families and the plane-culling proof at scale,
sharded over the machine's cores (or a Dask cluster: --scheduler, --dask-workers), resumable
(:mod:`raplas_hdl.verify.campaign`). Its reports go under build/stress-campaign/ unless
--out (or --results/--report) says otherwise."""

from __future__ import annotations

import json
import os

from .. import cluster
from ..model.modes import MODES
from . import grammar as g

__all__ = ["add_parser", "check", "run", "format_table"]

COLUMNS = ("pairs", "unguaranteed", "r_hits", "unit_hits", "false_hits", "false_misses",
           "uncertain", "edge_rays", "leaks", "t_rel_median", "t_rel_max")

#: Limits of the sizes (stated in --help).
MAX_PER_FAMILY = 1_000_000
MAX_CAMPAIGN_RAYS = 10_000_000
MAX_CAMPAIGN_BUNDLES = 1_000_000
MAX_SPHERES = 256
MAX_JOBS = 256

CAMPAIGN_OUT = os.path.join("build", "stress-campaign")
CAMPAIGN_SHARDS = os.path.join("build", "campaign")


def _families(text: str) -> tuple:
    from ..model.stress_cases import FAMILIES

    names = tuple(x.strip() for x in text.split(",") if x.strip())
    if not names:
        raise ValueError("--families is empty")
    for n in names:
        if n not in FAMILIES:
            raise ValueError(f"unknown stress family {n!r}; known: {', '.join(FAMILIES)}")
    return names


def add_parser(subparsers):
    p = subparsers.add_parser(
        "stress", help="numerical stress suites against exact references",
        description="Run a seeded stress suite and print false hits, false misses, leaks and "
                    "the relative error of t per case family, against the exact reference R.")
    sub = p.add_subparsers(dest="target", metavar="TARGET")
    sub.required = True

    r = sub.add_parser(
        "ray-triangle", help="the ray-triangle unit's stress families, a table per format",
        description="The seeded stress families of the ray-triangle unit (golden model) "
                    "against the exact reference R: a table per format and mode.")
    g.add_format_option(r, multiple=True, default="FP24/rtz")
    r.add_argument("--mode", type=g.choice(*MODES, "all", "both", what="mode"),
                   default="all", metavar="{" + ",".join(MODES) + ",all}",
                   help="ray-triangle mode(s) (default all; 'both' is an old name of all)")
    r.add_argument("--per-family", type=g.int_range(1, MAX_PER_FAMILY), default=1000,
                   metavar="N", help=f"rays per family, 1 to {MAX_PER_FAMILY:,} (default 1000)")
    r.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    r.add_argument("--families", default=None, metavar="LIST",
                   help="comma-separated subset of the families (default: all)")
    r.add_argument("--margin-scale", type=g.float_range(0.0, 1e6, lo_open=True), default=1.0,
                   metavar="S", help="scale s of the conservative margin and of every certified "
                                     "bound, above 0 (default 1: the derivation)")
    r.add_argument("--bisect", action="store_true",
                   help="also find the smallest s with zero false misses (conservative mode) "
                        "and the largest s < 1 that mis-certifies a pair (certified mode: "
                        "the negative control)")
    r.add_argument("--json", default=None, metavar="FILE.json",
                   help="write the results as JSON")
    r.set_defaults(_check_target=check_ray_triangle, _run_target=run_ray_triangle)

    c = sub.add_parser(
        "campaign", help="the stress families and the culling proof at scale (resumable)",
        description="The stress families and the plane-culling proof over formats, roundings "
                    "and both modes (48.5 M cases by default), sharded over the cores (or "
                    "a Dask cluster: --scheduler, --dask-workers), seeded, resumable: run "
                    "the same command again after an interruption. "
                    f"Shards go to --shard-dir (default {CAMPAIGN_SHARDS}), the merged JSON "
                    f"and markdown report to --out (default {CAMPAIGN_OUT}). To regenerate "
                    "the committed report, give --results docs/results/stress_campaign.json "
                    "--report docs/stress-campaign.md.")
    g.add_format_option(c, multiple=True, plural=True, default="FP16,FP20,FP24,FP32",
                        rounding_default="rtz,rne,chop")
    c.add_argument("--families", default=None, metavar="LIST",
                   help="comma-separated subset of the ray-triangle families (default: all)")
    c.add_argument("--rays-per-family", type=g.int_range(0, MAX_CAMPAIGN_RAYS), default=50000,
                   metavar="N", help=f"rays per family, format and rounding, 0 to "
                                     f"{MAX_CAMPAIGN_RAYS:,} (default 50000)")
    c.add_argument("--shard-rays", type=g.int_range(1, MAX_CAMPAIGN_RAYS), default=5000,
                   metavar="N", help="rays per ray-triangle shard (default 5000)")
    c.add_argument("--bundles", type=g.int_range(0, MAX_CAMPAIGN_BUNDLES), default=5000,
                   metavar="N", help=f"culling bundles per sphere kind, format and rounding, "
                                     f"0 to {MAX_CAMPAIGN_BUNDLES:,} (default 5000)")
    c.add_argument("--shard-bundles", type=g.int_range(1, MAX_CAMPAIGN_BUNDLES), default=250,
                   metavar="N", help="bundles per culling shard (default 250)")
    c.add_argument("--spheres", type=g.int_range(1, MAX_SPHERES), default=16, metavar="N",
                   help=f"spheres per bundle, 1 to {MAX_SPHERES} (default 16)")
    c.add_argument("--seed", "--campaign-seed", dest="seed", type=int, default=2026,
                   metavar="S", help="seed (default 2026)")
    c.add_argument("--certified-scale", type=g.float_range(0.0, 1.0, lo_open=True),
                   default=1.0, metavar="S",
                   help="factor on every bound of the certified mode, in (0, 1] (default 1: "
                        "the guarantee; below the bisected factor the campaign must fail: "
                        "the negative control)")
    c.add_argument("--shard-dir", "--out-dir", dest="shard_dir", default=CAMPAIGN_SHARDS,
                   metavar="DIR", help=f"shard directory (default {CAMPAIGN_SHARDS}; "
                                       "--out-dir is its old name)")
    g.add_out_option(c, CAMPAIGN_OUT, "directory of the merged JSON (stress_campaign.json) "
                                      "and the report (stress-campaign.md)")
    c.add_argument("--results", default=None, metavar="FILE.json",
                   help="merged JSON (default <out>/stress_campaign.json)")
    c.add_argument("--report", default=None, metavar="FILE.md",
                   help="markdown summary (default <out>/stress-campaign.md)")
    c.add_argument("--jobs", type=g.int_range(1, MAX_JOBS), default=None, metavar="N",
                   help=f"worker processes of the local pool, 1 to {MAX_JOBS} (default: the "
                        "number of cores)")
    c.add_argument("--max-shards", type=g.int_range(1), default=None, metavar="K",
                   help="run at most K new shards, then stop (no merge)")
    c.add_argument("--no-progress", action="store_true", help="no progress bar")
    cluster.add_options(c, "shards")
    c.set_defaults(_check_target=check_campaign, _run_target=run_campaign)
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


def check(args) -> None:
    args._check_target(args)


def run(args) -> int:
    return args._run_target(args)


# -- stress ray-triangle --------------------------------------------------------------

def check_ray_triangle(args) -> None:
    args.fmts = g.formats_from_args(args, default=("FP24/rtz",), default_roundings=("rtz",))
    args.family_list = None if args.families is None else _families(args.families)
    if args.bisect and args.mode == "paper":
        raise g.UsageError("--bisect applies to the conservative and certified modes; not "
                           "with --mode paper")
    if args.json:
        g.check_output_file(args.json, (".json",), "--json")


def run_ray_triangle(args) -> int:
    from ..model import stress_cases
    from ..verify import stress

    families = stress_cases.FAMILIES if args.family_list is None else args.family_list
    modes = MODES if args.mode in ("all", "both") else (args.mode,)
    results = []
    status = 0
    for fmt in args.fmts:
        cases = stress_cases.generate(fmt, args.per_family, args.seed, families)
        enc = stress.reference(cases, fmt)
        for mode in modes:
            table = stress.evaluate(cases, enc, mode, args.margin_scale)
            tot = stress.pooled(table)
            print(f"\n{fmt} {mode}" + (f" s={args.margin_scale:g}" if mode != "paper"
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
            if mode == "certified":
                if tot["false_hits"] or tot["false_misses"] or tot["leaks"]:
                    print("certified mode: MIS-CERTIFIED PAIRS INSIDE THE DOMAIN")
                    status = 1
                if args.bisect:
                    b = stress.bisect_certified(cases, enc)
                    entry["bisection"] = b
                    print("negative control: " + (
                        "no pair mis-certified down to s = {:.4g}".format(b["s_pass"])
                        if b["s_fail"] is None else
                        f"bounds x{b['s_fail']:.4g} mis-certify {b['wrong_at_fail']} pair(s); "
                        f"x{b['s_pass']:.4g} none (slack of the bound: "
                        f"{1 / b['s_fail']:.3g}x)"))
            results.append(entry)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1, sort_keys=True)
            fh.write("\n")
        print(f"wrote {args.json}")
    return status


# -- stress campaign --------------------------------------------------------------------

def check_campaign(args) -> None:
    from ..verify import campaign

    args.format_names = g.format_names(args, ("FP16", "FP20", "FP24", "FP32"))
    args.rounding_names = g.roundings_of(args, ("rtz", "rne", "chop"))
    families = () if args.families is None else _families(args.families)
    args.params = campaign.CampaignParams(
        formats=tuple(args.format_names), roundings=tuple(args.rounding_names),
        families=families, rays_per_family=args.rays_per_family,
        shard_rays=args.shard_rays, bundles=args.bundles, shard_bundles=args.shard_bundles,
        spheres_per_bundle=args.spheres, seed=args.seed,
        certified_scale=args.certified_scale)
    out = args.out or CAMPAIGN_OUT
    args.results = args.results or os.path.join(out, "stress_campaign.json")
    args.report = args.report or os.path.join(out, "stress-campaign.md")
    g.check_output_dir(args.shard_dir, "--shard-dir")
    for opt, path, ext in (("--results", args.results, ".json"),
                           ("--report", args.report, ".md")):
        g.check_output_file(path, (ext,), opt, must_exist_dir=False)
    g.check_distinct(**{"--results": args.results, "--report": args.report})
    cluster.check_options(args, conflicts=("jobs",))


def _campaign_command(args) -> str:
    """The command line that reproduces the campaign (the committed reports quote it)."""
    parts = ["raplas-hdl stress campaign", "--formats", ",".join(args.format_names),
             "--roundings", ",".join(args.rounding_names)]
    if args.families:
        parts += ["--families", args.families]
    parts += ["--rays-per-family", str(args.rays_per_family), "--shard-rays",
              str(args.shard_rays), "--bundles", str(args.bundles), "--shard-bundles",
              str(args.shard_bundles), "--spheres", str(args.spheres), "--seed",
              str(args.seed), "--shard-dir", args.shard_dir]
    if args.certified_scale != 1.0:
        parts += ["--certified-scale", repr(args.certified_scale)]
    if args.jobs:
        parts += ["--jobs", str(args.jobs)]
    return " ".join(parts + cluster.command_options(args))


def run_campaign(args) -> int:
    """``stress campaign``: run the missing shards, then merge and write the reports."""
    import sys
    import time

    from ..verify import campaign

    params = args.params
    t0 = time.perf_counter()
    try:
        with cluster.executor_from_args(args, args.jobs,
                                        campaign.worker_versions) as executor:
            info = campaign.run_campaign(params, args.shard_dir, max_shards=args.max_shards,
                                         progress=not args.no_progress, executor=executor)
    except KeyboardInterrupt:
        print("\ninterrupted: finished shards are kept; run the same command to resume",
              file=sys.stderr)
        return 130
    print(f"{info['run']} shards run ({info['executor']}), {info['reused']} reused, "
          f"{info['pending']} of {info['shards']} missing ({info['wall_s']:.1f} s)")
    if info["pending"]:
        print("campaign incomplete: run the same command again to resume; not merged")
        return 0
    doc = campaign.merge(params, args.shard_dir, _campaign_command(args),
                         {"wall_s": time.perf_counter() - t0, "shards_run": info["run"],
                          "shards_reused": info["reused"], "executor": info["executor"]})
    campaign.write_outputs(doc, args.results, args.report)
    tot, gu = doc["totals"], doc["guarantees"]
    print(f"{tot['cases']:,} cases ({tot['raytri_pairs']:,} ray-triangle pairs x "
          f"{len(MODES)} modes, "
          f"{tot['sphere_tests']:,} culling sphere tests); CPU {doc['cpu_s']:.0f} s")
    print(f"in-domain culling false rejections {gu['culling_false_rejections']}; conservative "
          f"false misses {gu['conservative_false_misses']}, leaks {gu['conservative_leaks']}; "
          f"certified mis-certified pairs {gu['certified_mis_certified']}, leaks "
          f"{gu['certified_leaks']}")
    print(f"written {args.results} and {args.report}")
    if not gu["ok"]:
        print("GUARANTEE VIOLATED (see the report)")
        return 1
    return 0
