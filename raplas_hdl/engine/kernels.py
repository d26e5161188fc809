"""Compiled pass kernels: the hierarchy cull and the unit's runs over a whole pass.

Two arithmetics run the same passes:

- the **model**: the bit-exact plane test and ray-triangle pair of the golden models
  (:func:`raplas_hdl.model.plane_sphere.plane_keep`; the pairs a block at a time through
  :func:`raplas_hdl.model.pair_kernels.vpair`, lanes that leave the common case through
  :func:`~raplas_hdl.model.ray_triangle.pair_fast` and
  :func:`~raplas_hdl.model.ray_triangle.pair_exact`), the format, the rounding and the mode
  as runtime arguments: compiled once for all of them and cached on disk by numba;
- **float64**: the reference, ``|n.C + p| <= r`` with a float64-rounding allowance and the
  division-free Moller-Trumbore decision on the original geometry
  (:func:`raplas_hdl.host.exact.float64_intersect`, operation for operation), compiled once.

Each kernel takes a half-open range ``lo, hi`` of its independent items (candidate
(bundle, node) pairs for the cull, runs for the unit) and releases the GIL, so
:func:`raplas_hdl.parallel.run_chunks` spreads a pass over the cores; every item
writes only its own outputs, so the results do not depend on the thread count.

Pass layout (``B`` bundles of ``rows`` x ``cols`` rays, ``P = rows + cols`` planes):

- planes ``pn (B*P, 3)``, ``pp (B*P,)``: bundle ``b``'s plane ``k`` is row ``b*P + k``
  (rows first, then columns);
- rays ``ro (B, 3)`` (one origin per bundle), ``rd (B*R, 3)``: ray ``r`` of bundle ``b``
  is row ``b*R + r``, ``R = rows*cols``; ``enable (B, R)``; ``keep_all (B,)``;
- runs: run ``u`` tests spheres ``run_sph[run_start[u]:run_start[u+1]]`` (in order)
  against bundle ``run_b[u]``; a pass names each bundle at most once;
- the unit's stream order inside a run is the RTL's: spheres in run order, rows
  ascending, columns ascending, triangles in list order. :func:`sphere_rays` is its one
  definition (a sphere's masks and the enable bits to the rays it reaches); the three trace
  kernels (:func:`trace_f64`, :func:`trace_model` and
  :func:`raplas_hdl.engine.certified.trace_certified`) differ only in the masks'
  arithmetic and in what they do with each pair.

The trace kernels reduce the stream as the renderer needs it: per ray the nearest hit
accepted by ``tmin <= t <= tmax[b, r]`` and ``tri != exclude[b]`` (ties to the lower
triangle ID), the same choice as :func:`raplas_hdl.host.shading.nearest_hits`; and the
unit's counters per run, in :data:`~raplas_hdl.model.config.COUNTER_NAMES` order.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..fp.kernels import decode_k, rmode_code
from ..fp.numba_cache import drop_stale_cache
from ..model.plane_sphere import plane_keep
from ..model.pair_kernels import BLOCK, gather, vpair
from ..model.ray_triangle import hit_common, pair_exact, pair_fast, pair_margins

drop_stale_cache(__file__)

__all__ = ["cull_model", "trace_model", "model_args", "cull_f64", "trace_f64", "F64_SLACK",
           "N_COUNTERS"]

#: Relative allowance of the float64 plane test for float64's own rounding.
F64_SLACK = 1e-9
#: Columns of the counters array (COUNTER_NAMES).
N_COUNTERS = 8


@njit(cache=True)
def _accept(t, tid, b, ray, tmin, tmax, excl, best_t, best_tri):
    """Fold one hit into the ray's nearest (ties to the lower triangle ID)."""
    if np.isfinite(t) and t >= tmin and t <= tmax[b, ray] and tid != excl[b]:
        bt = best_t[b, ray]
        if t < bt or (t == bt and tid < best_tri[b, ray]):
            best_t[b, ray] = t
            best_tri[b, ray] = tid


