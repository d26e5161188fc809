"""Numerical stress suite of the ray-triangle unit: seeded hard-case families, judged by R.

:func:`raplas_hdl.model.stress_cases.generate` makes (ray, triangle) pairs in float64 scene
coordinates, family by family; :func:`evaluate` encodes them for a format (the ray with the
format's rounding, the triangle through :func:`raplas_hdl.model.triangles.make_triangles`),
runs the golden model in a mode and compares with **R**
(:func:`raplas_hdl.host.exact.exact_intersect_bits`):

``false_hits``    the unit hits, R misses;
``false_misses``  R hits, the unit misses;
``leaks``         a ray aimed at the interior of an edge shared by two coplanar triangles
                  (or at a vertex shared by a fan) that R hits on at least one side and the
                  unit hits on none;
``t_rel_*``       relative error of ``t = t'/det`` (host division in float64) against R's
                  ``t`` over the pairs both hit (median, 99th percentile, max).
``uncertain``     certified mode: pairs whose outcome is *uncertain*; there ``false_hits``
                  and ``false_misses`` count the **mis-certified** pairs (a certified hit
                  that R misses, a certified miss that R hits: must be 0), and a leak is a
                  ray that R hits on some side and the unit certifies as a miss on every
                  side.

Only pairs inside the format's domain (:func:`raplas_hdl.model.conservative.domain`; for the
certified mode :func:`raplas_hdl.model.certified.certified_domain`) count; the others are
reported as ``unguaranteed`` (and triangles the record builder rejects as ``skipped``).
:func:`bisect_certified` is the negative control of the certified bounds: the largest
factor below 1 on every bound at which some pair is mis-certified.

The families (``FAMILIES``) and the bit-pattern vectors drawn from them are documented where
they are made, in :mod:`raplas_hdl.model.stress_cases`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..fp.format import FPFormat
from ..fp.model import decode, encode
from ..model.certified import MAX_EXP_BITS, certified_domain
from ..model.conservative import domain
from ..model.ray_triangle import intersect
from ..model.stress_cases import FAMILIES, StressCases
from ..model.triangles import make_triangles
from ..host.exact import exact_intersect_bits

__all__ = ["reference", "evaluate", "pooled", "bisect_scale", "bisect_certified"]


@dataclass
class Encoded:
    """The cases as one format sees them, and R's verdicts."""

    fmt: FPFormat
    o_bits: np.ndarray
    d_bits: np.ndarray
    v0_bits: np.ndarray
    e1_bits: np.ndarray
    e2_bits: np.ndarray
    n_bits: np.ndarray
    kept: np.ndarray          # pair indices with a valid triangle record
    in_domain: np.ndarray     # bool per pair (kept and inside the domain)
    r_hit: np.ndarray
    r_t: np.ndarray
    cert_in_domain: np.ndarray | None = None    # kept and inside the certified domain


def reference(cases: StressCases, fmt: FPFormat) -> Encoded:
    """Encode the cases for ``fmt`` and compute R (slow part; reuse it across modes)."""
    o_bits = encode(cases.o, fmt)
    d_bits = encode(cases.d, fmt)
    recs = make_triangles(np.stack([cases.v0, cases.v1, cases.v2], 1), fmt, on_bad="skip")
    kept = recs.ids
    dom = domain(fmt)
    od = decode(o_bits, fmt)
    dd = decode(d_bits, fmt)
    far = (np.abs(np.concatenate([od, cases.v0, cases.v1, cases.v2], 1)) > dom.max_coord).any(1)
    edges = np.stack([np.linalg.norm(a - b, axis=1) for a, b in
                      ((cases.v1, cases.v0), (cases.v2, cases.v0), (cases.v2, cases.v1))], 1)
    ok = ~far & (edges >= dom.min_edge).all(1) & (np.abs(dd) <= 1).all(1)
    in_domain = np.zeros(len(cases), bool)
    in_domain[kept] = ok[kept]
    r = exact_intersect_bits(o_bits[kept], d_bits[kept], cases.v0[kept], cases.v1[kept],
                             cases.v2[kept], fmt)
    r_hit = np.zeros(len(cases), bool)
    r_hit[kept] = r["hit"]
    r_t = np.full(len(cases), np.nan)
    r_t[kept] = r["t"]
    cert_ok = np.zeros(len(cases), bool)
    if fmt.exp_bits <= MAX_EXP_BITS:
        verts = np.concatenate([cases.v0, cases.v1, cases.v2], 1)
        cert_ok[kept] = ((np.abs(verts[kept]) <= certified_domain(fmt)).all(1)
                         & np.isfinite(np.concatenate([od, dd], 1)[kept]).all(1))
    return Encoded(fmt, o_bits, d_bits, recs.v0_bits, recs.e1_bits, recs.e2_bits, recs.n_bits,
                   kept, in_domain, r_hit, r_t, cert_ok)


