"""Certified mode: uncertain fraction of the bunny's primary pairs per bound variant and
format, and the model's pairs/s in certified mode against paper mode.

Pairs: the Stanford bunny scene (normalised to the renderer's bound 8) and its camera at
256x256, cut into the renderer's 8x8 tiles; ``--tiles`` tiles drawn at random (seed), each
tile's 64 unit rays against every triangle whose bounding sphere meets the tile's cone (a
per-triangle stand-in for the engine's leaf-sphere cull, which issues the same pairs and
more distant ones). Every pair is also judged by R, so the run checks that no hit or miss
is wrong. The conservative margins (``raplas_hdl.model.conservative``) used as the bounds
(scaled by 1, 0.05, 0.02) are measured on the same pairs as the baseline of the issue.

Writes ``docs/results/certified.json``. The machine is shared: CPU time is reported beside
wall time.

``--speed``: only the speed rows, printed: pairs per CPU-second of paper mode, of the
certified mode one pair at a time (``block=False``, the path before the block path) and a
block at a time, on the same pairs at FP24/rtz and FP16/rtz, each the best of three runs.

Usage: ``python benchmarks/bench_certified.py [--tiles 40] [--seed 13] [--out PATH] [--speed]``
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

import numpy as np

from raplas_hdl.fp.format import FPFormat
from raplas_hdl.fp.model import decode, encode
from raplas_hdl.host.exact import exact_intersect_bits
from raplas_hdl.host.scenes import get_scene
from raplas_hdl.model import certified
from raplas_hdl.model.conservative import margins
from raplas_hdl.model.ray_triangle import intersect
from raplas_hdl.model.triangles import make_triangles

FORMATS = ("FP24/rtz", "FP24/rne", "FP24/chop", "FP20/rtz", "FP16/rtz")
BASELINE_SCALES = (1.0, 0.05, 0.02)
SIZE, TILE = 256, 8


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def bunny_pairs(n_tiles: int, seed: int):
    """Rays (float64 origin, unit direction) and triangles (float64, (k, 3, 3)) of the
    bunny's primary pairs in ``n_tiles`` random tiles; returns ``(o, d, tri)`` pairwise."""
    scene = get_scene("stanford-bunny")
    tris = scene.triangles
    cam = scene.camera
    pos = np.asarray(cam.position, np.float64)
    pts = cam.pixel_points(SIZE, SIZE)
    rng = np.random.default_rng(seed)
    n_t = SIZE // TILE
    pick = rng.choice(n_t * n_t, n_tiles, replace=False)
    centre = tris.mean(axis=1)
    rad = np.linalg.norm(tris - centre[:, None, :], axis=2).max(axis=1)
    v = centre - pos
    dist = np.linalg.norm(v, axis=1)
    o_l, d_l, t_l = [], [], []
    for k in pick:
        y0, x0 = divmod(int(k), n_t)
        rel = pts[y0 * TILE:(y0 + 1) * TILE, x0 * TILE:(x0 + 1) * TILE].reshape(-1, 3) - pos
        dirs = rel / np.linalg.norm(rel, axis=1, keepdims=True)
        c = dirs.mean(axis=0)
        c /= np.linalg.norm(c)
        alpha = np.arccos(np.clip(dirs @ c, -1, 1)).max()
        theta = np.arccos(np.clip(v @ c / dist, -1, 1))
        near = dist <= rad
        reach = np.arcsin(np.clip(rad / np.maximum(dist, 1e-300), 0, 1))
        sel = np.flatnonzero(near | (theta - reach <= alpha * 1.05))
        o_l.append(np.broadcast_to(pos, (len(dirs) * len(sel), 3)))
        d_l.append(np.repeat(dirs, len(sel), axis=0))
        t_l.append(np.tile(tris[sel], (len(dirs), 1, 1)))
    return np.concatenate(o_l), np.concatenate(d_l), np.concatenate(t_l)


def _encoded(o, d, tri, fmt):
    recs = make_triangles(tri, fmt, on_bad="skip")
    k = recs.ids
    ob, db = encode(o[k], fmt), encode(d[k], fmt)
    r = exact_intersect_bits(ob, db, recs.v0, recs.v1, recs.v2, fmt)
    return (ob, db, recs.v0_bits, recs.e1_bits, recs.e2_bits, recs.n_bits), r["hit"]


