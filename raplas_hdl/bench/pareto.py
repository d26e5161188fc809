"""Configurations aggregated over scenes, and their Pareto fronts (minimise error and cost).

A *configuration* is a format, rounding and mode at the main bundle size; its figures are
aggregated over the scenes of the ``main`` grid (every configuration has the same scenes):

``err_pixels``  mean over scenes of the fraction of pixels whose nearest triangle differs
                from float64's;
``err_t``       median over scenes of the median relative error of t (in-domain pairs);
``time_s``      sum over scenes of the render's wall time (model backend);
``hw_cost``     the device fraction of :mod:`.cost` (one ray-triangle unit on one XC4VSX35);
``device_s``    sum over scenes of the frame time on the device (:mod:`.cost`: the device
                unit's cycles for the frame over the units that fit on one XC4VSX35 and the
                board clock; ``inf`` when no unit fits).

A configuration with a *capped* point (not rendered to the end: its figures are estimates)
takes no part in the fronts; its errors are aggregated over its other points.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ERRORS", "COSTS", "aggregate", "pareto_front", "fronts"]

#: Error and cost axes of the fronts: key -> label.
ERRORS = {"err_pixels": "pixels whose nearest triangle differs (mean over scenes)",
          "err_t": "median relative error of t (median over scenes)"}
COSTS = {"time_s": "model render wall time (s, sum over scenes)",
         "hw_cost": "device fraction of one ray-triangle unit (XC4VSX35)",
         "device_s": "frame time on one XC4VSX35 (s, sum over scenes, 100 MHz)"}


def aggregate(points: list[dict], grid: str = "main") -> list[dict]:
    """One row per configuration (format, rounding, mode, bundle) of ``grid``'s model points."""
    groups: dict = {}
    for p in points:
        if p.get("grid") != grid or p.get("backend") == "float64":
            continue
        key = (p["format"], p["rounding"], p["mode"], p["bundle"])
        groups.setdefault(key, []).append(p)
    out = []
    for (f, r, m, b), all_ps in groups.items():
        capped = sum(1 for p in all_ps if p.get("capped"))
        ps = [p for p in all_ps if not p.get("capped")] or all_ps

        def col(k, pts=ps):
            return np.array([np.nan if p.get(k) is None else float(p[k]) for p in pts])

        def total(k):
            v = col(k, all_ps)
            return float(np.sum(v)) if v.size and not np.isnan(v).any() else math.nan

        t_med = col("t_rel_median")
        psnr = col("psnr")
        unit_t = np.sum(col("t_primary_unit") + col("t_shadow_unit"))
        dev_s = total("device_frame_s")
        out.append({
            "format": f, "rounding": r, "mode": m, "bundle": b, "scenes": len(all_ps),
            "config": f"{f}/{r}/{m}", "capped": capped,
            "err_pixels": _mean(col("tri_differs")),
            "err_pixels_in_domain": _nanmean(col("tri_differs_in_domain")),
            "err_t": float(np.nanmedian(t_med)) if np.isfinite(t_med).any() else math.nan,
            "err_t_p99": float(np.nanmax(col("t_rel_p99")))
            if np.isfinite(col("t_rel_p99")).any() else math.nan,
            "psnr_min": float(np.min(psnr)) if psnr.size else math.nan,
            "time_s": total("t_total"), "cpu_s": total("cpu_total"),
            "pairs_issued": total("pairs_issued"),
            "pairs_per_s": float(np.sum(col("pairs_issued")) / max(1e-12, unit_t))
            if np.isfinite(unit_t) else math.nan,
            "pairs_out_of_domain_frac": _mean(col("pairs_out_of_domain_frac")),
            "hw_cost": ps[0].get("hw_cost"), "hw_dsp48": ps[0].get("hw_dsp48"),
            "hw_slices": ps[0].get("hw_slices"), "hw_luts": ps[0].get("hw_luts"),
            "device_s": dev_s, "device_cycles": total("device_cycles"),
            "device_units": ps[0].get("device_units"),
            "link_bits": total("link_bits"),
            "link_bits_per_s": (total("link_bits") / dev_s
                                if dev_s and math.isfinite(dev_s) else math.nan),
            "r_false_hits": ps[0].get("r_false_hits"),
            "r_false_misses": ps[0].get("r_false_misses"), "r_leaks": ps[0].get("r_leaks"),
        })
    return out


def _mean(v) -> float:
    return float(np.mean(v)) if v.size else math.nan


def _nanmean(v) -> float:
    return float(np.nanmean(v)) if np.isfinite(v).any() else math.nan


def pareto_front(rows: list[dict], error: str, cost: str) -> list[int]:
    """Indices of the rows no other row dominates (lower or equal in both, lower in one),
    sorted by cost. Rows with a missing or infinite value, and rows with capped points, take
    no part."""
    ok = [i for i, r in enumerate(rows)
          if not r.get("capped") and r.get(error) is not None and r.get(cost) is not None
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
