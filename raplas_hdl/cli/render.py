"""``raplas-hdl render``: render a scene through a backend and print the summary."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..model.modes import MODES
from . import grammar as g

__all__ = [
    "DEFAULT_MODE",
    "add_parser",
    "add_render_options",
    "add_secondary_options",
    "add_view_options",
    "check",
    "check_scene",
    "resolve_mode",
    "run",
    "scene_from_args",
    "settings_from_args",
]

#: The render mode without ``--mode``: the exact reference's nearest triangle and visibility
#: on every ray (docs/certified-render.md); ``--mode paper`` is the paper's own behaviour.
DEFAULT_MODE = "certified"
#: Limits of the render options (stated in --help, checked while parsing).
MAX_TRIS_PER_SPHERE = 4096
MAX_FANOUT = 64
MAX_BATCH = 4096


def _power_of_two(text):
    v = g.int_range(2, MAX_FANOUT)(text)
    if v & (v - 1):
        import argparse

        raise argparse.ArgumentTypeError(f"must be a power of two from 2 to {MAX_FANOUT}, "
                                         f"not {v}")
    return v


def _point(text):
    """``X,Y,Z``: three finite numbers (scene units)."""
    import argparse
    import math

    try:
        v = tuple(float(x) for x in str(text).split(","))
    except ValueError:
        v = ()
    if len(v) != 3 or not all(math.isfinite(c) for c in v):
        raise argparse.ArgumentTypeError(f"{text!r} is not a point X,Y,Z (three finite "
                                         "numbers, for example 0,1.5,4)")
    return v


def _axis(text):
    """``x``, ``y``, ``z``, ``-x``, ... or ``X,Y,Z``."""
    import argparse

    from ..host.scene_file import parse_axis

    try:
        return parse_axis(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_view_options(p):
    """``--camera``, ``--look-at``, ``--up``, ``--fov``, ``--light``: override a scene's
    view and light (in the scene's own units, before the load normalisation)."""
    v = p.add_argument_group(
        "view overrides", "In the scene's own units (a mesh file stands on the floor y = 0, "
        "centred on x = z = 0, its largest side 2). A value starting with '-' is written "
        "with '=': --up=-z. See docs/scenes.md.")
    v.add_argument("--camera", type=_point, default=None, metavar="X,Y,Z",
                   help="camera position")
    v.add_argument("--look-at", type=_point, default=None, metavar="X,Y,Z",
                   help="the point the camera looks at")
    v.add_argument("--up", type=_axis, default=None, metavar="x|y|z|X,Y,Z",
                   help="the up axis: for a mesh file, the mesh's axis that points up (the "
                        "mesh is turned to stand on the floor); otherwise the camera's up "
                        "vector (-x, -y, -z too)")
    v.add_argument("--fov", type=g.float_range(0.0, 180.0, lo_open=True, hi_open=True),
                   default=None, metavar="DEG", help="vertical field of view in degrees, "
                                                     "between 0 and 180")
    v.add_argument("--light", type=_point, default=None, metavar="X,Y,Z",
                   help="move the light's centre there (its size and orientation kept)")


def _overrides(args) -> dict:
    return {k: getattr(args, k, None) for k in ("camera", "look_at", "up", "fov", "light")}


def _render_mode(text: str) -> str:
    """A registered render mode's name (the registry loads with the host, which a render
    needs anyway: not at the CLI's start)."""
    from ..host.modes import mode_names

    if text not in mode_names():
        raise argparse.ArgumentTypeError(
            f"mode must be one of {', '.join(mode_names())}, not {text!r}")
    return text


def resolve_mode(args, backend: str = "model"):
    """Set ``args.mode`` (:data:`DEFAULT_MODE` when ``--mode`` is not given) and return the
    registered mode, after checking that a certified mode fits the format (a one-line
    ``UsageError`` naming the format and ``--mode paper`` otherwise)."""
    from ..host.modes import get_mode

    given = args.mode is not None
    args.mode = args.mode if given else DEFAULT_MODE
    mode = get_mode(args.mode)
    if mode.unit_mode == "certified" and backend != "float64":
        from ..model.certified import check_certified_format

        try:
            check_certified_format(args.fmt)
        except ValueError as exc:
            raise g.UsageError(f"--mode {args.mode}{'' if given else ' (the default)'}: "
                               f"{exc}; --mode paper renders any format") from None
    return mode


def add_render_options(p):
    """Options shared by ``render`` and ``demo``: the format and the render settings."""
    g.add_format_option(p, field_widths=True)
    r = p.add_argument_group("render settings")
    r.add_argument("--mode", type=_render_mode, default=None,
                   metavar="{" + ",".join(MODES) + "}",
                   help="render mode of the model and rtl backends, built in or registered "
                        "(raplas_hdl.host.modes.register_mode; default certified: the exact "
                        "reference's nearest triangle and visibility on every ray; paper: "
                        "the paper's inequalities on the unit's arithmetic alone)")
    r.add_argument("--tile", type=g.lattice_type("--tile", allow_zero=False), default=(8, 8),
                   metavar="RxC", help=f"primary bundle size, sides 1 to {g.MAX_LATTICE} "
                                       "(default 8x8)")
    r.add_argument("--shadow", type=g.lattice_type("--shadow"), default=(3, 3), metavar="RxC",
                   help=f"light lattice of a shadow bundle, sides 1 to {g.MAX_LATTICE}, or 0 "
                        "for no shadows (default 3x3)")
    r.add_argument("--tris-per-sphere", type=g.int_range(1, MAX_TRIS_PER_SPHERE), default=8,
                   metavar="N", help=f"triangles per bounding sphere, 1 to "
                                     f"{MAX_TRIS_PER_SPHERE} (default 8)")
    r.add_argument("--fanout", type=_power_of_two, default=8, metavar="N",
                   help=f"sphere hierarchy fan-out, a power of two from 2 to {MAX_FANOUT} "
                        "(default 8)")
    r.add_argument("--no-hierarchy", action="store_true",
                   help="send every leaf sphere to the unit (no host hierarchy cull)")
    r.add_argument("--no-early-out", action="store_true",
                   help="do not disable blocked shadow rays between sphere batches")
    r.add_argument("--batch", type=g.int_range(1, MAX_BATCH), default=16, metavar="N",
                   help=f"leaf spheres per shadow run (early-out granularity), 1 to "
                        f"{MAX_BATCH} (default 16)")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")


def add_secondary_options(p):
    """``--depth``, ``--glossy``, ``--ao``, ``--ao-angle``, ``--ao-distance``: secondary
    rays (default: the scene file's ``[render]`` table, else none)."""
    from ..host.scene_file import MAX_DEPTH, MAX_SECONDARY_LATTICE

    r = p.add_argument_group(
        "secondary rays", "Default: the scene file's [render] table (the shipped showcase "
        "has one), else none. See docs/secondary-rays.md.")
    r.add_argument("--depth", type=g.int_range(0, MAX_DEPTH), default=None, metavar="N",
                   help=f"generations of reflection and refraction rays, 0 to {MAX_DEPTH} "
                        "(default 0)")
    r.add_argument("--glossy", type=g.lattice_type("--glossy"), default=None, metavar="RxC",
                   help=f"glossy bundle per point of a material with gloss_angle > 0, sides 1 "
                        f"to {MAX_SECONDARY_LATTICE}, or 0 for the single mirror ray "
                        "(default 0)")
    r.add_argument("--ao", type=g.lattice_type("--ao"), default=None, metavar="RxC",
                   help=f"ambient-occlusion bundle per primary point, sides 1 to "
                        f"{MAX_SECONDARY_LATTICE}, or 0 for none (default 0)")
    r.add_argument("--ao-angle", type=g.float_range(0.0, 90.0, lo_open=True, hi_open=True),
                   default=None, metavar="DEG",
                   help="half-angle of the ambient-occlusion cone, between 0 and 90 degrees "
                        "(default 60)")
    r.add_argument("--ao-distance", type=g.float_range(0.0, 1.0, lo_open=True), default=None,
                   metavar="F", help="reach of an ambient-occlusion ray as a fraction of the "
                                     "scene's extent, above 0 and at most 1 (default 0.25)")


def _secondary(args) -> dict:
    """The secondary-ray options given on the command line, as settings."""
    out = {}
    if getattr(args, "depth", None) is not None:
        out["depth"] = args.depth
    for kind in ("glossy", "ao"):
        if getattr(args, kind, None) is not None:
            out[f"{kind}_rows"], out[f"{kind}_cols"] = getattr(args, kind)
    for key in ("ao_angle", "ao_distance"):
        if getattr(args, key, None) is not None:
            out[key] = getattr(args, key)
    return out


def settings_from_args(args, size, defaults: dict | None = None):
    """The render settings of the options; ``defaults`` (a scene's
    :attr:`~raplas_hdl.host.scene.Scene.render_defaults`) under the secondary-ray options."""
    from ..host.render import RenderSettings

    rows, cols = args.tile
    sr, sc = args.shadow
    return RenderSettings(width=size[0], height=size[1], rows=rows, cols=cols,
                          shadow_rows=sr, shadow_cols=sc,
                          tris_per_sphere=args.tris_per_sphere, fanout=args.fanout,
                          hierarchy=not args.no_hierarchy, early_out=not args.no_early_out,
                          batch_spheres=args.batch, progress=not args.no_progress,
                          **{**(defaults or {}), **_secondary(args)})


def check_scene(spec: str, overrides: dict | None = None) -> None:
    """A scene name, a mesh file that exists (its contents are read by the command) or a
    scene file (``.toml``, or a shipped one by name), checked whole with the view
    ``overrides`` (:func:`~raplas_hdl.host.scene_file.check_scene_file`)."""
    from ..host import meshes, scenes

    def scene_file(path):
        from ..host.scene_file import check_scene_file

        check_scene_file(path, **(overrides or {}))

    if spec in scenes.SCENES or spec in meshes.MESHES:
        return
    if spec in scenes.SCENE_FILES:
        return scene_file(scenes.SCENE_FILES[spec])
    suffixes = tuple(scenes.SCENE_SUFFIXES) + tuple(meshes.MESH_SUFFIXES)
    p = Path(spec)
    if p.suffix.lower() in suffixes or p.exists():
        if p.is_dir():
            raise ValueError(f"scene {spec!r} is a directory, not a mesh or scene file")
        if not p.exists():
            raise ValueError(f"scene file {spec!r} does not exist")
        if p.suffix.lower() not in suffixes:
            raise ValueError(f"scene file {spec!r}: unsupported type {p.suffix!r} (use "
                             f"{', '.join(suffixes)})")
        g.check_input_file(spec, "scene file")
        if p.suffix.lower() in scenes.SCENE_SUFFIXES:
            scene_file(spec)
        return
    raise ValueError(f"unknown scene {spec!r}: use one of "
                     f"{', '.join([*scenes.SCENES, *meshes.MESHES, *scenes.SCENE_FILES])} "
                     f"or a path to an {'/'.join(s[1:].upper() for s in suffixes)} file")


def scene_from_args(args):
    """The scene of ``--scene`` with the view overrides, in its own units.

    For a mesh file ``--up`` names the mesh's up axis; for a scene file the overrides are
    checked with the file (:func:`check_scene`); for every other scene they replace the
    camera's values and move the light (:func:`~raplas_hdl.host.scene_file.override_scene`).
    """
    from ..host import scenes
    from ..host.scene_file import override_scene

    spec, over = args.scene, _overrides(args)
    if spec in scenes.SCENE_FILES or Path(spec).suffix.lower() in scenes.SCENE_SUFFIXES:
        return scenes.get_scene(spec, bound=None, **over)
    if spec not in scenes.SCENES and over["up"] is not None:        # a mesh file
        scene = scenes.get_scene(spec, bound=None, up=over.pop("up"))
    else:
        scene = scenes.get_scene(spec, bound=None)
    return override_scene(scene, **over)


def add_parser(subparsers):
    p = subparsers.add_parser(
        "render", help="render a scene through the float64, model, rtl or board backend",
        description="Render a procedural scene (cornell, spheres, terrain, soup), a mesh "
                    "file (OBJ, PLY, STL, glTF) or a scene file (TOML: camera, light, "
                    "materials, meshes with transforms; docs/scenes.md) with primary "
                    "bundles, Phong shading, soft shadows and, when asked, reflection, "
                    "refraction, glossy and ambient-occlusion bundles "
                    "(docs/secondary-rays.md), and print rays, bundles, spheres, plane "
                    "tests, pairs against brute force (per ray type), hits, time per stage "
                    "and arithmetic events.")
    p.add_argument("--scene", default="cornell", metavar="NAME|FILE",
                   help="cornell | spheres | terrain | soup | a shipped mesh (stanford-bunny, "
                        "teapot, spot, suzanne, stanford-dragon-100k) | a shipped scene file "
                        "(showcase) | path to .obj/.ply/.stl/.gltf/.glb or .toml "
                        "(default cornell)")
    p.add_argument("--size", type=g.size_type("--size"), default=(128, 128), metavar="WxH",
                   help=f"image size, sides 1 to {g.MAX_IMAGE} (default 128x128)")
    p.add_argument("--backend", type=g.choice("float64", "model", "rtl", "board",
                                               what="backend"),
                   default="model", metavar="{float64,model,rtl,board}",
                   help="intersection backend (default model; board: the unit on a board, "
                        "or the simulated board of raplas-hdl board-sim, behind --port)")
    p.add_argument("--port", default=None, metavar="PORT",
                   help="the board's serial port, e.g. /dev/ttyUSB0 (--backend board only)")
    p.add_argument("--baud", type=g.int_range(1200, 100_000_000), default=None,
                   metavar="N", help="the serial line's baud rate (default 3000000; "
                                     "--backend board only)")
    p.add_argument("--sim", type=g.choice("icarus", "verilator", what="simulator"),
                   default=None, metavar="{icarus,verilator}",
                   help="simulator of the rtl backend (default icarus; --backend rtl only)")
    p.add_argument("--reduce", action="store_true",
                   help="through the unit built with the on-chip reduction: one answer per "
                        "ray leaves the unit, not one beat per pair (model and rtl; --mode "
                        "paper, or certified: the unit's uncertain pairs leave it too; "
                        "docs/intersection-unit.md)")
    add_render_options(p)
    add_secondary_options(p)
    add_view_options(p)
    o = p.add_argument_group("outputs")
    o.add_argument("-o", "--output", required=True, metavar="FILE.png", help="PNG to write")
    o.add_argument("--compare", action="store_true",
                   help="also render with float64 and report PSNR and differing pixels "
                        "(not with --backend float64)")
    o.add_argument("--diff", metavar="FILE.png",
                   help="write the difference image against float64 (implies --compare)")
    o.add_argument("--ids", metavar="FILE.npz",
                   help="write per-pixel nearest triangle IDs (and t, visibility, and the "
                        "secondary rays' layers) as .npz")
    o.add_argument("--json", metavar="FILE.json", help="write the summary as JSON")
    g.add_waves_option(p, "every simulation of the rtl backend")
    return p


def check(args) -> None:
    args.fmt = g.format_from_args(args)
    if args.backend == "float64":
        g.reject(args, ("compare", "diff"), "to --backend float64 (it is the reference)")
    if args.backend != "rtl":
        g.reject(args, ("sim",), f"to --backend {args.backend} (only to rtl)")
    if args.backend != "board":
        g.reject(args, ("port", "baud"), f"to --backend {args.backend} (only to board)")
    elif not args.port:
        raise g.UsageError("--backend board needs --port (the board's serial port, or the "
                           "name raplas-hdl board-sim prints)")
    if args.reduce and args.backend == "float64":
        raise g.UsageError("--reduce does not apply to --backend float64 (it has no unit; "
                           "use model or rtl)")
    from ..host.modes import get_mode, mode_names

    mode = resolve_mode(args, args.backend)
    if args.reduce and not mode.reducible:
        usable = " or ".join(n for n in mode_names() if get_mode(n).reducible)
        raise g.UsageError(f"--reduce has no {mode.name} mode (its hits must reach the host "
                           f"to be resolved): use --mode {usable}")
    if args.reduce:
        from ..model.reduction import check_reduce_format

        try:
            check_reduce_format(args.fmt)
        except ValueError as exc:
            raise g.UsageError(f"--reduce: {exc}") from None
    check_scene(args.scene, _overrides(args))
    g.check_output_file(args.output, (".png",), "-o")
    if args.diff:
        g.check_output_file(args.diff, (".png",), "--diff")
    if args.ids:
        g.check_output_file(args.ids, (".npz",), "--ids")
    if args.json:
        g.check_output_file(args.json, (".json",), "--json")
    g.check_distinct(**{"-o": args.output, "--diff": args.diff, "--ids": args.ids,
                        "--json": args.json})
    args.sim = args.sim or "icarus"
    g.check_waves(args, args.sim, applies=args.backend == "rtl",
                  why=f"to --backend {args.backend} (it simulates nothing; use --backend rtl)")
    if args.backend == "rtl":
        g.require_simulator(args.sim)


def run(args) -> int:
    scene = scene_from_args(args)    # a bad mesh or override fails here, before the rest

    from ..host.backends import make_backend
    from ..host.output import compare, difference_image, format_summary, save_ids, save_png
    from ..host.render import render

    size = args.size
    settings = settings_from_args(args, size, scene.render_defaults)
    fmt = args.fmt
    scene = scene.normalised(settings.bound)
    backend = make_backend(args.backend, fmt, mode=args.mode, sim=args.sim,
                           reduce=args.reduce, port=args.port, baudrate=args.baud)
    with g.waves(args):
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
        Path(args.json).write_text(json.dumps(g.jsonable(out), indent=2))
        print(f"wrote {args.json}")
    return 0

