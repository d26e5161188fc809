"""``raplas-hdl bench``: run time against error over formats, roundings, modes, scenes, bundle
sizes and backends, with hardware cost from Yosys and the Pareto fronts (issue 6, point 1).

Renders procedural scenes at 128x128 and meshes at 256x256 with 3x3 soft shadows; beside
the software time, each point gets its frame time on one XC4VSX35 (the synthesised
intersection unit's cycles for the frame from the model's counters, over the units that fit
and the clock) and the result link's traffic. A point may issue at most --max-pairs pairs:
a point estimated (by a low-resolution pre-pass) to issue more is reported as capped.

Writes results.csv, results.json and PNG plots under --out (default build/bench, with
--quick build/bench-quick) and a markdown report at --report (default <out>/bench.md).
Nothing goes to docs/ unless asked: to regenerate the committed report give
--out docs/results/bench --report docs/bench.md. With --max-pairs 100000000 and --meshes
none (the procedural and bundle grids, 200 points) it took 25 minutes of CPU (one thread per
render; 36 minutes of wall time on 2 shared cores); the meshes add well over an hour, most of
it the conservative and certified modes, whose hits the host re-checks.
--quick takes 10-20 s with warm caches. The points run in this process, one after the
other (the timings are per core); with --scheduler ADDRESS or --dask-workers N they run on a
Dask cluster (pip install 'raplas-hdl[cluster]'), grouped by scene, bundle size and bound:
the same results, in less wall time.
"""

from __future__ import annotations

import os
import shlex
from pathlib import Path

from .. import cluster
from ..model.modes import MODES
from . import grammar as g

__all__ = ["add_parser", "check", "run", "spec_from_args"]

BENCH_OUT = os.path.join("build", "bench")
QUICK_OUT = os.path.join("build", "bench-quick")
MAX_PER_FAMILY = 1_000_000
MAX_REPEAT = 100
MAX_MAX_PAIRS = 10**12
SCENE_NAMES = ("cornell", "spheres", "terrain", "soup")

#: The options of a sweep (none applies with --from-json).
SWEEP_OPTIONS = ("quick", "format", "rounding", "modes", "scenes", "meshes", "bundles",
                 "size", "mesh_size", "shadow", "rtl", "per_family", "seed", "repeat",
                 "max_pairs", "waves", "scheduler", "dask_workers")


def add_parser(subparsers):
    p = subparsers.add_parser(
        "bench", help="benchmark: run time against error, hardware cost, Pareto fronts",
        description=__doc__.split("\n\n", 1)[1])
    p.add_argument("--quick", action="store_true",
                   help="small sweep (FP16, FP24, FP32; rtz; paper; cornell, spheres; 8x8; "
                        "32x32, 2x2 shadows; one point under a cap of 1000 pairs, which comes "
                        "out capped): 10-20 s with warm caches")
    g.add_format_option(p, multiple=True, plural=True, default="FP16,FP20,FP24,FP32; quick "
                        "FP16,FP24,FP32", rounding_default="rtz,rne,chop; quick rtz")
    p.add_argument("--modes", default=None, metavar="LIST",
                   help="comma-separated ray-triangle modes: paper, conservative (default "
                        "both; quick paper)")
    p.add_argument("--scenes", default=None, metavar="LIST",
                   help="comma-separated procedural scenes: " + ", ".join(SCENE_NAMES)
                        + " (default all; quick cornell,spheres)")
    p.add_argument("--meshes", default=None, metavar="DIR",
                   help="directory of mesh files, or none (default the meshes shipped with "
                        "the package; quick none)")
    p.add_argument("--bundles", default=None, metavar="LIST",
                   help=f"comma-separated bundle sizes RxC, sides 1 to {g.MAX_LATTICE}, the "
                        "first is the main one (default 8x8,4x4,16x16; quick 8x8)")
    p.add_argument("--size", type=g.size_type("--size"), default=None, metavar="WxH",
                   help=f"image size of procedural scenes, sides 1 to {g.MAX_IMAGE} "
                        "(default 128x128; quick 32x32)")
    p.add_argument("--mesh-size", type=g.size_type("--mesh-size"), default=None,
                   metavar="WxH", help=f"image size of mesh scenes, sides 1 to {g.MAX_IMAGE} "
                                       "(default 256x256; quick 32x32)")
    p.add_argument("--shadow", type=g.lattice_type("--shadow"), default=None, metavar="RxC",
                   help=f"shadow lattice per point, sides 1 to {g.MAX_LATTICE}, or 0 for no "
                        "shadows (default 3x3; quick 2x2)")
    p.add_argument("--max-pairs", type=g.int_range(1, MAX_MAX_PAIRS), default=None,
                   metavar="N", help=f"pairs a point may issue, 1 to {MAX_MAX_PAIRS:.0e}; a "
                                     "point estimated to issue more is reported as capped "
                                     "(default 500,000,000)")
    p.add_argument("--rtl", default=None, type=g.choice("icarus", "verilator", what="simulator"),
                   metavar="{icarus,verilator}",
                   help="also run one tiny point through the RTL under this simulator (slow)")
    p.add_argument("--per-family", type=g.int_range(1, MAX_PER_FAMILY), default=None,
                   metavar="N", help=f"stress rays per family for the R metrics, 1 to "
                                     f"{MAX_PER_FAMILY:,} (default 2000; quick 300)")
    p.add_argument("--seed", type=int, default=None, metavar="S", help="seed (default 0)")
    p.add_argument("--repeat", type=g.int_range(1, MAX_REPEAT), default=None, metavar="N",
                   help=f"renders per point, 1 to {MAX_REPEAT}; the fastest run's timings "
                        "are kept (default 1)")
    p.add_argument("--out", "--out-dir", dest="out", default=None, metavar="DIR",
                   help=f"directory of the CSV, JSON and plots (default {BENCH_OUT}, quick "
                        f"{QUICK_OUT}; --out-dir is its old name)")
    p.add_argument("--report", default=None, metavar="FILE.md",
                   help="markdown report (default <out>/bench.md)")
    p.add_argument("--from-json", default=None, metavar="FILE.json",
                   help="do not run: rewrite the CSV, plots and report from a results.json")
    p.add_argument("--quiet", action="store_true", help="no per-point progress lines")
    g.add_waves_option(p, "the --rtl point's simulations")
    cluster.add_options(p, "points (the --rtl point and the Yosys costs stay here)")
    return p


