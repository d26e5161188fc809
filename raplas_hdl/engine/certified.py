"""The certified pass: the unit's three-valued outcome, a float64 filter, an exact list.

In ``certified`` mode the ray-triangle unit reports per pair *hit*, *miss* or *uncertain*
(:mod:`raplas_hdl.model.certified`): a hit is a hit of the exact reference R, a miss is a
miss of R. The pass turns that into R's answer per ray without exact arithmetic on the
common path:

1. the unit's misses are final;
2. every other pair (a certified hit, which still needs its ``t`` to be ordered, or an
   uncertain pair) goes through the float64 filter of R
   (:func:`raplas_hdl.engine.exact_filter.filter_pair`): a decided miss, a decided hit with
   an interval around ``t``, or undecided;
3. decided hits are folded per ray: *nearest* (primary rays: the hit whose interval lies
   wholly before the others'; ties to the lower triangle ID) or *any* (shadow rays: the
   ray is blocked as soon as one hit is certainly inside ``[tmin, tmax]``, later pairs are
   not even filtered);
4. what the filter cannot decide (an undecided pair, a hit whose interval straddles
   ``tmin`` or ``tmax``, two hits whose intervals overlap) goes to a *pending* list
   ``(bundle, ray, triangle)``, which the host resolves in exact arithmetic with the ray's
   folded hit (:func:`raplas_hdl.host.exact.exact_t`).

The kernel runs a range of runs like :func:`raplas_hdl.engine.kernels.trace_model`; each
bundle appears in one run of a pass, so each ray's state is written by one range only. The
unit's pairs go a block at a time, in three compiled steps per list of whole runs: the
kernel lists the runs' pairs in stream order, :func:`raplas_hdl.model.certified.block_pairs`
(the kernel ``intersect(mode="certified")`` runs: compiled once for both) gives each pair's
outcome and counts, and :func:`_tails` filters, folds and lists them pending in stream order.
``certified_pass(..., block=False)`` runs the unit one pair at a time instead
(:func:`raplas_hdl.model.certified.pairs_one`); the results (counters, pending list and its
order, folded hits) are the same.

The conservative mode's render uses the same pass (``certified_pass(..., unit=
conservative_pairs)``): its unit never misses a hit of R inside the domain but also
reports false hits in a band around each triangle (docs/conservative-mode.md), so its
misses are final and each of its hits is an *uncertain* pair for the filter and the exact
resolution, which gives R's answer per ray.
Counters per run: the unit's eight (``hits`` counts the unit's certified hits), then
``uncertain`` (the unit's uncertain pairs), ``filtered`` (pairs through the float64
filter) and ``pending``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..fp.numba_cache import drop_stale_cache
from ..parallel import run_chunks
from .exact_filter import HIT, MISS, filter_pair
from .kernels import N_COUNTERS, plane_masks, sphere_rays
from .passes import pass_arguments
from ..model.certified import block_pairs, pairs_one
from ..model.ray_triangle import pairs_loop

drop_stale_cache(__file__)

__all__ = ["certified_pass", "trace_certified", "conservative_pairs", "fold_outcomes",
           "N_CERT_COUNTERS", "CERT_COUNTERS"]

#: Extra counter columns after the unit's eight.
CERT_COUNTERS = ("uncertain", "filtered", "pending")
#: Pairs listed at a time by the block path (runs are listed whole, up to half of it).
LANES = 1 << 15
N_CERT_COUNTERS = N_COUNTERS + len(CERT_COUNTERS)


@njit(cache=True)
def _push(pend, npend, b, ray, tid):
    k = npend
    if k < pend.shape[0]:
        pend[k, 0] = b
        pend[k, 1] = ray
        pend[k, 2] = tid
    return npend + 1


@njit(cache=True, error_model="numpy")
def _tail(outcome, u, b, ray, di, tid, o64, d64, tri64, tmin, tmax, excl, any_hit,
          best_lo, best_hi, best_tri, counters, pend, npend):
    """One pair's outcome, a hit or uncertain, into run ``u``'s counters and ray ``(b,
    ray)``'s state: the filter, the fold and the pending list (module docstring); returns
    the new pending count."""
    if outcome == 1:
        counters[u, 4] += 1
    else:
        counters[u, N_COUNTERS] += 1
    if tid == excl[b] or (any_hit and best_tri[b, ray] >= 0):
        return npend
    counters[u, N_COUNTERS + 1] += 1
    st, tl, th = filter_pair(
        o64[b, 0], o64[b, 1], o64[b, 2], d64[di, 0], d64[di, 1], d64[di, 2],
        tri64[tid, 0, 0], tri64[tid, 0, 1], tri64[tid, 0, 2],
        tri64[tid, 1, 0], tri64[tid, 1, 1], tri64[tid, 1, 2],
        tri64[tid, 2, 0], tri64[tid, 2, 1], tri64[tid, 2, 2])
    tmx = tmax[b, ray]
    if st == MISS or (st == HIT and (th < tmin or tl > tmx)):
        return npend
    if st != HIT or tl < tmin or th > tmx:
        counters[u, N_COUNTERS + 2] += 1
        return _push(pend, npend, b, ray, tid)
    bt = best_tri[b, ray]
    if bt < 0 or th < best_lo[b, ray]:
        best_lo[b, ray] = tl
        best_hi[b, ray] = th
        best_tri[b, ray] = tid
        return npend
    if tl <= best_hi[b, ray]:
        counters[u, N_COUNTERS + 2] += 1
        return _push(pend, npend, b, ray, tid)
    return npend


@njit(nogil=True, cache=True, error_model="numpy")
def trace_certified(pn, pp, enable, keep_all, rows, cols, run_b, run_start, run_sph, sc, sr,
                    tcount, tlist, lo, hi, counters, lanes, e, m, r):
    """The pairs of runs ``lo ..`` of a pass in the unit's stream order (module
    docstring), into ``lanes (5, L)``: per column ``(bundle, ray, direction row, triangle,
    run)``. Runs are listed whole; the kernel stops after the run that reaches ``L // 2``
    pairs (or at ``hi``) and returns ``count * (hi + 1) + next run``, or -1 when ``L`` pairs
    do not hold a run. Sets the runs' counters 0-3 and zeroes the others."""
    n_planes = rows + cols
    n_rays = rows * cols
    rm = np.empty(rows, np.bool_)
    cm = np.empty(cols, np.bool_)
    rays = np.empty(n_rays, np.int64)
    cap = lanes.shape[1]
    n = 0
    for u in range(lo, hi):
        if 2 * n >= cap:
            return n * (hi + 1) + u
        b = run_b[u]
        base = b * n_planes
        skipped = 0
        n0 = n
        for c in range(4, N_COUNTERS + 3):
            counters[u, c] = 0
        for q in range(run_start[u], run_start[u + 1]):
            s = run_sph[q]
            plane_masks(pn, pp, base, rows, n_planes, keep_all[b], sc, sr, s, rm, cm, e, m, r)
            nt = tcount[s]
            nr, sk = sphere_rays(rm, cm, enable, b, cols, nt, rays)
            skipped += sk
            if n + nr * nt > cap:
                return -1
            for x in range(nr):
                ray = rays[x]
                for k in range(nt):
                    lanes[0, n], lanes[1, n], lanes[2, n] = b, ray, b * n_rays + ray
                    lanes[3, n], lanes[4, n] = tlist[s, k], u
                    n += 1
        n_sph = run_start[u + 1] - run_start[u]
        counters[u, 0], counters[u, 1] = n_sph, n_sph * n_planes
        counters[u, 2], counters[u, 3] = n - n0, skipped
    return n * (hi + 1) + hi


