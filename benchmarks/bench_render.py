"""Render benchmark: the Stanford bunny at 256x256 with soft shadows, per backend.

For each backend (float64 reference, FP24 golden model, optionally the RTL on a small
scene): wall time per stage, rays, bundles, plane tests, pairs issued against brute force
(every ray against every triangle), early-out skips, hits, arithmetic events, and the
model's image error against float64 (PSNR, fraction of pixels whose nearest triangle
differs). Results go to ``docs/results/render_bench.json`` (written after every backend,
so a long run leaves partial results), images beside it.

Usage::

    python benchmarks/bench_render.py [--mesh FILE] [--size 256x256] [--shadow 3x3]
        [--backends float64,model] [--format FP24] [--mode paper] [--rtl-sim icarus]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from raplas_hdl.cli.render import _jsonable, _lattice, _size
from raplas_hdl.fp import parse_format
from raplas_hdl.host.backends import BackendUnavailable, make_backend
from raplas_hdl.host.render import (
    RenderSettings,
    compare,
    difference_image,
    format_summary,
    render,
    save_png,
)
from raplas_hdl.host.scenes import get_scene

DEFAULT_MESH = Path("/work/shared/meshes/stanford-bunny.obj")


def _entry(result):
    st = result.stats
    return {"seconds": sum(result.timings.values()), "timings": result.timings,
            "rays": st["rays"], "bundles": st["bundles"], "spheres": st["spheres"],
            "plane_tests": st["plane_tests"], "pairs_issued": st["pairs_issued"],
            "brute_force_pairs": st["brute_force_pairs"],
            "pair_fraction": st["pair_fraction"],
            "early_out_pairs_skipped": st["early_out_pairs_skipped"], "hits": st["hits"],
            "events": st["events"], "hierarchy": st["hierarchy"], "stats": st}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--mesh", default=str(DEFAULT_MESH))
    p.add_argument("--size", default="256x256")
    p.add_argument("--tile", default="8x8")
    p.add_argument("--shadow", default="3x3")
    p.add_argument("--backends", default="float64,model")
    p.add_argument("--format", default="FP24")
    p.add_argument("--mode", default="paper", choices=("paper", "conservative"))
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--rtl-sim", default=None, choices=("icarus", "verilator"),
                   help="also time the rtl backend on a small scene (soup, 16x16)")
    p.add_argument("--out", default=str(ROOT / "docs" / "results" / "render_bench.json"))
    args = p.parse_args(argv)

    mesh = Path(args.mesh)
    if not mesh.exists():
        print(f"bench_render: {mesh} not found (the benchmark needs the shared meshes)",
              file=sys.stderr)
        return 2
    w, h = _size(args.size)
    rows, cols = _lattice(args.tile, "--tile")
    sr, sc = _lattice(args.shadow, "--shadow")
    fmt = parse_format(args.format)
    settings = RenderSettings(w, h, rows, cols, sr, sc, batch_spheres=args.batch)
    scene = get_scene(str(mesh))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    report = {"scene": scene.name, "triangles": scene.n_triangles, "size": f"{w}x{h}",
              "tile": f"{rows}x{cols}", "shadow": f"{sr}x{sc}", "format": str(fmt),
              "mode": args.mode, "machine": platform.platform(),
              "command": " ".join(["python", "benchmarks/bench_render.py"] + (argv or
                                                                              sys.argv[1:])),
              "backends": {}}
    results = {}
    for name in args.backends.split(","):
        backend = make_backend(name, fmt, mode=args.mode,
                               **({"sim": args.rtl_sim or "verilator"} if name == "rtl" else {}))
        t0 = time.perf_counter()
        res = render(scene, backend, settings)
        wall = time.perf_counter() - t0
        results[name] = res
        entry = _entry(res)
        entry["wall_seconds"] = wall
        if name != "float64" and "float64" in results:
            entry["vs_float64"] = compare(res, results["float64"])
            save_png(difference_image(res, results["float64"]),
                     out.parent / f"render_bench_{scene.name}_"
                     f"{'' if name == 'model' else name + '_'}diff.png", linear=False)
        if name == "rtl" and "model" in results:
            entry["equal_to_model"] = bool(
                (res.tri_id == results["model"].tri_id).all()
                and (res.image == results["model"].image).all()
                and (res.visibility == results["model"].visibility).all())
        report["backends"][backend.describe()] = entry
        save_png(res.image, out.parent / f"render_bench_{scene.name}_{name}.png")
        print(format_summary(res, entry.get("vs_float64")), flush=True)
        out.write_text(json.dumps(_jsonable(report), indent=2))
    if args.rtl_sim and "rtl" not in args.backends.split(","):
        small = get_scene("soup", n=24)
        st = RenderSettings(16, 16, 4, 4, 0, 0, progress=False)
        try:
            rtl = make_backend("rtl", fmt, mode=args.mode, sim=args.rtl_sim)
            t0 = time.perf_counter()
            r_rtl = render(small, rtl, st)
            t_rtl = time.perf_counter() - t0
            t0 = time.perf_counter()
            r_mod = render(small, make_backend("model", fmt, mode=args.mode), st)
            t_mod = time.perf_counter() - t0
            report["rtl_small"] = {"scene": "soup n=24, 16x16, no shadows",
                                   "simulator": args.rtl_sim, "rtl_seconds": t_rtl,
                                   "model_seconds": t_mod,
                                   "equal_to_model": bool((r_rtl.tri_id == r_mod.tri_id).all()
                                                          and (r_rtl.image == r_mod.image).all())}
        except BackendUnavailable as exc:
            report["rtl_small"] = {"unavailable": str(exc)}
        out.write_text(json.dumps(_jsonable(report), indent=2))
    bf = next(iter(report["backends"].values()))
    print(f"pairs issued / brute force: {bf['pair_fraction']:.5f}; wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
