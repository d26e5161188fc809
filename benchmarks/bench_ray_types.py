"""What culling saves per ray type, and the FP24 model's error per ray type.

Each scene is rendered through the FP24 golden model (paper mode) and the float64 reference
with every ray type the renderer has: primary tiles, soft-shadow bundles, the 1x1 bundles of
mirror reflection and refraction, glossy bundles around the mirror direction and
ambient-occlusion bundles. Per ray type (``result.stats["ray_types"]``): rays, bundles, rays
per bundle, pairs issued against brute force (every ray against every triangle), plane tests
per ray (host hierarchy and unit), pairs per ray, early-out savings and hits. Per render:
wall and CPU time (``time.process_time``: every thread of the process) and the load average.
The model against float64: PSNR of the whole image, the fraction of pixels whose primary
nearest triangle differs, and, per first-bounce layer (:func:`raplas_hdl.host.output.compare`),
the fraction of pixels (where either render has the ray) whose reflection / refraction
triangle differs and the mean absolute difference of the glossy hit fraction and of the
ambient-occlusion factor (where both have it).

``--picture WxH`` renders the showcase alone at that size with the scene's own render
settings (those of ``raplas-hdl render --scene showcase``: the command's defaults under the
scene's ``[render]`` table) and writes the README picture: ``showcase_model.png``,
``showcase_float64.png`` and ``showcase_diff.png`` (:func:`raplas_hdl.host.output.difference_image`, x4, magenta
where the nearest triangle differs) under ``--images`` and the figures as JSON.

Usage::

    python benchmarks/bench_ray_types.py [--size 128x128] [--scenes showcase,bunny-mirror,small]
        [--out docs/results/ray_types.json]
    python benchmarks/bench_ray_types.py --picture 512x512 [--images docs/images]
        [--out docs/results/showcase_picture.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from raplas_hdl.cli import grammar as g  # noqa: E402
from raplas_hdl.fp import FP24  # noqa: E402
from raplas_hdl.host import render as rr  # noqa: E402
from raplas_hdl.host.backends import make_backend  # noqa: E402
from raplas_hdl.host.scenes import get_scene  # noqa: E402

RAY_TYPES = ("primary", "shadow", "reflection", "refraction", "glossy", "ao")

#: The scenes and their render settings (besides the size). ``showcase`` is the shipped
#: Cornell box with a mirror sphere, a glass Suzanne and a glossy floor; ``bunny-mirror`` the
#: bunny on a mirror floor (``benchmarks/scenes/``); ``small`` the RTL test's scene.
SCENES = {
    "showcase": dict(rows=8, cols=8, shadow_rows=3, shadow_cols=3, depth=3, glossy_rows=3,
                     glossy_cols=3, ao_rows=3, ao_cols=3),
    "bunny-mirror": dict(rows=8, cols=8, shadow_rows=3, shadow_cols=3, depth=2, ao_rows=3,
                         ao_cols=3),
    "small": dict(rows=8, cols=8, shadow_rows=3, shadow_cols=3, depth=3, glossy_rows=3,
                  glossy_cols=3, ao_rows=3, ao_cols=3),
}
SCENE_FILES = {"bunny-mirror": ROOT / "benchmarks" / "scenes" / "bunny-mirror.toml"}
DEFAULT_OUT = ROOT / "build" / "ray-types" / "ray_types.json"


def timed_render(scene, backend_name, settings):
    """Render and return ``(result, figures)``: wall and CPU seconds, load average."""
    backend = make_backend(backend_name, FP24, mode="paper")
    load0 = os.getloadavg()
    t0, c0 = time.perf_counter(), time.process_time()
    result = rr.render(scene, backend, settings)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return result, {"wall_s": wall, "cpu_s": cpu,
                    "load_average": {"before": load0, "after": os.getloadavg()}}


def ray_type_table(result) -> dict:
    """Per ray type: the renderer's counters plus per-ray and per-bundle figures, and the
    wall seconds of its cull and unit stages (``stage_s``)."""
    out = {}
    for name, c in result.stats["ray_types"].items():
        rays, bundles = c["rays"], c["bundles"]
        row = dict(c)
        row["rays_per_bundle"] = rays / bundles if bundles else 0.0
        row["plane_tests_per_ray"] = c["plane_tests"] / rays if rays else 0.0
        row["pairs_per_ray"] = c["pairs_issued"] / rays if rays else 0.0
        row["brute_force_pairs_per_ray"] = c["brute_force_pairs"] / rays if rays else 0.0
        # work per ray in tests (plane tests + ray-triangle pairs) against brute force's
        # one ray-triangle test per triangle
        bf = c["brute_force_pairs"]
        row["work_fraction"] = (c["plane_tests"] + c["pairs_issued"]) / bf if bf else 0.0
        row["stage_s"] = sum(result.timings.get(f"{name} {k}", 0.0) for k in ("cull", "unit"))
        out[name] = row
    return out


def bench_scene(name, size, settings, images=None, prefix=None):
    scene = get_scene(str(SCENE_FILES.get(name, name)))
    st = rr.RenderSettings(*size, progress=False, **settings)
    model, fig_m = timed_render(scene, "model", st)
    ref, fig_f = timed_render(scene, "float64", st)
    entry = {
        "scene": name, "triangles": scene.n_triangles, "size": list(size),
        "settings": {k: getattr(st, k) for k in (
            "rows", "cols", "shadow_rows", "shadow_cols", "depth", "glossy_rows",
            "glossy_cols", "ao_rows", "ao_cols", "ao_angle", "ao_distance", "tris_per_sphere",
            "fanout", "batch_spheres", "early_out")},
        "model": {**fig_m, "ray_types": ray_type_table(model), "timings": model.timings,
                  "totals": {k: model.stats[k] for k in ("rays", "bundles", "pairs_issued",
                                                         "brute_force_pairs", "pair_fraction",
                                                         "plane_tests", "hits")}},
        "float64": {**fig_f, "ray_types": ray_type_table(ref), "timings": ref.timings,
                    "totals": {k: ref.stats[k] for k in ("rays", "bundles", "pairs_issued",
                                                         "brute_force_pairs", "pair_fraction",
                                                         "plane_tests", "hits")}},
        "model_vs_float64": rr.compare(model, ref),
    }
    if images is not None:
        images.mkdir(parents=True, exist_ok=True)
        stem = prefix or f"ray_types_{name}"
        rr.save_png(model.image, images / f"{stem}_model.png")
        rr.save_png(ref.image, images / f"{stem}_float64.png")
        rr.save_png(rr.difference_image(model, ref), images / f"{stem}_diff.png", linear=False)
    return entry


def _pct(x):
    return f"{100.0 * x:.3f} %"


def print_table(entry):
    m = entry["model"]
    print(f"\n{entry['scene']} ({entry['triangles']:,} triangles) {entry['size'][0]}x"
          f"{entry['size'][1]}: model {m['wall_s']:.1f} s wall / {m['cpu_s']:.1f} s CPU, "
          f"float64 {entry['float64']['wall_s']:.1f} s / {entry['float64']['cpu_s']:.1f} s")
    print(f"  {'type':10s} {'rays':>10s} {'bundles':>9s} {'rays/b':>6s} {'pairs':>12s} "
          f"{'of brute force':>14s} {'planes/ray':>10s} {'pairs/ray':>9s} {'early-out':>11s} "
          f"{'hits':>9s} {'work/bf':>7s} {'stage s':>7s}")
    for name in RAY_TYPES:
        r = m["ray_types"].get(name)
        if r is None:
            continue
        print(f"  {name:10s} {r['rays']:>10,} {r['bundles']:>9,} {r['rays_per_bundle']:>6.1f} "
              f"{r['pairs_issued']:>12,} {_pct(r['pair_fraction']):>14s} "
              f"{r['plane_tests_per_ray']:>10.1f} {r['pairs_per_ray']:>9.1f} "
              f"{r['early_out_pairs_skipped']:>11,} {r['hits']:>9,} {r['work_fraction']:>7.3f} "
              f"{r['stage_s']:>7.2f}")
    c = entry["model_vs_float64"]
    print(f"  vs float64: PSNR {c['psnr']:.2f} dB, primary nearest triangle differs on "
          f"{_pct(c['tri_differs'])} of pixels")
    for name, e in c["layers"].items():
        if not e["pixels"]:
            continue
        if "differs" in e:
            print(f"    {name}: differs on {_pct(e['differs'])} of {e['pixels']:,} pixels")
        else:
            print(f"    {name}: mean |diff| {e['mean_abs']:.6f} over {e['pixels']:,} pixels")


def picture_settings(scene) -> dict:
    """The settings of ``raplas-hdl render --scene showcase`` with no option: the render
    command's defaults (8x8 tiles, 3x3 shadows, 8 triangles per sphere, batches of 16
    spheres) under the scene's ``[render]`` table."""
    return dict(rows=8, cols=8, shadow_rows=3, shadow_cols=3, tris_per_sphere=8, fanout=8,
                batch_spheres=16, **scene.render_defaults)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=g.size_type(), default=(128, 128))
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--picture", type=g.size_type(), default=None, metavar="WxH",
                    help="render the README picture of the showcase at this size instead")
    ap.add_argument("--images", type=Path, default=None,
                    help="where the PNGs go (default: beside --out)")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = ap.parse_args(argv)
    unknown = [n for n in args.scenes.split(",") if n not in SCENES]
    if unknown:
        ap.error(f"unknown scene {unknown[0]!r}: use {', '.join(SCENES)}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    images = args.images or args.out.parent
    report = {"machine": platform.platform(), "cpus": os.cpu_count(), "format": str(FP24),
              "mode": "paper", "scenes": []}
    if args.picture:
        scene = get_scene("showcase")
        settings = picture_settings(scene)
        entry = bench_scene("showcase", args.picture, settings, images, prefix="showcase")
        report["scenes"].append(entry)
        print_table(entry)
    else:
        for name in args.scenes.split(","):
            entry = bench_scene(name, args.size, SCENES[name], images)
            report["scenes"].append(entry)
            args.out.write_text(json.dumps(g.jsonable(report), indent=1))
            print_table(entry)
    args.out.write_text(json.dumps(g.jsonable(report), indent=1))
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