@njit(cache=True)
def sphere_rays(rm, cm, enable, b, cols, nt, rays):
    """The rays of bundle ``b`` a leaf sphere of ``nt`` triangles reaches under its row and
    column masks ``rm, cm``, in the unit's order (rows ascending, then columns ascending),
    into ``rays``; returns ``(n, skipped)``: the rays listed and the pairs of the rays whose
    enable bit is clear. The one definition of the unit's pair enumeration: each trace
    kernel gives each listed ray the sphere's triangles in list order."""
    n = 0
    skipped = 0
    for i in range(rm.size):
        if not rm[i]:
            continue
        for j in range(cols):
            if not cm[j]:
                continue
            ray = i * cols + j
            if enable[b, ray]:
                rays[n] = ray
                n += 1
            else:
                skipped += nt
    return n, skipped


# -- float64 ------------------------------------------------------------------------------
@njit(cache=True)
def _keep_f64(pn, pk, pp, c, s, r):
    a0 = c[s, 0] * pn[pk, 0]
    a1 = c[s, 1] * pn[pk, 1]
    a2 = c[s, 2] * pn[pk, 2]
    d = a0 + a1 + a2 + pp[pk]
    slack = F64_SLACK * (abs(a0) + abs(a1) + abs(a2) + abs(pp[pk]))
    return abs(d) <= r[s] + slack


@njit(nogil=True, cache=True)
def cull_f64(pn, pp, rows, n_planes, cand_b, cand_node, nc, nr, lo, hi, keep):
    """Hierarchy cull, float64: ``keep[q]`` when some row plane and some column plane of
    bundle ``cand_b[q]`` touch node ``cand_node[q]``."""
    for q in range(lo, hi):
        base = cand_b[q] * n_planes
        s = cand_node[q]
        row = False
        for i in range(rows):
            if _keep_f64(pn, base + i, pp, nc, s, nr):
                row = True
                break
        col = False
        if row:
            for j in range(rows, n_planes):
                if _keep_f64(pn, base + j, pp, nc, s, nr):
                    col = True
                    break
        keep[q] = row and col


@njit(cache=True)
def _pair_f64(o, oi, d, di, v0, e1, e2, nn, ti):
    """float64 Moller-Trumbore of :func:`raplas_hdl.host.exact.float64_intersect`:
    ``(hit, t)``."""
    tx = v0[ti, 0] - o[oi, 0]
    ty = v0[ti, 1] - o[oi, 1]
    tz = v0[ti, 2] - o[oi, 2]
    dx, dy, dz = d[di, 0], d[di, 1], d[di, 2]
    det = nn[ti, 0] * dx + nn[ti, 1] * dy + nn[ti, 2] * dz
    tp = nn[ti, 0] * tx + nn[ti, 1] * ty + nn[ti, 2] * tz
    qx = dy * tz - dz * ty
    qy = dz * tx - dx * tz
    qz = dx * ty - dy * tx
    up = -(qx * e2[ti, 0] + qy * e2[ti, 1] + qz * e2[ti, 2])
    vp = qx * e1[ti, 0] + qy * e1[ti, 1] + qz * e1[ti, 2]
    s = up + vp
    if det > 0:
        hit = up >= 0 and vp >= 0 and s <= det and tp >= 0
    elif det < 0:
        hit = up <= 0 and vp <= 0 and s >= det and tp <= 0
    else:
        hit = False
    return hit, tp / det if hit else np.nan


