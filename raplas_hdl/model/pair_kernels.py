"""The numba primitives of a (ray, triangle) pair's arithmetic, shared by the ray-triangle
model (:mod:`.ray_triangle`), its certified mode (:mod:`.certified`) and the renderer's
fused kernels (:mod:`raplas_hdl.engine.kernels`).

- :func:`add_op`, :func:`mul_op`, :func:`sub_op`: one reference operation, ``(pattern,
  flags)``, through the integer kernels of :mod:`raplas_hdl.fp.kernels` (one compiled
  signature for every caller); :func:`tally` packs an operation's flags into event counts.
- :func:`vpair`: the pair's 33 (34) operations over a block of :data:`BLOCK` pairs, in the
  branch-free common case of :mod:`raplas_hdl.fp.fast`.
- :func:`gather`: one pair's operands into a block; :func:`store`: one pair's outputs into
  the result arrays.

The bits are those of :class:`raplas_hdl.rtl.ray_triangle.RayTriangleUnit`; the order of
the operations is documented in :mod:`.ray_triangle`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..fp.fast import common_add, common_mul
from ..fp.format import FLAG_INVALID, FLAG_OVERFLOW, FLAG_UNDERFLOW
from ..fp.kernels import add_int_k, mul_int_k, neg_k
from ..fp.numba_cache import drop_stale_cache

__all__ = ["BLOCK", "add_op", "gather", "mul_op", "store", "sub_op", "tally", "vpair"]

drop_stale_cache(__file__)

# tally packs the flag bits by these values (the columns of the model's ``event_counts``)
assert (FLAG_OVERFLOW, FLAG_UNDERFLOW, FLAG_INVALID) == (1, 2, 4)


@njit(cache=True)
def tally(f):
    """An operation's event flags as packed counts: one byte per event (overflow in bits
    0-7, underflow 8-15, invalid 16-23), so that sums of up to 255 operations add lanewise."""
    f = np.int64(f)
    return (f & 1) | ((f & 2) << 7) | ((f & 4) << 14)


@njit(cache=True)
def add_op(a, b, e, m, r):
    """The reference ``a + b`` (the integer kernel: the same bits as ``add_k``, and one
    compiled signature for every caller)."""
    return add_int_k(np.int64(a), np.int64(b), e, m, r)


@njit(cache=True)
def mul_op(a, b, e, m, r):
    return mul_int_k(np.int64(a), np.int64(b), e, m, r)


@njit(cache=True)
def sub_op(a, b, e, m, r):
    return add_int_k(np.int64(a), np.int64(neg_k(np.int64(b), e, m)), e, m, r)


# -- pairs a block at a time ----------------------------------------------------------------
# Callers gather BLOCK pairs' operands structure-of-arrays and :func:`vpair` runs each of the
# 33 (34) operations over the block as one loop of the branch-free common case of
# :mod:`raplas_hdl.fp.fast` (LLVM vectorises these loops); ``acc`` collects the OR of every
# intermediate pattern, so a lane with any sentinel (a zero, infinite or NaN operand,
# overflow, underflow) is recomputed alone, by :func:`pair_fast` (zeros) or
# :func:`pair_exact` (everything, with the event flags); the other lanes decide with
# :func:`hit_common`.
BLOCK = 128


@njit(cache=True)
def _vsub(a, b, out, acc, n, E, M, R):
    sb = np.int64(1) << (E + M)
    for k in range(n):
        r = common_add(a[k], b[k] ^ sb, E, M, R)
        out[k] = r
        acc[k] |= r


@njit(cache=True)
def _vdot(a0, a1, a2, b0, b1, b2, out, acc, n, E, M, R):
    for k in range(n):
        p0 = common_mul(a0[k], b0[k], E, M, R)
        p1 = common_mul(a1[k], b1[k], E, M, R)
        p2 = common_mul(a2[k], b2[k], E, M, R)
        s = common_add(p0, p1, E, M, R)
        r = common_add(s, p2, E, M, R)
        out[k] = r
        acc[k] |= p0 | p1 | p2 | s | r


@njit(cache=True)
def _vcross(a, b, c, d, out, acc, n, E, M, R):
    """``a*b - c*d``."""
    sb = np.int64(1) << (E + M)
    for k in range(n):
        p = common_mul(a[k], b[k], E, M, R)
        q = common_mul(c[k], d[k], E, M, R)
        r = common_add(p, q ^ sb, E, M, R)
        out[k] = r
        acc[k] |= p | q | r


@njit(inline="always")
def gather(g, q, o, oi, d, di, v0, e1, e2, nn, ti):
    """Lane ``q`` of a block's operands ``g`` (18, BLOCK): ray row ``oi`` of ``o``, ``di``
    of ``d``, triangle row ``ti`` (the layout :func:`vpair` reads). Element by element:
    slice assignments compile into numba's broadcasting machinery (seconds of a cold
    start)."""
    for c in range(3):
        g[c, q] = o[oi, c]
        g[3 + c, q] = d[di, c]
        g[6 + c, q] = v0[ti, c]
        g[9 + c, q] = e1[ti, c]
        g[12 + c, q] = e2[ti, c]
        g[15 + c, q] = nn[ti, c]


@njit(cache=True)
def vpair(g, w, n, cons, E, M, R):
    """The pair's operations over a block: ``g`` (18, BLOCK) the operands (O, D, V0, E1,
    E2, N, three rows each), ``w`` (13, BLOCK) out: t', u', v', det, s, w in rows 0-5, and
    row 11 the OR of every intermediate (negative: a lane to recompute)."""
    acc = w[11]
    for k in range(n):
        acc[k] = 0
    tx, ty, tz = w[6], w[7], w[8]
    _vsub(g[6], g[0], tx, acc, n, E, M, R)
    _vsub(g[7], g[1], ty, acc, n, E, M, R)
    _vsub(g[8], g[2], tz, acc, n, E, M, R)
    det, tp, up, vp, s, ww = w[3], w[0], w[1], w[2], w[4], w[5]
    _vdot(g[15], g[16], g[17], g[3], g[4], g[5], det, acc, n, E, M, R)
    _vdot(g[15], g[16], g[17], tx, ty, tz, tp, acc, n, E, M, R)
    qx, qy, qz = w[9], w[10], w[12]
    _vcross(g[4], tz, g[5], ty, qx, acc, n, E, M, R)
    _vcross(g[5], tx, g[3], tz, qy, acc, n, E, M, R)
    _vcross(g[3], ty, g[4], tx, qz, acc, n, E, M, R)
    _vdot(qx, qy, qz, g[12], g[13], g[14], up, acc, n, E, M, R)
    _vdot(qx, qy, qz, g[9], g[10], g[11], vp, acc, n, E, M, R)
    sb = np.int64(1) << (E + M)
    for k in range(n):
        up[k] ^= sb                                            # u' = neg(Q.E2)
    for k in range(n):
        s[k] = common_add(up[k], vp[k], E, M, R)               # s = u' + v' (not minus)
        acc[k] |= s[k]
    if cons:
        _vsub(det, s, ww, acc, n, E, M, R)


@njit(cache=True)
def store(i, tp, up, vp, det, cnt, t_o, u_o, v_o, det_o, cnt_o):
    """Row ``i`` of the pair outputs: t', u', v', det and the packed event counts unpacked
    into their three columns."""
    t_o[i] = tp
    u_o[i] = up
    v_o[i] = vp
    det_o[i] = det
    cnt_o[i, 0] = cnt & 0xFF
    cnt_o[i, 1] = (cnt >> 8) & 0xFF
    cnt_o[i, 2] = (cnt >> 16) & 0xFF