@njit(nogil=True, cache=True, error_model="numpy")
def _tails(lanes, n, outc, cnt, o64, d64, tri64, tmin, tmax, excl, any_hit, best_lo, best_hi,
           best_tri, counters, pend, npend):
    """The listed pairs' outcomes and event counts (``cnt``: overflow, underflow, invalid)
    into the counters and the rays' state, in stream order (:func:`_tail` for the pairs that
    are not misses: a miss is only counted, without a call); returns the pending count."""
    for q in range(n):
        u = lanes[4, q]
        counters[u, 5] += cnt[q, 0]
        counters[u, 6] += cnt[q, 1]
        counters[u, 7] += cnt[q, 2]
        if outc[q] != 0:
            npend = _tail(outc[q], u, lanes[0, q], lanes[1, q], lanes[2, q], lanes[3, q], o64,
                          d64, tri64, tmin, tmax, excl, any_hit, best_lo, best_hi, best_tri,
                          counters, pend, npend)
    return npend


def conservative_pairs(o, d, v0, e1, e2, nn, mc, lane_o, lane_d, lane_t, lo, hi, outc, t_o,
                       u_o, v_o, det_o, cnt_o, e, m, r):
    """:func:`~raplas_hdl.model.certified.block_pairs` for the conservative unit (margin
    table ``mc``): outcome 2 (uncertain) where it hits, 0 (a miss of R) elsewhere."""
    sel = slice(lo, hi)
    t = lane_t[sel]
    hit = np.empty(hi - lo, np.bool_)
    pairs_loop(o[lane_o[sel]], d[lane_d[sel]], v0[t], e1[t], e2[t], nn[t], mc, 0, hi - lo,
               hit, t_o[sel], u_o[sel], v_o[sel], det_o[sel], cnt_o[sel], e, m, r,
               np.bool_(True))
    outc[sel] = np.where(hit, 2, 0)


