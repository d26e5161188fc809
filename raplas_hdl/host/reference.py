"""The exact reference of a render: R's answer for every ray the render issued.

A certified render (``render --mode certified``) claims the per-pixel nearest triangle and
shadow visibility of the exact reference R (:mod:`raplas_hdl.host.exact`) over the
triangles the backend loaded, for the rays it issued (the encoded origin and direction,
the shadow origins from its own hit points, the same ``tmin``/``tmax`` and own-triangle
exclusion, ties to the lowest ID). :func:`exact_reference` recomputes that answer by
brute force, without culling and without the unit, from
:attr:`raplas_hdl.host.render.RenderResult.rays`:

- ``method="exact"``: every (ray, triangle) pair in exact integer arithmetic (about 100 k
  pairs a second: the test scenes);
- ``method="filtered"``: every pair through the float64 filter of R
  (:mod:`raplas_hdl.engine.exact_filter`) in compiled code, the pairs it cannot decide or
  order in exact arithmetic (:func:`raplas_hdl.host.resolve.resolve_pending`);
- ``method="tree"``: as ``filtered``, over the triangles of the leaf spheres of a sphere
  hierarchy that the ray's *line* passes within (float64 distance test, radii recomputed
  here to contain their triangles and children with a relative slack of ``1e-9``, far
  above float64's error on these few operations): meshes.

:func:`check_passes` checks every recorded pass of every ray type (secondary rays too) ray
by ray, with ``t`` as well.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
from numba import njit

from ..engine.exact_filter import HIT, MISS, filter_pair
from ..parallel import run_chunks
from .exact import exact_t
from .resolve import resolve_pending
from .spheres import build_sphere_tree

__all__ = ["exact_reference", "compare_reference", "check_passes"]


@njit(nogil=True, cache=True)
def _brute(o, d, tri, ids, start, per_ray, tmin, tmax, excl, any_hit, lo, hi, best_lo,
           best_hi, best_tri, pend):
    """Rays ``lo .. hi-1`` (bundle ``b``, one ray each) against the triangles ``ids`` (every
    ray all of them; ``per_ray``: ray ``b`` those of ``ids[start[b]:start[b+1]]``)."""
    n = 0
    for b in range(lo, hi):
        k0, k1 = (start[b], start[b + 1]) if per_ray else (0, ids.size)
        for k in range(k0, k1):
            tid = ids[k]
            if tid == excl[b]:
                continue
            st, tl, th = filter_pair(o[b, 0], o[b, 1], o[b, 2], d[b, 0], d[b, 1], d[b, 2],
                                     tri[tid, 0, 0], tri[tid, 0, 1], tri[tid, 0, 2],
                                     tri[tid, 1, 0], tri[tid, 1, 1], tri[tid, 1, 2],
                                     tri[tid, 2, 0], tri[tid, 2, 1], tri[tid, 2, 2])
            if st == MISS or (st == HIT and (th < tmin or tl > tmax[b, 0])):
                continue
            if st != HIT or tl < tmin or th > tmax[b, 0] or (
                    best_tri[b, 0] >= 0 and tl <= best_hi[b, 0] and th >= best_lo[b, 0]):
                if n < pend.shape[0]:
                    pend[n, 0] = b
                    pend[n, 1] = 0
                    pend[n, 2] = tid
                n += 1
                continue
            if best_tri[b, 0] < 0 or th < best_lo[b, 0]:
                best_lo[b, 0] = tl
                best_hi[b, 0] = th
                best_tri[b, 0] = tid
                if any_hit:
                    break
    return n


@njit(cache=True)
def _near_line(c, r, o, d, dd):
    """The line ``o + t d`` passes within ``r`` (with slack) of ``c``."""
    px, py, pz = c[0] - o[0], c[1] - o[1], c[2] - o[2]
    qx = py * d[2] - pz * d[1]
    qy = pz * d[0] - px * d[2]
    qz = px * d[1] - py * d[0]
    rr = r * (1.0 + 1e-9) + 1e-9 * (abs(px) + abs(py) + abs(pz))
    return qx * qx + qy * qy + qz * qz <= rr * rr * dd


@njit(nogil=True, cache=True)
def _tree_candidates(o, d, centres, radii, child_start, child_index, node_leaf, leaf_tris,
                     lo, hi, count, out):
    """Per ray ``lo .. hi-1``: the triangles of the leaves its line passes near; ``count``
    (rays + 1 prefix, filled for the range) and ``out`` (None on a counting run)."""
    stack = np.empty(4096, np.int64)
    for i in range(lo, hi):
        dd = d[i, 0] * d[i, 0] + d[i, 1] * d[i, 1] + d[i, 2] * d[i, 2]
        n = 0
        top = 0
        stack[0] = 0
        top = 1
        while top:
            top -= 1
            k = stack[top]
            if not _near_line(centres[k], radii[k], o[i], d[i], dd):
                continue
            leaf = node_leaf[k]
            if leaf >= 0:
                for j in range(leaf_tris.shape[1]):
                    t = leaf_tris[leaf, j]
                    if t >= 0:
                        if out.shape[0]:
                            out[count[i] + n] = t
                        n += 1
                continue
            for c in range(child_start[k], child_start[k + 1]):
                stack[top] = child_index[c]
                top += 1
        if not out.shape[0]:
            count[i + 1] = n


def _safe_tree(tris, ids):
    """A sphere hierarchy over triangles ``ids`` whose radii contain their triangles and
    children in float64 with room (module docstring)."""
    tree = build_sphere_tree(tris[ids], 8, 8)
    c = tree.centres
    r = np.zeros(len(c))
    lt = tree.leaf_tris
    for leaf, node in enumerate(tree.leaf_node):
        v = tris[ids[lt[leaf][lt[leaf] >= 0]]].reshape(-1, 3)
        r[node] = np.sqrt(((v - c[node]) ** 2).sum(axis=1).max())
    for node in np.argsort(-tree.depth, kind="stable"):
        kids = tree.child_index[tree.child_start[node]:tree.child_start[node + 1]]
        if kids.size:
            r[node] = (np.sqrt(((c[kids] - c[node]) ** 2).sum(axis=1)) + r[kids]).max()
        r[node] = r[node] * (1.0 + 1e-9) + 1e-300
    leaf_tris = np.where(lt >= 0, ids[np.maximum(lt, 0)], -1)
    return tree, r, leaf_tris


def _filtered(o, d, tris, ids, tmin, tmax, excl, any_hit, tree=None):
    n = len(o)
    best_lo = np.full((n, 1), np.inf)
    best_hi = best_lo.copy()
    best_tri = np.full((n, 1), -1, np.int64)
    o = np.ascontiguousarray(o, np.float64)
    d = np.ascontiguousarray(d, np.float64)
    tmx = np.ascontiguousarray(np.asarray(tmax, np.float64).reshape(n, 1))

    if tree is not None:
        t, radii, leaf_tris = tree
        count = np.zeros(n + 1, np.int64)
        args = (o, d, t.centres, radii, t.child_start, t.child_index, t.node_leaf, leaf_tris)
        run_chunks(n, lambda lo, hi: _tree_candidates(*args, lo, hi, count,
                                                      np.zeros(0, np.int64)), min_chunk=256)
        np.cumsum(count, out=count)
        cand = np.empty(count[-1], np.int64)
        run_chunks(n, lambda lo, hi: _tree_candidates(*args, lo, hi, count, cand),
                   min_chunk=256)
    else:
        count = np.arange(n + 1, dtype=np.int64) * 0
        cand = ids

    def chunk(lo, hi):
        cap = 4096
        while True:
            pend = np.empty((cap, 3), np.int64)
            saved = best_lo[lo:hi].copy(), best_hi[lo:hi].copy(), best_tri[lo:hi].copy()
            k = _brute(o, d, tris, cand, count, tree is not None, float(tmin), tmx, excl,
                       any_hit, lo, hi, best_lo, best_hi, best_tri, pend)
            if k <= cap:
                return pend[:k]
            best_lo[lo:hi], best_hi[lo:hi], best_tri[lo:hi] = saved
            cap = k

    parts = run_chunks(n, chunk, min_chunk=64)
    pending = np.concatenate(parts) if parts else np.zeros((0, 3), np.int64)
    best_t = np.full((n, 1), np.inf)
    resolve_pending(pending, o, d[:, None, :], tris, best_lo, best_hi, best_tri, best_t, tmin,
                    tmx, excl, any_hit)
    return best_tri[:, 0]


def _exact(o, d, tris, ids, tmin, tmax, excl, any_hit):
    out = np.full(len(o), -1, np.int64)
    lo_q = Fraction(float(tmin))
    for i in range(len(o)):
        k = ids[ids != excl[i]]
        n = k.size
        hit, t = exact_t(np.broadcast_to(o[i], (n, 3)), np.broadcast_to(d[i], (n, 3)),
                         tris[k, 0], tris[k, 1], tris[k, 2])
        best = None
        hi = float(tmax[i])
        for j in np.flatnonzero(hit):       # ascending IDs: a strictly smaller t wins
            if t[j] < lo_q or (np.isfinite(hi) and t[j] > Fraction(hi)):
                continue
            if best is None or t[j] < best[0]:
                best = (t[j], int(k[j]))
                if any_hit:
                    break
        out[i] = -1 if best is None else best[1]
    return out


def exact_reference(result, tris, method: str = "exact") -> dict:
    """R's nearest triangle per pixel and visibility per shaded point for the rays of a
    render (module docstring).

    Parameters
    ----------
    result : RenderResult
        Rendered with ``RenderSettings(record_rays=True)``.
    tris : ndarray (F, 3, 3)
        The scene's triangles as the render loaded them (normalised scene coordinates).
    method : ``"exact"``, ``"filtered"`` or ``"tree"``

    Returns
    -------
    dict
        ``tri_id`` (H, W) int64 and ``visibility`` (H, W) float64 (NaN where no point).
    """
    rays, tris, ids, fn = _setup(result, tris, method)
    po, pd, yx = rays["primary_o"], rays["primary_d"], rays["primary_yx"]
    n = len(po)
    tri_id = np.full(result.tri_id.shape, -1, np.int64)
    tri_id[yx[:, 0], yx[:, 1]] = fn(po, pd, tris, ids, 0.0, np.full(n, np.inf),
                                    np.full(n, -1, np.int64), False)
    vis = np.full(result.tri_id.shape, np.nan)
    ys, xs = np.nonzero(result.tri_id >= 0)
    vis[ys, xs] = 1.0
    so = rays["shadow_o"]
    if len(so):
        sd, tmax = rays["shadow_d"], rays["shadow_tmax"]
        S, r = tmax.shape
        blocked = fn(np.repeat(so, r, axis=0), sd.reshape(-1, 3), tris, ids,
                     rays["shadow_tmin"], tmax.reshape(-1), np.repeat(rays["shadow_own"], r),
                     True) >= 0
        point = rays["shadow_point"]
        vis[ys[point], xs[point]] = 1.0 - blocked.reshape(S, r).mean(axis=1)
        # points without a shadow bundle (behind the light, facing away) stay as rendered
        rest = np.ones(len(ys), bool)
        rest[point] = False
        vis[ys[rest], xs[rest]] = result.visibility[ys[rest], xs[rest]]
    return {"tri_id": tri_id, "visibility": vis}


def _setup(result, tris, method):
    """The recorded rays, the triangles, the loaded IDs and R's answer function of
    ``method`` (``fn(o, d, tris, ids, tmin, tmax, exclude, any_hit)`` -> triangle IDs)."""
    if result.rays is None:
        raise ValueError("the render did not record its rays (RenderSettings(record_rays="
                         "True))")
    if method not in ("exact", "filtered", "tree"):
        raise ValueError(f"method must be 'exact', 'filtered' or 'tree', not {method!r}")
    rays = result.rays
    tris = np.ascontiguousarray(tris, np.float64)
    ids = np.asarray(rays["loaded"], np.int64)
    if method == "tree":
        tree = _safe_tree(tris, ids)

        def fn(*a):
            return _filtered(*a, tree=tree)
    else:
        fn = _exact if method == "exact" else _filtered
    return rays, tris, ids, fn


def check_passes(result, tris, method: str = "tree") -> dict:
    """Every recorded pass of a render against R, ray by ray: primary, shadow and every
    secondary ray type (``RenderResult.rays["passes"]``, recorded with
    ``RenderSettings(record_rays=True)``).

    For a nearest-hit pass, R's nearest triangle in the pass's window (ties to the lowest
    ID) and, where it hits, its exact ``t`` rounded to the nearest float64; for an any-hit
    pass, whether R has a hit in the window. Arguments as :func:`exact_reference`.

    Returns
    -------
    dict
        Per ray type: ``rays`` (traced), ``differ`` (rays whose triangle, or for any-hit
        passes whose blocked state, is not R's), ``t_differ`` (nearest hits whose ``t`` is
        not R's correctly rounded ``t``; 0 for any-hit passes).
    """
    rays, tris, ids, fn = _setup(result, tris, method)
    out: dict = {}
    for p in rays.get("passes") or ():
        en = p["enable"].reshape(-1)
        B, R = p["enable"].shape
        o = np.repeat(p["origin"], R, axis=0)[en]
        d = p["directions"].reshape(-1, 3)[en]
        tmax = p["tmax"].reshape(-1)[en]
        excl = np.repeat(p["exclude"], R)[en]
        ref = fn(o, d, tris, ids, p["tmin"], tmax, excl, p["any_hit"])
        got = p["answer"].reshape(-1)[en]
        row = out.setdefault(p["kind"], {"rays": 0, "differ": 0, "t_differ": 0})
        row["rays"] += int(en.sum())
        if p["any_hit"]:
            row["differ"] += int(np.count_nonzero((ref >= 0) != got))
            continue
        row["differ"] += int(np.count_nonzero(ref != got))
        hit = (got >= 0) & (ref == got)
        if hit.any():
            k = got[hit]
            r_hit, t = exact_t(o[hit], d[hit], tris[k, 0], tris[k, 1], tris[k, 2])
            want = np.array([float(x) if h else np.nan for x, h in zip(t, r_hit)])
            row["t_differ"] += int(np.count_nonzero(want != p["t"].reshape(-1)[en][hit]))
    return out


def compare_reference(result, reference: dict) -> dict:
    """Pixels whose nearest triangle or visibility differ from the reference."""
    tri_diff = int(np.count_nonzero(result.tri_id != reference["tri_id"]))
    a, b = result.visibility, reference["visibility"]
    vis_diff = int(np.count_nonzero(~((a == b) | (np.isnan(a) & np.isnan(b)))))
    return {"pixels": int(result.tri_id.size), "tri_id_differ": tri_diff,
            "visibility_differ": vis_diff}
