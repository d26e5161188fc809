"""Numerical stress suite of the ray-triangle unit: seeded hard-case families, judged by R.

:func:`generate` makes (ray, triangle) pairs in float64 scene coordinates, family by
family; :func:`evaluate` encodes them for a format (the ray with the format's rounding, the
triangle through :func:`raplas_hdl.host.triangles.make_triangles`), runs the golden model
in a mode and compares with **R** (:func:`raplas_hdl.host.exact.exact_intersect_bits`):

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

Families (``FAMILIES``): ``random``; ``shared_edge`` (two triangles of a quad, ray aimed
at a point of the diagonal); ``shared_vertex`` (a fan of six triangles, ray aimed at the
centre); ``near_parallel`` (det near 0); ``grazing`` (target at a relative distance
``2**-k`` from an edge, either side); ``tiny`` (edges near the domain's minimum,
geometry at that scale);
``huge`` (edges near the domain's maximum); ``far`` (geometry near the domain's
bound, far from the origin); ``thin`` (aspect ratios ``2**6`` to ``2**16``, targets near
the long edges); ``on_start`` (ray origin on the triangle, or just behind or in front);
``flush`` (edges near ``2**(emin/2)``, so that N, det and t' are near the format's flush
level and some of their products flush to zero: the certified bounds' flush terms).
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
from ..host.exact import exact_intersect_bits
from ..host.triangles import make_triangles

__all__ = ["FAMILIES", "StressCases", "generate", "reference", "evaluate", "pooled",
           "bisect_scale", "bisect_certified", "vectors"]

FAMILIES = ("random", "shared_edge", "shared_vertex", "near_parallel", "grazing", "tiny",
            "huge", "far", "thin", "on_start", "flush")


@dataclass
class StressCases:
    """Pairs of one or more families (float64 scene coordinates).

    Attributes
    ----------
    family : ndarray of int
        Index into ``FAMILIES`` per pair.
    group : ndarray of int
        Ray group for the leak count (pairs of one ray against the triangles around a
        shared edge or vertex share a group), -1 elsewhere.
    o, d, v0, v1, v2 : ndarray of float64, shape (n, 3)
    seed : int
    """

    family: np.ndarray
    group: np.ndarray
    o: np.ndarray
    d: np.ndarray
    v0: np.ndarray
    v1: np.ndarray
    v2: np.ndarray
    seed: int

    def __len__(self):
        return len(self.family)


# -- geometry helpers ----------------------------------------------------------------------
def _rotations(rng, n):
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    return q * np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]


def _place(local, rot, scale, centre):
    """``centre + scale * rot @ local`` for (n, k, 3) local points."""
    return centre[:, None, :] + scale[:, None, None] * np.einsum("nij,nkj->nki", rot, local)


def _dirs(rng, n, rot, min_z=0.2):
    """Unit directions in world space with ``|local z| >= min_z`` and a random sign."""
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    z = np.abs(v[:, 2])
    v[:, 2] = np.where(z < min_z, min_z, z) * rng.choice([-1.0, 1.0], size=n)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return np.einsum("nij,nj->ni", rot, v)


def _tri_local(rng, n):
    a = rng.uniform(-0.5, 1.5, n)
    b = rng.uniform(0.2, 1.5, n)
    z = np.zeros(n)
    return np.stack([np.stack([z, z, z], 1), np.stack([z + 1, z, z], 1),
                     np.stack([a, b, z], 1)], axis=1)


def _bary_point(tri, beta, gamma):
    return tri[:, 0] + beta[:, None] * (tri[:, 1] - tri[:, 0]) \
        + gamma[:, None] * (tri[:, 2] - tri[:, 0])


def _cycle(rng, tri):
    """Random cyclic vertex order (which vertex is V0 changes E1, E2 and N)."""
    k = rng.integers(0, 3, len(tri))
    idx = (np.arange(3)[None, :] + k[:, None]) % 3
    return np.take_along_axis(tri, idx[:, :, None], axis=1)


def _single(rng, n, scale, centre, target_local, rot=None, dirs=None, dist=None):
    """One triangle per ray, both given in local coordinates then placed."""
    rot = _rotations(rng, n) if rot is None else rot
    tri_local = target_local[1]
    tri = _place(tri_local, rot, scale, centre)
    p = _place(target_local[0][:, None, :], rot, scale, centre)[:, 0]
    d = _dirs(rng, n, rot) if dirs is None else dirs
    dist = scale * 2.0 ** rng.uniform(0, 6, n) if dist is None else dist
    o = p - dist[:, None] * d
    return o, d, _cycle(rng, tri)


# -- families ------------------------------------------------------------------------------
def _fam_random(rng, n, fmt):
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.3, 1.3, n), rng.uniform(-0.3, 1.3, n))
    return _single(rng, n, 2.0 ** rng.uniform(-4, 4, n), rng.uniform(-8, 8, (n, 3)), (p, tri))


def _edge_target(rng, tri, rel):
    """A point on a random edge of each triangle, moved in-plane by ``rel`` (signed)."""
    n = len(tri)
    k = rng.integers(0, 3, n)
    a = tri[np.arange(n), k]
    b = tri[np.arange(n), (k + 1) % 3]
    lam = rng.uniform(0.05, 0.95, n)
    e = b - a
    perp = np.stack([-e[:, 1], e[:, 0], np.zeros(n)], 1)
    perp /= np.linalg.norm(perp, axis=1, keepdims=True)
    return a + lam[:, None] * e + rel[:, None] * perp


def _fam_grazing(rng, n, fmt):
    tri = _tri_local(rng, n)
    rel = rng.choice([-1.0, 1.0], n) * 2.0 ** -rng.uniform(4, fmt.man_bits + 8, n)
    p = _edge_target(rng, tri, rel)
    return _single(rng, n, 2.0 ** rng.uniform(-3, 3, n), rng.uniform(-4, 4, (n, 3)), (p, tri))


def _fam_near_parallel(rng, n, fmt):
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.2, 1.2, n), rng.uniform(-0.2, 1.2, n))
    rot = _rotations(rng, n)
    ang = rng.uniform(0, 2 * np.pi, n)
    dz = rng.choice([-1.0, 1.0], n) * 2.0 ** -rng.uniform(1, fmt.man_bits + 6, n)
    dl = np.stack([np.cos(ang), np.sin(ang), dz], 1)
    dl /= np.linalg.norm(dl, axis=1, keepdims=True)
    d = np.einsum("nij,nj->ni", rot, dl)
    scale = 2.0 ** rng.uniform(-3, 3, n)
    return _single(rng, n, scale, rng.uniform(-4, 4, (n, 3)), (p, tri), rot=rot, dirs=d,
                   dist=scale * 2.0 ** rng.uniform(0, 3, n))


def _fam_tiny(rng, n, fmt):
    dom = domain(fmt)
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.2, 1.2, n), rng.uniform(-0.2, 1.2, n))
    scale = 2.0 ** -(dom.min_edge_exp - rng.uniform(0, 6, n))
    centre = rng.uniform(-1, 1, (n, 3)) * (scale * 2.0 ** rng.uniform(0, 10, n))[:, None]
    return _single(rng, n, scale, centre, (p, tri),
                   dist=scale * 2.0 ** rng.uniform(0, 8, n))


def _fam_huge(rng, n, fmt):
    dom = domain(fmt)
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.2, 1.2, n), rng.uniform(-0.2, 1.2, n))
    scale = 2.0 ** (dom.pos_exp - 2 - rng.uniform(0, 3, n))
    centre = rng.uniform(-1, 1, (n, 3)) * 2.0 ** (dom.pos_exp - 3)
    return _single(rng, n, scale, centre, (p, tri), dist=scale * rng.uniform(0.1, 0.5, n))


def _fam_far(rng, n, fmt):
    dom = domain(fmt)
    tri = _tri_local(rng, n)
    rel = rng.choice([-1.0, 1.0], n) * 2.0 ** -rng.uniform(2, fmt.man_bits + 4, n)
    p = _edge_target(rng, tri, rel)
    centre = (rng.choice([-1.0, 1.0], (n, 3)) * rng.uniform(0.5, 0.9, (n, 3))
              * 2.0 ** dom.pos_exp)
    scale = 2.0 ** rng.uniform(-2, 4, n)
    return _single(rng, n, scale, centre, (p, tri), dist=scale * 2.0 ** rng.uniform(0, 4, n))


def _fam_thin(rng, n, fmt):
    h = 2.0 ** -rng.uniform(6, 16, n)
    a = rng.uniform(0, 1, n)
    z = np.zeros(n)
    tri = np.stack([np.stack([z, z, z], 1), np.stack([z + 1, z, z], 1),
                    np.stack([a, h, z], 1)], axis=1)
    rel = rng.choice([-1.0, 1.0], n) * h * 2.0 ** -rng.uniform(0, fmt.man_bits, n)
    lam = rng.uniform(0.05, 0.95, n)
    p = np.stack([lam, rel, z], 1)
    return _single(rng, n, 2.0 ** rng.uniform(-2, 4, n), rng.uniform(-4, 4, (n, 3)), (p, tri))


def _fam_on_start(rng, n, fmt):
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.1, 1.1, n), rng.uniform(-0.1, 1.1, n))
    scale = 2.0 ** rng.uniform(-3, 3, n)
    off = rng.choice([-1.0, 0.0, 1.0], n) * 2.0 ** -rng.uniform(2, fmt.man_bits + 6, n)
    return _single(rng, n, scale, rng.uniform(-4, 4, (n, 3)), (p, tri), dist=scale * off)


def _fam_flush(rng, n, fmt):
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.2, 1.2, n), rng.uniform(-0.2, 1.2, n))
    scale = 2.0 ** (fmt.emin / 2 + rng.uniform(-1, 4, n))
    centre = rng.uniform(-1, 1, (n, 3)) * (scale * 2.0 ** rng.uniform(0, 6, n))[:, None]
    return _single(rng, n, scale, centre, (p, tri), dist=scale * 2.0 ** rng.uniform(0, 6, n))


def _fam_shared_edge(rng, n, fmt):
    """Quads split along a diagonal: rays aimed at the diagonal hit (in R) one or both."""
    z = np.zeros(n)
    v1 = np.stack([z, z, z], 1)
    v2 = np.stack([z + 1, z, z], 1)
    va = np.stack([rng.uniform(-0.5, 1.5, n), rng.uniform(0.2, 1.5, n), z], 1)
    vb = np.stack([rng.uniform(-0.5, 1.5, n), -rng.uniform(0.2, 1.5, n), z], 1)
    rot = _rotations(rng, n)
    scale = 2.0 ** rng.uniform(-3, 3, n)
    centre = rng.uniform(-4, 4, (n, 3))
    pts = _place(np.stack([v1, v2, va, vb], 1), rot, scale, centre)
    lam = rng.uniform(0.02, 0.98, n)
    target = pts[:, 0] + lam[:, None] * (pts[:, 1] - pts[:, 0])
    d = _dirs(rng, n, rot)
    o = target - (scale * 2.0 ** rng.uniform(0, 6, n))[:, None] * d
    ta = _cycle(rng, np.stack([pts[:, 2], pts[:, 0], pts[:, 1]], 1))
    tb = _cycle(rng, np.stack([pts[:, 3], pts[:, 1], pts[:, 0]], 1))
    grp = np.arange(n)
    return (np.concatenate([o, o]), np.concatenate([d, d]), np.concatenate([ta, tb]),
            np.concatenate([grp, grp]))


def _fam_shared_vertex(rng, n, fmt, k=6):
    ang = 2 * np.pi * (np.arange(k)[None, :] + rng.uniform(-0.2, 0.2, (n, k))) / k
    rad = rng.uniform(0.7, 1.3, (n, k))
    ring = np.stack([rad * np.cos(ang), rad * np.sin(ang), np.zeros((n, k))], 2)
    rot = _rotations(rng, n)
    scale = 2.0 ** rng.uniform(-3, 3, n)
    centre = rng.uniform(-4, 4, (n, 3))
    pts = _place(np.concatenate([np.zeros((n, 1, 3)), ring], 1), rot, scale, centre)
    d = _dirs(rng, n, rot)
    o = pts[:, 0] - (scale * 2.0 ** rng.uniform(0, 6, n))[:, None] * d
    tris = [_cycle(rng, np.stack([pts[:, 0], pts[:, 1 + j], pts[:, 1 + (j + 1) % k]], 1))
            for j in range(k)]
    grp = np.arange(n)
    return (np.tile(o, (k, 1)), np.tile(d, (k, 1)), np.concatenate(tris), np.tile(grp, k))


_GEN = {"random": _fam_random, "grazing": _fam_grazing, "near_parallel": _fam_near_parallel,
        "tiny": _fam_tiny, "huge": _fam_huge, "far": _fam_far, "thin": _fam_thin,
        "on_start": _fam_on_start, "shared_edge": _fam_shared_edge, "flush": _fam_flush,
        "shared_vertex": _fam_shared_vertex}


def generate(fmt: FPFormat, per_family: int = 1000, seed: int = 0,
             families=FAMILIES) -> StressCases:
    """Generate ``per_family`` rays of each family (the edge and vertex families give 2 and
    6 pairs per ray). Same arguments, same cases.

    Raises
    ------
    ValueError
        For an unknown family or a non-positive count.
    """
    if per_family < 1:
        raise ValueError(f"per_family must be at least 1, not {per_family}")
    fam, grp, o, d, tri = [], [], [], [], []
    gbase = 0
    for name in families:
        if name not in _GEN:
            raise ValueError(f"unknown stress family {name!r}; known: {', '.join(FAMILIES)}")
        rng = np.random.default_rng([seed, FAMILIES.index(name)])
        out = _GEN[name](rng, per_family, fmt)
        if len(out) == 4:
            oo, dd, tt, gg = out
            gg = gg + gbase
            gbase = gg.max() + 1
        else:
            oo, dd, tt = out
            gg = np.full(len(oo), -1)
        fam.append(np.full(len(oo), FAMILIES.index(name)))
        grp.append(gg)
        o.append(oo)
        d.append(dd)
        tri.append(tt)
    tri = np.concatenate(tri)
    return StressCases(np.concatenate(fam), np.concatenate(grp), np.concatenate(o),
                       np.concatenate(d), tri[:, 0].copy(), tri[:, 1].copy(), tri[:, 2].copy(),
                       seed)


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


def vectors(fmt: FPFormat, count: int, seed: int = 0, special_rate: float = 0.02,
            random_rate: float = 0.1) -> dict:
    """Bit-pattern vectors for checking an implementation against the golden model.

    Pairs of all families (encoded as :func:`reference` does), where a fraction
    ``special_rate`` of the components is replaced by a special pattern (signed zeros,
    infinities, the canonical and other NaNs, denormal patterns, max finite, min normal)
    and a fraction ``random_rate`` of the pairs by uniformly random patterns.

    Returns
    -------
    dict
        ``o``, ``d``, ``v0``, ``e1``, ``e2``, ``n``: uint32 arrays of shape (count, 3).
    """
    per = max(1, -(-count // len(FAMILIES)))
    cases = generate(fmt, per, seed)
    recs = make_triangles(np.stack([cases.v0, cases.v1, cases.v2], 1), fmt, on_bad="skip")
    k = recs.ids
    rng = np.random.default_rng([seed, 99])
    pick = rng.permutation(len(k))[:count]
    if len(pick) < count:
        pick = rng.choice(len(k), count)
    out = {"o": encode(cases.o[k], fmt)[pick], "d": encode(cases.d[k], fmt)[pick],
           "v0": recs.v0_bits[pick], "e1": recs.e1_bits[pick], "e2": recs.e2_bits[pick],
           "n": recs.n_bits[pick]}
    m = fmt.man_bits
    specials = np.array([0, fmt.sign_bit, fmt.inf, fmt.inf | fmt.sign_bit, fmt.nan,
                         fmt.inf | 1, fmt.nan | fmt.sign_bit, 1, fmt.man_mask | fmt.sign_bit,
                         fmt.max_finite, fmt.max_finite | fmt.sign_bit, fmt.min_normal,
                         fmt.min_normal | fmt.sign_bit, fmt.one, fmt.one | fmt.sign_bit,
                         1 << m], dtype=np.uint32)
    rand_pair = rng.random(count) < random_rate
    for name in out:
        a = out[name].copy()
        a[rand_pair] = rng.integers(0, fmt.mask + 1, (int(rand_pair.sum()), 3), dtype=np.uint32)
        sp = rng.random(a.shape) < special_rate
        a[sp] = rng.choice(specials, int(sp.sum()))
        out[name] = a
    return out