def _baseline(arrs, r_hit, fmt, scale):
    """The conservative margins (times ``scale``) used as the certified bounds: certified
    hit / miss as in the certified mode, with w = det - s in float64 (a measurement of the
    baseline's uncertain fraction, not a guarantee)."""
    res = intersect(*arrs, fmt, mode="paper")
    mg = margins(*arrs, fmt, margin_scale=scale)
    val = {k: decode(res[k], fmt) for k in ("det", "t", "u", "v")}
    val["w"] = val["det"] - val["u"] - val["v"]
    g = {k: decode(mg[k], fmt) for k in ("det", "t", "u", "v", "w")}
    ge = {k: val[k] >= g[k] for k in val}
    gt = {k: val[k] > g[k] for k in val}
    le = {k: val[k] <= -g[k] for k in val}
    lt = {k: val[k] < -g[k] for k in val}
    q = ("u", "v", "w", "t")
    hit = ((gt["det"] & np.all([ge[k] for k in q], 0))
           | (lt["det"] & np.all([le[k] for k in q], 0)))
    miss = ((le["det"] | np.any([lt[k] for k in q], 0))
            & (ge["det"] | np.any([gt[k] for k in q], 0)))
    return float(np.mean(~hit & ~miss)), int((hit & ~r_hit).sum() + (miss & r_hit).sum())


def _timed(fn, repeat=3):
    best_w, best_c = np.inf, np.inf
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), _cpu()
        fn()
        best_w, best_c = min(best_w, time.perf_counter() - w0), min(best_c, _cpu() - c0)
    return best_w, best_c


def speed_row(name, o, d, tri):
    """Pairs per CPU-second (and wall second) of paper mode and of the certified mode one
    pair at a time and a block at a time, on ``(o, d, tri)`` in format ``name``."""
    from raplas_hdl.fp.format import parse_format
    from raplas_hdl.model.ray_triangle import operand_array

    fmt = parse_format(name)
    arrs, _ = _encoded(o, d, tri, fmt)
    vec = [operand_array(a, fmt, "x") for a in arrs]
    runs = {"paper": lambda: intersect(*arrs, fmt, mode="paper"),
            "certified_pairs": lambda: certified.intersect_certified(vec, fmt, block=False),
            "certified_block": lambda: certified.intersect_certified(vec, fmt, block=True)}
    row = {"format": name, "pairs": int(len(arrs[0]))}
    for key, fn in runs.items():
        fn()                                                                # compiled
        w, c = _timed(fn)
        row[f"{key}_pairs_per_cpu_s"] = len(arrs[0]) / c
        row[f"{key}_pairs_per_s_wall"] = len(arrs[0]) / w
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tiles", type=int, default=40)
    ap.add_argument("--seed", type=int, default=13)
    ap.add_argument("--out", default="docs/results/certified.json")
    ap.add_argument("--speed", action="store_true",
                    help="print only the speed rows (paper, certified per pair, per block)")
    args = ap.parse_args(argv)
    from raplas_hdl.fp.format import parse_format
    from numba import get_num_threads

    o, d, tri = bunny_pairs(args.tiles, args.seed)
    if args.speed:
        for name in ("FP24/rtz", "FP16/rtz"):
            print(json.dumps(speed_row(name, o, d, tri) | {"threads": get_num_threads()}),
                  flush=True)
        return
    rows = []
    for name in FORMATS:
        fmt = parse_format(name)
        arrs, r_hit = _encoded(o, d, tri, fmt)
        row = {"format": name, "pairs": int(len(r_hit)), "r_hits": int(r_hit.sum()),
               "variants": {}, "baseline": {}}
        for var in certified.VARIANTS:
            res = intersect(*arrs, fmt, mode="certified", bound_variant=var)
            oc = res["outcome"]
            wrong = int(((oc == 1) & ~r_hit).sum() + ((oc == 0) & r_hit).sum())
            row["variants"][var] = {"uncertain": float(np.mean(oc == 2)), "wrong": wrong}
        for s in BASELINE_SCALES:
            unc, wrong = _baseline(arrs, r_hit, fmt, s)
            row["baseline"][f"conservative x{s:g}"] = {"uncertain": unc, "wrong": wrong}
        if name == "FP24/rtz":
            for mode, var in (("paper", None), ("certified", None)):
                intersect(*arrs, fmt, mode=mode, bound_variant=var)          # compiled
                w, c = _timed(lambda: intersect(*arrs, fmt, mode=mode, bound_variant=var))
                row[f"{mode}_pairs_per_s_wall"] = len(r_hit) / w
                row[f"{mode}_pairs_per_cpu_s"] = len(r_hit) / c
        rows.append(row)
        print(json.dumps(row), flush=True)
    doc = {"command": "python benchmarks/bench_certified.py " + " ".join(argv or sys.argv[1:]),
           "tiles": args.tiles, "seed": args.seed, "image": f"{SIZE}x{SIZE}",
           "threads": get_num_threads(), "default_variant": certified.DEFAULT_VARIANT,
           "note": "machine shared by several agents: CPU time beside wall time",
           "rows": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