@njit(nogil=True, cache=True, error_model="numpy")
def trace_f64(pn, pp, ro, rd, enable, keep_all, rows, cols, run_b, run_start, run_sph, sc, sr,
              tcount, tlist, v0, e1, e2, nn, tmin, tmax, excl, lo, hi, best_t, best_tri,
              counters):
    """Runs ``lo .. hi-1`` of a pass, float64 (module docstring)."""
    n_planes = rows + cols
    n_rays = rows * cols
    rm = np.empty(rows, np.bool_)
    cm = np.empty(cols, np.bool_)
    rays = np.empty(n_rays, np.int64)
    for u in range(lo, hi):
        b = run_b[u]
        base = b * n_planes
        issued = 0
        skipped = 0
        hits = 0
        for q in range(run_start[u], run_start[u + 1]):
            s = run_sph[q]
            for i in range(rows):
                rm[i] = keep_all[b] or _keep_f64(pn, base + i, pp, sc, s, sr)
            for j in range(cols):
                cm[j] = keep_all[b] or _keep_f64(pn, base + rows + j, pp, sc, s, sr)
            nt = tcount[s]
            nr, sk = sphere_rays(rm, cm, enable, b, cols, nt, rays)
            skipped += sk
            issued += nr * nt
            for x in range(nr):
                ray = rays[x]
                for k in range(nt):
                    tid = tlist[s, k]
                    h, t = _pair_f64(ro, b, rd, b * n_rays + ray, v0, e1, e2, nn, tid)
                    if h:
                        hits += 1
                        _accept(t, tid, b, ray, tmin, tmax, excl, best_t, best_tri)
        n_sph = run_start[u + 1] - run_start[u]
        counters[u, 0], counters[u, 1] = n_sph, n_sph * n_planes
        counters[u, 2], counters[u, 3] = issued, skipped
        counters[u, 4] = hits
        counters[u, 5] = 0
        counters[u, 6] = 0
        counters[u, 7] = 0


@njit(nogil=True, cache=True, error_model="numpy")
def _flush(g, w, lane_b, lane_ray, lane_di, lane_tid, lane_u, n, ro, rd, v0, e1, e2, nn, mc,
           tmin, tmax, excl, best_t, best_tri, counters, e, m, r, cons):
    """The block's pairs: operations, recomputed lanes, decisions, nearest hits."""
    vpair(g, w, n, cons, e, m, r)
    sb = np.int64(1) << (e + m)
    zero = np.uint32(0)
    for k in range(n):
        b = lane_b[k]
        di = lane_di[k]
        tid = lane_tid[k]
        if w[11, k] >= 0:
            margins = (zero, zero, zero, zero, zero)
            if cons:
                margins = pair_margins(ro, b, rd, di, v0, e1, e2, nn, tid, e, m, mc)
            h = hit_common(w[3, k], w[0, k], w[1, k], w[2, k], w[4, k], w[5, k], cons,
                            margins, sb)
            tp = np.uint32(w[0, k])
            det = np.uint32(w[3, k])
        else:
            ok, h, tp, _, _, det = pair_fast(ro, b, rd, di, v0, e1, e2, nn, tid, e, m, r,
                                             cons, mc)
            if not ok:
                h, tp, _, _, det, c = pair_exact(ro, b, rd, di, v0, e1, e2, nn, tid, e, m, r,
                                                 cons, mc)
                u = lane_u[k]
                counters[u, 5] += c & 0xFF
                counters[u, 6] += (c >> 8) & 0xFF
                counters[u, 7] += (c >> 16) & 0xFF
        if h:
            counters[lane_u[k], 4] += 1
            tf = np.int64(decode_k(tp, e, m)).view(np.float64)
            df = np.int64(decode_k(det, e, m)).view(np.float64)
            _accept(tf * (1.0 / df), tid, b, lane_ray[k], tmin, tmax, excl, best_t,
                    best_tri)


# -- the model ----------------------------------------------------------------------------
@njit(cache=True)
def plane_masks(pn, pp, base, rows, n_planes, keep_all, sc, sr, s, rm, cm, e, m, r):
    """The unit's row and column masks of leaf sphere ``s`` against the planes
    ``base .. base + n_planes - 1`` (rows first), into ``rm`` and ``cm``; all set for a
    keep-all bundle."""
    for k in range(n_planes):
        pk = base + k
        keep = keep_all or plane_keep(pn[pk, 0], pn[pk, 1], pn[pk, 2], pp[pk], sc[s, 0],
                                      sc[s, 1], sc[s, 2], sr[s], e, m, r)
        if k < rows:
            rm[k] = keep
        else:
            cm[k - rows] = keep