def _list(text, name, known=None):
    items = [x.strip() for x in text.split(",") if x.strip()]
    if not items:
        raise g.UsageError(f"{name} is empty")
    if known is not None:
        for x in items:
            if x not in known:
                raise g.UsageError(f"{name}: unknown value {x!r}; use {', '.join(known)}")
    return items


def spec_from_args(args):
    """The :class:`~raplas_hdl.bench.plan.BenchSpec` an argument namespace asks for."""
    from ..bench.plan import full_spec, quick_spec

    kw = {}
    if args.format:
        kw["formats"] = g.format_names(args, ())
    if args.rounding:
        kw["roundings"] = g.roundings_of(args, ())
    if args.modes:
        kw["modes"] = _list(args.modes, "--modes", MODES)
    if args.scenes:
        kw["scenes"] = _list(args.scenes, "--scenes", SCENE_NAMES)
    if args.meshes is not None:
        kw["mesh_dir"] = None if args.meshes.lower() == "none" else args.meshes
    if args.bundles:
        kw["bundles"] = g.lattice_list(args.bundles, "--bundles")
    if args.size:
        kw["size"] = args.size
    if args.mesh_size:
        kw["mesh_size"] = args.mesh_size
    if args.shadow is not None:
        kw["shadow"] = args.shadow
    if args.per_family is not None:
        kw["per_family"] = args.per_family
    if args.max_pairs is not None:
        kw["max_pairs"] = args.max_pairs
    kw.update(rtl=args.rtl, seed=args.seed or 0, repeats=args.repeat or 1)
    return quick_spec(**kw) if args.quick else full_spec(**kw)


def check(args) -> None:
    if args.from_json:
        g.reject(args, SWEEP_OPTIONS, "with --from-json (it rewrites the outputs of a "
                                      "finished run)")
        g.check_input_file(args.from_json, "--from-json", (".json",))
        from ..bench.report import load_results

        try:
            args.results = load_results(args.from_json)
        except (ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"--from-json {args.from_json!r} is not a bench results.json "
                             f"({type(exc).__name__}: {g.one_line(exc)})") from None
    else:
        if args.meshes is not None and args.meshes.lower() != "none":
            p = Path(args.meshes)
            if not p.is_dir():
                raise g.UsageError(f"--meshes {args.meshes!r} is not a directory (give none "
                                   "for no meshes)")
        args.spec = spec_from_args(args)
        g.check_waves(args, args.rtl, applies=args.rtl is not None,
                      why="without --rtl (only the rtl point simulates)")
        if args.rtl:
            g.require_simulator(args.rtl)
        cluster.check_options(args)
    args.out = args.out or (QUICK_OUT if args.quick else BENCH_OUT)
    g.check_output_dir(args.out, "--out")
    args.report = args.report or os.path.join(args.out, "bench.md")
    g.check_output_file(args.report, (".md",), "--report", must_exist_dir=False)


def run(args) -> int:
    from ..bench.report import write_outputs
    from ..bench.sweep import run_sweep

    command = _command(args)
    if args.from_json:
        for f in write_outputs(args.results, args.out, args.report, command=command):
            print(f"  wrote {f}")
        return 0
    executor = cluster.executor_from_args(args) if cluster.command_options(args) else None
    try:
        with g.waves(args):
            results = run_sweep(args.spec, progress=None if args.quiet else _say,
                                executor=executor)
    finally:
        if executor is not None:
            executor.close()
    files = write_outputs(results, args.out, args.report, command=command)
    print(f"bench: {len(results['points'])} points in {results['wall_seconds']:.0f} s")
    for f in files:
        print(f"  wrote {f}")
    return 0


def _command(args) -> str:
    """The command line that reproduces this run (from the parsed options)."""
    parts = ["raplas-hdl", "bench"]
    if args.quick:
        parts.append("--quick")
    if args.format:
        parts += ["--format", ",".join(g.format_names(args, ()))]
    if args.rounding:
        parts += ["--rounding", ",".join(g.roundings_of(args, ()))]
    for opt, dest in (("--modes", "modes"), ("--scenes", "scenes"), ("--meshes", "meshes"),
                      ("--bundles", "bundles"), ("--rtl", "rtl"),
                      ("--per-family", "per_family"), ("--max-pairs", "max_pairs"),
                      ("--out", "out"),
                      ("--report", "report"), ("--from-json", "from_json")):
        v = getattr(args, dest)
        if v is not None:
            parts += [opt, str(v)]
    for opt, dest in (("--size", "size"), ("--mesh-size", "mesh_size"),
                      ("--shadow", "shadow")):
        v = getattr(args, dest)
        if v is not None:
            parts += [opt, "0" if v == (0, 0) else f"{v[0]}x{v[1]}"]
    if args.seed:
        parts += ["--seed", str(args.seed)]
    if args.repeat and args.repeat != 1:
        parts += ["--repeat", str(args.repeat)]
    parts += cluster.command_options(args)
    return " ".join(shlex.quote(p) for p in parts)


def _say(line):
    print(line, flush=True)
