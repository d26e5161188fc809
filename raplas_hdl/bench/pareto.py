"""Configurations aggregated over scenes, and their Pareto fronts (minimise error and cost).

A *configuration* is a format, rounding and mode at the main bundle size; its figures are
aggregated over the scenes of the ``main`` grid (every configuration has the same scenes):

``err_pixels``  mean over scenes of the fraction of pixels whose nearest triangle differs
                from float64's;
``err_t``       median over scenes of the median relative error of t (in-domain pairs);
``time_s``      sum over scenes of the render's wall time (model backend);
``hw_cost``     the device fraction of :mod:`.cost` (one ray-triangle unit on one XC4VSX35).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ERRORS", "COSTS", "aggregate", "pareto_front", "fronts"]

#: Error and cost axes of the fronts: key -> label.
ERRORS = {"err_pixels": "pixels whose nearest triangle differs (mean over scenes)",
          "err_t": "median relative error of t (median over scenes)"}
COSTS = {"time_s": "model render wall time (s, sum over scenes)",
         "hw_cost": "device fraction of one ray-triangle unit (XC4VSX35)"}


def aggregate(points: list[dict], grid: str = "main") -> list[dict]:
    """One row per configuration (format, rounding, mode, bundle) of ``grid``'s model points."""
    groups: dict = {}
    for p in points:
        if p.get("grid") != grid or p.get("backend") == "float64":
            continue
        key = (p["format"], p["rounding"], p["mode"], p["bundle"])
        groups.setdefault(key, []).append(p)
    out = []
    for (f, r, m, b), ps in groups.items():
        def col(k):
            return np.array([np.nan if p.get(k) is None else float(p[k]) for p in ps])

        t_med = col("t_rel_median")
        psnr = col("psnr")
        out.append({
            "format": f, "rounding": r, "mode": m, "bundle": b, "scenes": len(ps),
            "config": f"{f}/{r}/{m}",
            "err_pixels": float(np.mean(col("tri_differs"))),
            "err_pixels_in_domain": float(np.nanmean(col("tri_differs_in_domain")))
            if np.isfinite(col("tri_differs_in_domain")).any() else math.nan,
            "err_t": float(np.nanmedian(t_med)) if np.isfinite(t_med).any() else math.nan,
            "err_t_p99": float(np.nanmax(col("t_rel_p99")))
            if np.isfinite(col("t_rel_p99")).any() else math.nan,
            "psnr_min": float(np.min(psnr)),
            "time_s": float(np.sum(col("t_total"))),
            "pairs_per_s": float(np.sum(col("pairs_issued")) / max(1e-12, np.sum(
                col("t_primary_unit") + col("t_shadow_unit")))),
            "pairs_out_of_domain_frac": float(np.mean(col("pairs_out_of_domain_frac"))),
            "hw_cost": ps[0].get("hw_cost"), "hw_dsp48": ps[0].get("hw_dsp48"),
            "hw_slices": ps[0].get("hw_slices"), "hw_luts": ps[0].get("hw_luts"),
            "r_false_hits": ps[0].get("r_false_hits"),
            "r_false_misses": ps[0].get("r_false_misses"), "r_leaks": ps[0].get("r_leaks"),
        })
    return out


def pareto_front(rows: list[dict], error: str, cost: str) -> list[int]:
    """Indices of the rows no other row dominates (lower or equal in both, lower in one),
    sorted by cost. Rows with a missing value take no part."""
    ok = [i for i, r in enumerate(rows)
          if r.get(error) is not None and r.get(cost) is not None
          and math.isfinite(r[error]) and math.isfinite(r[cost])]
    order = sorted(ok, key=lambda i: (rows[i][cost], rows[i][error]))
    front, best = [], math.inf
    for i in order:
        if rows[i][error] < best:
            front.append(i)
            best = rows[i][error]
    return front


def fronts(rows: list[dict]) -> dict:
    """``(error, cost) -> front indices`` for every pair of :data:`ERRORS` x :data:`COSTS`."""
    return {(e, c): pareto_front(rows, e, c) for e in ERRORS for c in COSTS}