# The format, the rounding and the mode are runtime arguments: one compile serves them all
# (their values are loop invariants, so the vector loops of the block arithmetic still run
# at full speed); :func:`model_args` gives them for a format.
@njit(nogil=True, cache=True)
def cull_model(pn, pp, rows, n_planes, cand_b, cand_node, nc, nr, lo, hi, keep, e, m, r):
    """Hierarchy cull, the model: as :func:`cull_f64` with the plane-sphere tester's
    arithmetic (:func:`~raplas_hdl.model.plane_sphere.plane_keep`) in the format ``(e, m)``
    and rounding code ``r``."""
    for q in range(lo, hi):
        base = cand_b[q] * n_planes
        s = cand_node[q]
        row = False
        for i in range(rows):
            k = base + i
            if plane_keep(pn[k, 0], pn[k, 1], pn[k, 2], pp[k], nc[s, 0], nc[s, 1],
                          nc[s, 2], nr[s], e, m, r):
                row = True
                break
        col = False
        if row:
            for j in range(rows, n_planes):
                k = base + j
                if plane_keep(pn[k, 0], pn[k, 1], pn[k, 2], pp[k], nc[s, 0], nc[s, 1],
                              nc[s, 2], nr[s], e, m, r):
                    col = True
                    break
        keep[q] = row and col

@njit(nogil=True, cache=True, error_model="numpy")
def trace_model(pn, pp, ro, rd, enable, keep_all, rows, cols, run_b, run_start, run_sph, sc,
                sr, tcount, tlist, v0, e1, e2, nn, mc, tmin, tmax, excl, lo, hi, best_t,
                best_tri, counters, e, m, r, cons):
    """Runs ``lo .. hi-1`` of a pass, the model (module docstring): the unit's plane tests
    and pair order, the pairs a block at a time, in the format ``(e, m)``, rounding code
    ``r`` and mode ``cons`` (conservative), with the margin table ``mc``."""
    n_planes = rows + cols
    n_rays = rows * cols
    rm = np.empty(rows, np.bool_)
    cm = np.empty(cols, np.bool_)
    g = np.empty((18, BLOCK), np.int64)
    w = np.empty((13, BLOCK), np.int64)
    lane_b = np.empty(BLOCK, np.int64)
    lane_ray = np.empty(BLOCK, np.int64)
    lane_di = np.empty(BLOCK, np.int64)
    lane_tid = np.empty(BLOCK, np.int64)
    lane_u = np.empty(BLOCK, np.int64)
    rays = np.empty(n_rays, np.int64)
    n = np.int64(0)
    for u in range(lo, hi):
        b = run_b[u]
        base = b * n_planes
        issued = 0
        skipped = 0
        for c in range(4, 8):
            counters[u, c] = 0
        for q in range(run_start[u], run_start[u + 1]):
            s = run_sph[q]
            plane_masks(pn, pp, base, rows, n_planes, keep_all[b], sc, sr, s, rm, cm, e, m, r)
            nt = tcount[s]
            nr, sk = sphere_rays(rm, cm, enable, b, cols, nt, rays)
            skipped += sk
            issued += nr * nt
            for x in range(nr):
                ray = rays[x]
                di = b * n_rays + ray
                for k in range(nt):
                    tid = tlist[s, k]
                    gather(g, n, ro, b, rd, di, v0, e1, e2, nn, tid)
                    lane_b[n] = b
                    lane_ray[n] = ray
                    lane_di[n] = di
                    lane_tid[n] = tid
                    lane_u[n] = u
                    n += 1
                    if n == BLOCK:
                        _flush(g, w, lane_b, lane_ray, lane_di, lane_tid, lane_u, n, ro, rd,
                               v0, e1, e2, nn, mc, tmin, tmax, excl, best_t, best_tri,
                               counters, e, m, r, cons)
                        n = np.int64(0)
        n_sph = run_start[u + 1] - run_start[u]
        counters[u, 0], counters[u, 1] = n_sph, n_sph * n_planes
        counters[u, 2], counters[u, 3] = issued, skipped
    if n:
        _flush(g, w, lane_b, lane_ray, lane_di, lane_tid, lane_u, n, ro, rd, v0, e1, e2,
               nn, mc, tmin, tmax, excl, best_t, best_tri, counters, e, m, r, cons)



def model_args(fmt, mode: str) -> tuple:
    """The trailing arguments ``(e, m, r, cons)`` of :func:`trace_model` (the first three
    end :func:`cull_model`'s) for a format and a ray-triangle mode."""
    return (np.int64(fmt.exp_bits), np.int64(fmt.man_bits), np.int64(rmode_code(fmt)),
            np.bool_(mode == "conservative"))
