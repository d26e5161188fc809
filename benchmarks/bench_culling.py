"""Plane-culling figures (issue 3, point 6): bundles of 4x4, 16x16 and 64x64 over scenes
of spheres.

A 64 x 64 image seen from a pinhole camera is cut into square bundles of each size. Every
bundle is tested against every sphere of the scene:

- work: plane tests (``rows + cols`` per sphere) against the brute-force ray-sphere tests
  (``rows * cols`` per sphere);
- the fraction of (ray, sphere) pairs that survive culling (the sphere touches both of
  the ray's planes): the FP24 golden model with the inflated radius ``r'``, the FP24
  model without inflation (unsafe, for the cost of the inflation), the same plane test in
  float64 (``|n.C + p| <= r``), and the rays that really meet their sphere (float64 line
  test: the floor any plane culling could reach).

Usage: ``python benchmarks/bench_culling.py [--out docs/results/culling.json]``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from raplas_hdl.fp import FP24, parse_format
from raplas_hdl.host.culling import CullingBudget, encode_spheres
from raplas_hdl.model.bundles import RayBundle, encode_bundles
from raplas_hdl.model.plane_sphere import tester_flags

IMAGE = 64
SIZES = (4, 16, 64)


def scene(name, rng, n=2000):
    """Sphere sets in the unit cube: ``random`` (uniform centres, radii 0.003..0.1) and
    ``shell`` (small spheres on a sphere's surface, as the leaves of a meshed object)."""
    if name == "random":
        c = rng.uniform(-1, 1, (n, 3))
        r = 10 ** rng.uniform(-2.5, -1, n)
    elif name == "shell":
        v = rng.normal(size=(n, 3))
        c = 0.8 * v / np.linalg.norm(v, axis=1, keepdims=True)
        r = np.full(n, 0.04)
    else:
        raise ValueError(f"unknown scene {name!r}")
    return c, r


def camera_bundles(size, eye=(0.0, 0.0, -3.0), half=0.45):
    """``(IMAGE/size)^2`` bundles of ``size`` x ``size`` tiling a screen at distance 1."""
    eye = np.array(eye)
    tiles = IMAGE // size
    step = 2 * half / tiles
    bundles = []
    for ty in range(tiles):
        for tx in range(tiles):
            centre = eye + np.array([-half + (tx + 0.5) * step, -half + (ty + 0.5) * step, 1.0])
            bundles.append(RayBundle(eye, centre, [step / 2, 0, 0], [0, step / 2, 0],
                                     size, size))
    return bundles


def run(fmt, scene_name, size, seed=0):
    rng = np.random.default_rng(seed)
    c, r = scene(scene_name, rng)
    budget = CullingBudget(fmt, o_max=4.0)
    c_enc, r_enc, r_inf, ok = encode_spheres(c, r, budget)
    bundles = camera_bundles(size)
    enc = encode_bundles(bundles, fmt)
    t_model = 0.0
    tot = dict(plane_tests=0, ray_tests=0, survive_fp=0, survive_raw=0, survive_f64=0,
               hits=0, lost=0)
    for b, (n, p, _, _) in zip(bundles, enc):
        t0 = time.perf_counter()
        keep = tester_flags(n, p, c_enc, r_inf, fmt)
        t_model += time.perf_counter() - t0
        keep_raw = tester_flags(n, p, c_enc, r_enc, fmt)
        keep64 = np.abs(c @ b.plane_n.T + b.plane_p) <= r[:, None]
        row, col = b.ray_planes()
        w = c - b.origin                                             # (S, 3)
        along = w @ b.directions.T                                   # (S, rays)
        w2 = np.sum(w * w, axis=1)[:, None]
        r2 = (r * r)[:, None]
        hit = (w2 - along ** 2 <= r2) & ((along >= 0) | (w2 <= r2))   # the ray meets it
        surv = keep[:, row] & keep[:, col]
        tot["plane_tests"] += keep.size
        tot["ray_tests"] += hit.size
        tot["survive_fp"] += int(surv.sum())
        tot["survive_raw"] += int((keep_raw[:, row] & keep_raw[:, col]).sum())
        tot["survive_f64"] += int((keep64[:, row] & keep64[:, col]).sum())
        tot["hits"] += int(hit.sum())
        tot["lost"] += int((hit & ~surv).sum())
    pairs = tot["ray_tests"]
    return {
        "format": str(fmt), "scene": scene_name, "bundle": f"{size}x{size}",
        "bundles": len(bundles), "spheres": len(r),
        "plane_tests": tot["plane_tests"], "brute_force_ray_tests": pairs,
        "plane_tests_per_ray_test": tot["plane_tests"] / pairs,
        "surviving_fraction_fp_inflated": tot["survive_fp"] / pairs,
        "surviving_fraction_fp_raw": tot["survive_raw"] / pairs,
        "surviving_fraction_float64": tot["survive_f64"] / pairs,
        "ray_hit_fraction": tot["hits"] / pairs,
        "false_accept_cost": (tot["survive_fp"] - tot["survive_f64"]) / max(tot["survive_f64"], 1),
        "hits_lost_by_culling": tot["lost"],
        "model_plane_tests_per_s": tot["plane_tests"] / t_model,
        "inflation": repr(budget),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--format", default="FP24")
    ap.add_argument("--out", default="docs/results/culling.json")
    args = ap.parse_args(argv)
    fmt = parse_format(args.format) if args.format else FP24
    rows = []
    for size in (4, 64):                    # compile the serial and parallel kernels first
        run(fmt, "shell", size)
    for scene_name in ("random", "shell"):
        for size in SIZES:
            res = run(fmt, scene_name, size)
            rows.append(res)
            print(f"{res['scene']:7s} {res['bundle']:6s} plane/ray tests "
                  f"{res['plane_tests_per_ray_test']:.3f}  surviving: FP24 r' "
                  f"{res['surviving_fraction_fp_inflated']:.6f}  FP24 r "
                  f"{res['surviving_fraction_fp_raw']:.6f}  float64 "
                  f"{res['surviving_fraction_float64']:.6f}  ray hits "
                  f"{res['ray_hit_fraction']:.6f}  lost {res['hits_lost_by_culling']}  "
                  f"{res['model_plane_tests_per_s'] / 1e6:.1f} M tests/s")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"image": IMAGE, "results": rows}, indent=1) + "\n")
    print(f"saved {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
