"""``raplas-hdl render``: render a scene through a backend and print the summary."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"size {text!r} is not WxH (for example 128x96)") from None
    if w < 1 or h < 1:
        raise ValueError(f"size {text!r} must be at least 1x1")
    return w, h


def _lattice(text: str, name: str) -> tuple[int, int]:
    if text in ("0", "off", "none"):
        return 0, 0
    try:
        r, c = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"{name} {text!r} is not RxC (for example 4x4)") from None
    if r < 1 or c < 1 or r > 64 or c > 64:
        raise ValueError(f"{name} {text!r}: rows and cols must be 1 to 64")
    return r, c


def add_render_options(p):
    """Options shared by ``render`` and ``demo``."""
    from .verilog import add_format_options

    add_format_options(p)
    p.add_argument("--mode", choices=("paper", "conservative"), default="paper",
                   help="ray-triangle mode of the model/rtl backends (default paper)")
    p.add_argument("--tile", default="8x8", help="primary bundle size RxC (default 8x8)")
    p.add_argument("--shadow", default="3x3",
                   help="light lattice of a shadow bundle RxC, or 0 for no shadows "
                        "(default 3x3)")
    p.add_argument("--tris-per-sphere", type=int, default=8,
                   help="triangles per bounding sphere (default 8)")
    p.add_argument("--fanout", type=int, default=8, help="sphere hierarchy fan-out (default 8)")
    p.add_argument("--no-hierarchy", action="store_true",
                   help="send every leaf sphere to the unit (no host hierarchy cull)")
    p.add_argument("--no-early-out", action="store_true",
                   help="do not disable blocked shadow rays between sphere batches")
    p.add_argument("--batch", type=int, default=16,
                   help="leaf spheres per shadow run (early-out granularity, default 16)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def settings_from_args(args, size):
    from ..host.render import RenderSettings

    rows, cols = _lattice(args.tile, "--tile")
    if rows == 0:
        raise ValueError("--tile cannot be 0")
    sr, sc = _lattice(args.shadow, "--shadow")
    return RenderSettings(width=size[0], height=size[1], rows=rows, cols=cols,
                          shadow_rows=sr, shadow_cols=sc,
                          tris_per_sphere=args.tris_per_sphere, fanout=args.fanout,
                          hierarchy=not args.no_hierarchy, early_out=not args.no_early_out,
                          batch_spheres=args.batch, progress=not args.no_progress)


def add_parser(subparsers):
    p = subparsers.add_parser(
        "render", help="render a scene through the float64, model or rtl backend",
        description="Render a procedural scene (cornell, spheres, terrain, soup) or a mesh "
                    "file (OBJ, PLY, STL) with primary bundles, Phong shading and soft "
                    "shadows, and print rays, bundles, spheres, plane tests, pairs against "
                    "brute force, hits, time per stage and arithmetic events.")
    p.add_argument("--scene", default="cornell",
                   help="cornell | spheres | terrain | soup | path to .obj/.ply/.stl "
                        "(default cornell)")
    p.add_argument("--size", default="128x128", help="image size WxH (default 128x128)")
    p.add_argument("--backend", choices=("float64", "model", "rtl"), default="model",
                   help="intersection backend (default model)")
    p.add_argument("--sim", choices=("icarus", "verilator"), default="icarus",
                   help="simulator of the rtl backend (default icarus)")
    add_render_options(p)
    p.add_argument("--compare", action="store_true",
                   help="also render with float64 and report PSNR and differing pixels")
    p.add_argument("--diff", metavar="PNG",
                   help="write the difference image against float64 (implies --compare)")
    p.add_argument("--ids", metavar="NPZ",
                   help="write per-pixel nearest triangle IDs (and t, visibility) as .npz")
    p.add_argument("--json", metavar="FILE", help="write the summary as JSON")
    p.add_argument("-o", "--output", required=True, help="PNG to write")
    return p


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    if hasattr(x, "item"):
        return _jsonable(x.item())
    return x


def run(args) -> int:
    from ..host.backends import BackendUnavailable, make_backend
    from ..host.render import compare, difference_image, format_summary, render, save_ids, save_png
    from ..host.scenes import get_scene
    from .verilog import format_from_args

    size = _size(args.size)
    settings = settings_from_args(args, size)
    fmt = format_from_args(args)
    scene = get_scene(args.scene, bound=settings.bound)
    try:
        backend = make_backend(args.backend, fmt, mode=args.mode, sim=args.sim)
    except BackendUnavailable as exc:
        print(f"raplas-hdl render: the {args.backend} backend is not available: {exc}",
              file=sys.stderr)
        return 3
    result = render(scene, backend, settings)
    save_png(result.image, args.output)
    cmp = None
    if (args.compare or args.diff) and args.backend != "float64":
        ref = render(scene, make_backend("float64"), settings)
        cmp = compare(result, ref)
        if args.diff:
            save_png(difference_image(result, ref), args.diff, linear=False)
    print(format_summary(result, cmp))
    print(f"wrote {args.output}" + (f", {args.diff}" if args.diff else ""))
    if args.ids:
        save_ids(result, args.ids)
        print(f"wrote {args.ids}")
    if args.json:
        out = {"stats": result.stats, "timings": result.timings, "comparison": cmp}
        Path(args.json).write_text(json.dumps(_jsonable(out), indent=2))
        print(f"wrote {args.json}")
    return 0