def fold_outcomes(lanes, outcome, batch, tri64, best_lo, best_hi, best_tri, tmin=0.0,
                  tmax=None, exclude=None, any_hit=False):
    """Step 2-4 of the pass (module docstring) for pairs whose outcomes are already known
    (the RTL's conservative stream: 2 where the unit hit): ``lanes (5, n)`` as
    :func:`trace_certified` lists them, in stream order; ``outcome (n,)``. Folds into
    ``best_lo, best_hi, best_tri`` as :func:`certified_pass` does and returns the pending
    list."""
    B, R = batch.n_bundles, batch.n_rays
    tmax = np.full((B, R), np.inf) if tmax is None else np.ascontiguousarray(tmax, np.float64)
    excl = (np.full(B, -1, np.int64) if exclude is None
            else np.ascontiguousarray(exclude, np.int64))
    n = lanes.shape[1]
    lanes = np.ascontiguousarray(lanes, np.int64).copy()
    lanes[4] = 0                                    # counters: one scratch row
    counters = np.zeros((1, N_CERT_COUNTERS), np.int64)
    o64 = np.ascontiguousarray(batch.origin, np.float64)
    d64 = np.ascontiguousarray(batch.directions, np.float64).reshape(-1, 3)
    tri64 = np.ascontiguousarray(tri64, np.float64)
    cap = 1024
    while True:
        pend = np.empty((cap, 3), np.int64)
        lo, hi, tri = best_lo.copy(), best_hi.copy(), best_tri.copy()
        npend = _tails(lanes, n, np.ascontiguousarray(outcome, np.uint8),
                       np.zeros((n, 3), np.uint8), o64, d64, tri64, float(tmin), tmax, excl,
                       bool(any_hit), lo, hi, tri, counters, pend, 0)
        if npend <= cap:
            best_lo[:], best_hi[:], best_tri[:] = lo, hi, tri
            return pend[:npend]
        cap = npend


def certified_pass(arith, scene, batch, run_b, run_start, run_sph, tri64, best_lo, best_hi,
                   best_tri, tmin=0.0, tmax=None, exclude=None, any_hit=False, block=True,
                   unit=None):
    """Runs of a pass in certified mode (module docstring).

    ``arith`` is the model's :class:`~raplas_hdl.engine.passes.Arithmetic` (its ``extra``
    holds the certified constants, its ``cull_tail`` the format and rounding); ``tri64``
    the original triangles (F, 3, 3); other arguments as
    :func:`~raplas_hdl.engine.passes.trace_pass`, with ``best_lo, best_hi`` the interval of
    each ray's folded ``t``; ``block`` False runs the unit's pairs one at a time (the
    reference of the block path: the same results); ``unit`` another pair kernel of
    :func:`~raplas_hdl.model.certified.block_pairs`' signature (:func:`conservative_pairs`,
    with the conservative margin table as ``arith.extra``).

    Returns
    -------
    counters : ndarray (U, N_CERT_COUNTERS) int64
    pending : ndarray (n, 3) int64
        ``(bundle, ray, triangle)`` for the host's exact resolution, in run order.
    """
    head, run_b, work, tail = pass_arguments(scene, batch, run_b, run_start, run_sph, tmin,
                                             tmax, exclude)
    counters = np.zeros((run_b.size, N_CERT_COUNTERS), np.int64)
    o64 = np.ascontiguousarray(batch.origin, np.float64)
    d64 = np.ascontiguousarray(batch.directions, np.float64).reshape(-1, 3)
    fold = (o64, d64, np.ascontiguousarray(tri64, np.float64), *tail, bool(any_hit))
    listing = (*head[:2], *head[4:8], run_b, *head[9:15])
    mem = [np.ascontiguousarray(x, np.uint32) for x in (*head[2:4], *head[15:19])]
    if unit is None:
        unit = block_pairs if block else pairs_one

    def units(lo, hi, pend):
        """Runs ``lo .. hi-1``: list, unit, fold; returns the pending count."""
        size = LANES
        npend = 0
        u = lo
        while u < hi:
            lanes = np.empty((5, size), np.int64)
            code = trace_certified(*listing, u, hi, counters, lanes, *arith.cull_tail)
            if code < 0:                                # one run holds more than size pairs
                size *= 4
                continue
            n, u = divmod(code, hi + 1)
            outc = np.empty(n, np.uint8)
            outs = [np.empty(n, np.uint32) for _ in range(4)]
            cnt = np.empty((n, 3), np.uint8)
            unit(*mem, *arith.extra, lanes[0], lanes[2], lanes[3], 0, n, outc, *outs, cnt,
                 *arith.cull_tail)
            npend = _tails(lanes, n, outc, cnt, *fold, best_lo, best_hi, best_tri, counters,
                           pend, npend)
        return npend

    def chunk(lo, hi):
        cap = 1024
        rows = run_b[lo:hi]
        saved = best_lo[rows], best_hi[rows], best_tri[rows]
        while True:
            pend = np.empty((cap, 3), np.int64)
            n = units(lo, hi, pend)
            if n <= cap:
                return pend[:n]
            # the buffer was too small: restore the range's rays and run it again
            best_lo[rows], best_hi[rows], best_tri[rows] = saved
            cap = n

    parts = run_chunks(run_b.size, chunk, min_chunk=16, weights=work)
    pending = np.concatenate(parts) if parts else np.zeros((0, 3), np.int64)
    return counters, pending
