"""``raplas-hdl bench``: run time against error over formats, roundings, modes, scenes, bundle
sizes and backends, with hardware cost from Yosys and the Pareto fronts (issue 6, point 1).

Writes ``results.csv``, ``results.json`` and PNG plots under ``--out-dir`` and a markdown
report at ``--report``. The default campaign takes about 20 minutes on 2 cores;
``--quick`` about 3 (cold caches).
"""

from __future__ import annotations

import shlex
from pathlib import Path

__all__ = ["add_parser", "run"]

ROOT = Path(__file__).resolve().parents[2]


def add_parser(subparsers):
    p = subparsers.add_parser(
        "bench", help="benchmark: run time against error, hardware cost, Pareto fronts",
        description="Sweep formats x roundings x ray-triangle modes x scenes x bundle sizes "
                    "x backends; measure run time per stage, throughput, error against "
                    "float64 and against the exact reference R, and the Yosys cost of each "
                    "format; write CSV/JSON, PNG plots and a markdown report.")
    p.add_argument("--quick", action="store_true",
                   help="small sweep (FP16, FP24, FP32; rtz; paper; cornell, spheres; 8x8; "
                        "32x32): about 3 minutes")
    p.add_argument("--formats", default=None, metavar="LIST",
                   help="comma-separated formats (default FP16,FP20,FP24,FP32)")
    p.add_argument("--format", action="append", default=[], dest="extra_formats",
                   metavar="FMT", help="an extra format, e.g. e6m17 (repeatable)")
    p.add_argument("--roundings", default=None, metavar="LIST",
                   help="comma-separated roundings (default rtz,rne,chop)")
    p.add_argument("--modes", default=None, metavar="LIST",
                   help="comma-separated ray-triangle modes (default paper,conservative)")
    p.add_argument("--scenes", default=None, metavar="LIST",
                   help="comma-separated procedural scenes (default cornell,spheres,terrain,"
                        "soup)")
    p.add_argument("--meshes", default=None, metavar="DIR",
                   help="directory of mesh files (default ../shared/meshes; 'none' for none; "
                        "a missing directory is skipped with a note)")
    p.add_argument("--bundles", default=None, metavar="LIST",
                   help="comma-separated bundle sizes, the first is the main one "
                        "(default 8x8,4x4,16x16)")
    p.add_argument("--size", default=None, metavar="WxH",
                   help="image size of procedural scenes (default 32x32)")
    p.add_argument("--mesh-size", default=None, metavar="WxH",
                   help="image size of mesh scenes (default 32x32)")
    p.add_argument("--shadow", default=None, metavar="RxC",
                   help="shadow lattice per point (default 2x2; 0 for no shadows)")
    p.add_argument("--rtl", default=None, choices=("icarus", "verilator"),
                   help="also run one tiny point through the RTL (slow)")
    p.add_argument("--per-family", type=int, default=None, metavar="N",
                   help="stress rays per family for the R metrics (default 2000; quick 300)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--repeat", type=int, default=1, metavar="N",
                   help="renders per point; the fastest run's timings are kept (default 1)")
    p.add_argument("--out-dir", default=None, metavar="DIR",
                   help="CSV, JSON and plots (default docs/results/bench, quick: "
                        "build/bench-quick)")
    p.add_argument("--report", default=None, metavar="FILE",
                   help="markdown report (default docs/bench.md, quick: "
                        "<out-dir>/bench.md)")
    p.add_argument("--from-json", default=None, metavar="FILE",
                   help="do not run: rewrite the CSV, plots and report from a results.json")
    p.add_argument("--quiet", action="store_true", help="no per-point progress lines")
    return p


def _list(text):
    return [x.strip() for x in text.split(",") if x.strip()]


def _pair(text, name):
    from .render import _lattice

    r, c = _lattice(text, name)
    return (r, c)


def spec_from_args(args):
    """The :class:`~raplas_hdl.bench.sweep.BenchSpec` an argument namespace asks for."""
    from ..bench.sweep import full_spec, quick_spec
    from .render import _size

    kw = {}
    if args.formats:
        kw["formats"] = _list(args.formats)
    if args.roundings:
        kw["roundings"] = _list(args.roundings)
    if args.modes:
        kw["modes"] = _list(args.modes)
    if args.scenes:
        kw["scenes"] = _list(args.scenes)
    if args.meshes is not None:
        kw["mesh_dir"] = None if args.meshes.lower() == "none" else args.meshes
    if args.bundles:
        kw["bundles"] = [_pair(b, "--bundles") for b in _list(args.bundles)]
        if any(b == (0, 0) for b in kw["bundles"]):
            raise ValueError("--bundles cannot contain 0")
    if args.size:
        kw["size"] = _size(args.size)
    if args.mesh_size:
        kw["mesh_size"] = _size(args.mesh_size)
    if args.shadow:
        kw["shadow"] = _pair(args.shadow, "--shadow")
    if args.per_family is not None:
        kw["per_family"] = args.per_family
    kw.update(rtl=args.rtl, seed=args.seed, repeats=args.repeat)
    spec = quick_spec(**kw) if args.quick else full_spec(**kw)
    for f in args.extra_formats:
        if f not in spec.formats:
            spec.formats.append(f)
    spec.__post_init__()
    return spec


def run(args) -> int:
    from ..bench.report import load_results, write_outputs
    from ..bench.sweep import run_sweep

    if args.from_json:
        results = load_results(args.from_json)
        out_dir = Path(args.out_dir) if args.out_dir else Path(args.from_json).parent
        report = Path(args.report) if args.report else ROOT / "docs" / "bench.md"
        for f in write_outputs(results, out_dir, report, command=_command(args)):
            print(f"  wrote {f}")
        return 0
    spec = spec_from_args(args)
    out_dir = Path(args.out_dir) if args.out_dir else (
        ROOT / "build" / "bench-quick" if args.quick else ROOT / "docs" / "results" / "bench")
    report = Path(args.report) if args.report else (
        out_dir / "bench.md" if args.quick else ROOT / "docs" / "bench.md")
    command = _command(args)
    results = run_sweep(spec, progress=None if args.quiet else _say)
    files = write_outputs(results, out_dir, report, command=command)
    print(f"bench: {len(results['points'])} points in {results['wall_seconds']:.0f} s")
    for f in files:
        print(f"  wrote {f}")
    return 0


def _command(args) -> str:
    """The command line that reproduces this run (from the parsed options)."""
    parts = ["raplas-hdl", "bench"]
    if args.quick:
        parts.append("--quick")
    for opt, dest in (("--formats", "formats"), ("--roundings", "roundings"),
                      ("--modes", "modes"), ("--scenes", "scenes"), ("--meshes", "meshes"),
                      ("--bundles", "bundles"), ("--size", "size"),
                      ("--mesh-size", "mesh_size"), ("--shadow", "shadow"), ("--rtl", "rtl"),
                      ("--per-family", "per_family"), ("--out-dir", "out_dir"),
                      ("--report", "report"), ("--from-json", "from_json")):
        v = getattr(args, dest)
        if v is not None:
            parts += [opt, str(v)]
    for f in args.extra_formats:
        parts += ["--format", f]
    if args.seed:
        parts += ["--seed", str(args.seed)]
    if args.repeat != 1:
        parts += ["--repeat", str(args.repeat)]
    return " ".join(shlex.quote(p) for p in parts)


def _say(line):
    print(line, flush=True)
