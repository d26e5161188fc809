"""``raplas-hdl demo``: the README's main job.

1. Emit the Verilog of every unit into build/verilog/ (one file and JSON manifest each; a
   unit that fails is reported, the render still runs, and the exit status is 1), in a
   second process while the renders run;
2. render the default scene (the Cornell box) with the bit-accurate model backend (FP24)
   and with the float64 reference;
3. write both PNGs and the difference image, and print the summary with the image error
   of the model against float64.

The scene, the size and the output directories are checked before step 1.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from . import grammar as g


def add_parser(subparsers):
    from .render import add_render_options

    p = subparsers.add_parser(
        "demo", help="emit the Verilog, render the default scene with model and float64",
        description=__doc__.split("\n\n", 1)[1])
    p.add_argument("--scene", default="cornell", metavar="NAME|FILE",
                   help="cornell | spheres | terrain | soup | a shipped mesh (stanford-bunny, "
                        "teapot, spot, suzanne, stanford-dragon-100k) | path to .obj/.ply/.stl "
                        "(default cornell)")
    p.add_argument("--size", type=g.size_type("--size"), default=(64, 64), metavar="WxH",
                   help=f"image size, sides 1 to {g.MAX_IMAGE} (default 64x64)")
    p.add_argument("--out", "--out-dir", dest="out", default="build/demo", metavar="DIR",
                   help="where the PNGs and the JSON summary go (default build/demo)")
    p.add_argument("--verilog-dir", default=None, metavar="DIR",
                   help="where the Verilog goes (default build/verilog)")
    p.add_argument("--no-verilog", action="store_true", help="skip the Verilog step")
    add_render_options(p)
    return p


def emit_verilog(outdir: Path, fmt) -> tuple[list, list]:
    """Emit every registered unit; returns (written paths, (unit, reason) failures).
    Runs in a worker process of :func:`run` (arguments and results are plain data)."""
    outdir = Path(outdir)
    try:
        from ..rtl.units import UNITS, emit_all
    except ImportError as exc:
        return [], [("all", f"the RTL generators are not available ({exc})")]
    written, failed = [], []
    outdir.mkdir(parents=True, exist_ok=True)
    for name in UNITS:
        try:
            written += emit_all(outdir, fmt, names=[name])
        except ImportError as exc:
            failed.append((name, f"generator not available ({exc})"))
        except Exception as exc:  # noqa: BLE001 (report and go on: the render needs no RTL)
            failed.append((name, f"{type(exc).__name__}: {exc}"))
    return written, failed


def check(args) -> None:
    from .render import check_scene, resolve_mode

    args.fmt = g.format_from_args(args)
    resolve_mode(args)
    if args.no_verilog:
        g.reject(args, ("verilog_dir",), "with --no-verilog")
    else:
        args.verilog_dir = args.verilog_dir or "build/verilog"
        g.check_output_dir(args.verilog_dir, "--verilog-dir")
    check_scene(args.scene)
    g.check_output_dir(args.out, "--out")


def run(args) -> int:
    from ..host.scenes import get_scene

    t0 = time.perf_counter()
    scene = get_scene(args.scene, bound=None)   # a bad mesh fails here, before the Verilog

    from ..host.backends import make_backend
    from ..host.output import compare, difference_image, format_summary, save_png
    from ..host.render import render
    from .render import settings_from_args

    fmt = args.fmt
    size = args.size
    settings = settings_from_args(args, size)
    scene = scene.normalised(settings.bound)
    failed = []
    emission = pool = None
    if not args.no_verilog:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        vdir = Path(args.verilog_dir)
        print(f"[1/3] Verilog ({fmt}): emitting every unit into {vdir}/ in a second process")
        pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
        emission = pool.submit(emit_verilog, str(vdir), fmt)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    shadow = "off" if args.shadow == (0, 0) else f"{args.shadow[0]}x{args.shadow[1]}"
    print(f"[2/3] rendering {scene.name} ({scene.n_triangles} triangles) at "
          f"{size[0]}x{size[1]}, shadows {shadow}: model {fmt} {args.mode}, then float64")
    try:
        model = render(scene, make_backend("model", fmt, mode=args.mode), settings)
        ref = render(scene, make_backend("float64"), settings)
        if emission is not None:
            written, failed = emission.result()
            print(f"[1/3] Verilog ({fmt}): {len(written)} unit(s) written to {vdir}/")
            for path in written:
                print(f"      {path}")
            for name, why in failed:
                print(f"      {name}: FAILED: {why}", file=sys.stderr)
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    cmp = compare(model, ref)
    paths = {"model": out / f"{scene.name}_model.png", "float64": out / f"{scene.name}_float64.png",
             "diff": out / f"{scene.name}_diff.png"}
    save_png(model.image, paths["model"])
    save_png(ref.image, paths["float64"])
    save_png(difference_image(model, ref), paths["diff"], linear=False)
    summary = out / f"{scene.name}_summary.json"
    summary.write_text(json.dumps(g.jsonable({"model": {"stats": model.stats,
                                                        "timings": model.timings},
                                              "float64": {"stats": ref.stats,
                                                          "timings": ref.timings},
                                              "comparison": cmp}), indent=2))
    print("[3/3] summary")
    print(format_summary(model, cmp))
    print(format_summary(ref))
    print(f"wrote {paths['model']}, {paths['float64']}, {paths['diff']} (x4 difference, "
          f"magenta: nearest triangle differs), {summary}")
    print(f"demo done in {time.perf_counter() - t0:.1f} s")
    if failed:
        print(f"raplas-hdl demo: {len(failed)} unit(s) failed to emit Verilog (see above)",
              file=sys.stderr)
        return 1
    return 0