def unit_hits(enc: Encoded, mode, margin_scale):
    """The unit's hit and ``t`` per pair (all pairs; not kept: no hit, NaN)."""
    hit, t, _ = unit_outcome(enc, mode, margin_scale)
    return hit, t


def unit_outcome(enc: Encoded, mode, margin_scale=1.0):
    """:func:`unit_hits` and the certified outcome per pair (uint8; 2 where not kept; None in
    the other modes)."""
    k = enc.kept
    res = intersect(enc.o_bits[k], enc.d_bits[k], enc.v0_bits, enc.e1_bits, enc.e2_bits,
                    enc.n_bits, enc.fmt, mode=mode, margin_scale=margin_scale)
    n = len(enc.in_domain)
    hit = np.zeros(n, bool)
    hit[k] = res["hit"]
    t = np.full(n, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        t[k] = decode(res["t"], enc.fmt) / decode(res["det"], enc.fmt)
    outcome = None
    if "outcome" in res:
        outcome = np.full(n, 2, np.uint8)
        outcome[k] = res["outcome"]
    return hit, t, outcome


def evaluate(cases: StressCases, enc: Encoded, mode: str = "paper",
             margin_scale: float = 1.0) -> dict:
    """Per-family counts of the unit (golden model) against R.

    Returns
    -------
    dict
        family name -> dict of ``pairs``, ``skipped``, ``unguaranteed``, ``r_hits``,
        ``unit_hits``, ``false_hits``, ``false_misses``, ``edge_rays``, ``leaks``,
        ``t_rel_median``, ``t_rel_p99``, ``t_rel_max`` (in-domain pairs only).
    """
    hit, t, outcome = unit_outcome(enc, mode, margin_scale)
    ok = enc.in_domain
    may_hit = hit                    # what a leak needs: no side that may be hit
    wrong_hit, wrong_miss = hit & ~enc.r_hit, ~hit & enc.r_hit
    if outcome is not None:
        ok = enc.cert_in_domain
        may_hit = outcome != 0
        wrong_miss = (outcome == 0) & enc.r_hit
    kept = np.zeros(len(ok), bool)
    kept[enc.kept] = True
    out = {}
    for fi, name in enumerate(FAMILIES):
        sel = cases.family == fi
        if not sel.any():
            continue
        s = sel & ok
        both = s & hit & enc.r_hit & np.isfinite(t) & np.isfinite(enc.r_t) & (enc.r_t != 0)
        rel = np.abs(t[both] - enc.r_t[both]) / np.abs(enc.r_t[both])
        row = {"pairs": int(sel.sum()), "skipped": int((sel & ~kept).sum()),
               "unguaranteed": int((sel & kept & ~ok).sum()),
               "r_hits": int((s & enc.r_hit).sum()), "unit_hits": int((s & hit).sum()),
               "false_hits": int((s & wrong_hit).sum()),
               "false_misses": int((s & wrong_miss).sum()),
               "uncertain": 0 if outcome is None else int((s & (outcome == 2)).sum()),
               "edge_rays": 0, "leaks": 0,
               "t_rel_median": float(np.median(rel)) if rel.size else 0.0,
               "t_rel_p99": float(np.quantile(rel, 0.99)) if rel.size else 0.0,
               "t_rel_max": float(rel.max()) if rel.size else 0.0}
        g = cases.group
        gs = sel & (g >= 0)
        if gs.any():
            ids = g[gs]
            n_g = ids.max() + 1
            all_ok = np.ones(n_g, bool)
            np.logical_and.at(all_ok, ids, ok[gs])
            r_any = np.zeros(n_g, bool)
            np.logical_or.at(r_any, ids, enc.r_hit[gs])
            u_any = np.zeros(n_g, bool)
            np.logical_or.at(u_any, ids, may_hit[gs])
            present = np.zeros(n_g, bool)
            present[ids] = True
            rays = present & all_ok & r_any
            row["edge_rays"] = int(rays.sum())
            row["leaks"] = int((rays & ~u_any).sum())
        out[name] = row
    return out


def pooled(table: dict) -> dict:
    """Sum of the count columns over the families (the t errors: max of the maxima)."""
    keys = ("pairs", "skipped", "unguaranteed", "r_hits", "unit_hits", "false_hits",
            "false_misses", "uncertain", "edge_rays", "leaks")
    out = {k: sum(row[k] for row in table.values()) for k in keys}
    out["t_rel_max"] = max((row["t_rel_max"] for row in table.values()), default=0.0)
    return out


def bisect_scale(cases: StressCases, enc: Encoded, lo: float = 2.0 ** -16, hi: float = 1.0,
                 steps: int = 14) -> dict:
    """Smallest margin scale ``s`` with zero pooled false misses (bisection in log2 s).

    Returns
    -------
    dict
        ``s_min`` (the smallest passing scale found), ``false_hits_min`` (pooled false hits
        at ``s_min``), ``false_hits_1`` (at ``s = 1``), ``ratio`` and ``lo_passes`` (True
        when even ``lo`` has no false miss: the bisection was bounded by ``lo``).
    """
    def misses(s):
        return pooled(evaluate(cases, enc, "conservative", s))

    at_hi = misses(hi)
    if at_hi["false_misses"]:
        raise ValueError(f"margin scale {hi} still gives {at_hi['false_misses']} false misses")
    at_lo = misses(lo)
    best = at_lo if at_lo["false_misses"] == 0 else at_hi
    s_best = lo if at_lo["false_misses"] == 0 else hi
    if at_lo["false_misses"]:
        a, b = np.log2(lo), np.log2(hi)
        for _ in range(steps):
            mid = 0.5 * (a + b)
            r = misses(2.0 ** mid)
            if r["false_misses"]:
                a = mid
            else:
                b, best, s_best = mid, r, 2.0 ** mid
    at_1 = misses(1.0)
    fh1, fhm = at_1["false_hits"], best["false_hits"]
    return {"s_min": float(s_best), "false_hits_min": int(fhm), "false_hits_1": int(fh1),
            "ratio": float(fh1 / fhm) if fhm else (float("inf") if fh1 else 1.0),
            "lo_passes": bool(at_lo["false_misses"] == 0)}


def bisect_certified(cases: StressCases, enc: Encoded, lo: float = 2.0 ** -12,
                     steps: int = 14) -> dict:
    """The negative control of the certified bounds: bisect (in log2) the factor ``s`` on
    every bound between ``lo`` and 1 for the largest ``s`` at which some in-domain pair is
    mis-certified (a certified hit that R misses or a certified miss that R hits).

    Returns
    -------
    dict
        ``s_fail`` (the largest failing factor found; None when even ``lo`` passes),
        ``s_pass`` (the smallest passing factor found), ``wrong_at_fail`` (mis-certified
        pairs at ``s_fail``), ``uncertain_at_1`` and ``uncertain_at_fail`` (pooled).

    Raises
    ------
    ValueError
        When the bounds as derived (``s = 1``) already mis-certify a pair.
    """
    def wrong(s):
        tot = pooled(evaluate(cases, enc, "certified", s))
        return tot["false_hits"] + tot["false_misses"], tot["uncertain"]

    w1, u1 = wrong(1.0)
    if w1:
        raise ValueError(f"the certified bounds mis-certify {w1} pairs at scale 1")
    w_lo, u_lo = wrong(lo)
    if not w_lo:
        return {"s_fail": None, "s_pass": lo, "wrong_at_fail": 0, "uncertain_at_1": u1,
                "uncertain_at_fail": None}
    a, b = math.log2(lo), 0.0
    best = (w_lo, u_lo)
    for _ in range(steps):
        mid = 0.5 * (a + b)
        w, u = wrong(2.0 ** mid)
        if w:
            a, best = mid, (w, u)
        else:
            b = mid
    return {"s_fail": float(2.0 ** a), "s_pass": float(2.0 ** b), "wrong_at_fail": int(best[0]),
            "uncertain_at_1": int(u1), "uncertain_at_fail": int(best[1])}
