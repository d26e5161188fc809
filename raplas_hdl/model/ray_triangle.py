"""Bit-exact golden model of the ray-triangle unit (division-free Moller-Trumbore).

The model performs the same floating-point operations, in the same order and with the same
operands, as :class:`raplas_hdl.rtl.ray_triangle.RayTriangleUnit`, so the two agree on
every bit. One compiled numba loop runs over the pairs and calls the scalar kernels of
:mod:`raplas_hdl.fp.kernels`.

Operations (``sub(a, b) = add(a, neg(b))``; vectors are ``(x, y, z)``)::

     1- 3  T  = V0 - O          tx = sub(v0x, ox), ty = sub(v0y, oy), tz = sub(v0z, oz)
     4- 8  det = N.D            add(add(mul(nx, dx), mul(ny, dy)), mul(nz, dz))
     9-13  t'  = N.T            add(add(mul(nx, tx), mul(ny, ty)), mul(nz, tz))
    14-22  Q   = D x T          qx = sub(mul(dy, tz), mul(dz, ty))
                                qy = sub(mul(dz, tx), mul(dx, tz))
                                qz = sub(mul(dx, ty), mul(dy, tx))
    23-27  u'  = neg(Q.E2)      neg(add(add(mul(qx, e2x), mul(qy, e2y)), mul(qz, e2z)))
    28-32  v'  = Q.E1           add(add(mul(qx, e1x), mul(qy, e1y)), mul(qz, e1z))
    33     s   = add(u', v')
    34     w   = sub(det, s)    conservative mode only

Every dot product is ``(x*x' + y*y') + z*z'``. ``neg`` is a sign flip (a NaN becomes the
canonical NaN) and raises no flag.

Decision, paper mode (raplas.md, "Ray-triangle test")::

    lt(0, det):  hit = le(0, u') & le(0, v') & le(s, det) & le(0, t')
    lt(det, 0):  hit = le(u', 0) & le(v', 0) & le(det, s) & le(t', 0)
    otherwise:   miss

Conservative mode: see :mod:`raplas_hdl.model.conservative` (margins from exponent
arithmetic; either sign of det while ``|det|`` is within its margin; NaN or overflow gives
a hit).

Compilation: the loop is cached on disk by numba, but numba's cache does not notice when
a *callee's* source changes (the FP kernels are compiled into the loop). So at import the
module compares a hash of the kernel sources with the one recorded beside its cache and
drops its own cache entries when they differ.

Certified mode: see :mod:`raplas_hdl.model.certified` (the 34 operations with a running
error bound beside each result; ``outcome`` 0 miss, 1 hit, 2 uncertain, guaranteed against
the exact reference; ``hit = outcome == 1``).

Outputs: ``hit``, ``t = t'``, ``u = u'``, ``v = v'``, ``det`` (bit patterns), ``flags``,
the OR of the event flags of the pair's operations (33 in paper mode, 34 in
conservative mode), and ``event_counts``, the number of the pair's operations that raised
each event (overflow, underflow, invalid; 0 to 34 each). ``flags`` bit ``k`` is set exactly
when count ``k`` is non-zero. The caller carries the ray and triangle IDs.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..fp.fast import fast_add, fast_mul
from ..fp.format import FLAG_INVALID, FLAG_OVERFLOW, FLAG_UNDERFLOW, FPFormat, check_format
from ..fp.kernels import is_nan_k, le_k, lt_k, neg_k, rmode_code
from ..fp.numba_cache import drop_stale_cache
from ..parallel import run_chunks
from .certified import DEFAULT_VARIANT, intersect_certified
from .conservative import margin_constants, margin_k, margin_table
from .modes import MODES, check_mode
from .pair_kernels import BLOCK, add_op, gather, mul_op, store, sub_op, tally, vpair

__all__ = ["EVENTS", "MODES", "N_OPS", "intersect"]

#: Arithmetic operations per pair, by mode.
N_OPS = {"paper": 33, "conservative": 34, "certified": 34}

#: The events counted per pair, in the columns of ``event_counts``.
EVENTS = ("overflow", "underflow", "invalid")


drop_stale_cache(__file__)


@njit(cache=True)
def _dot(a0, a1, a2, b0, b1, b2, e, m, r):
    p0, f0 = mul_op(a0, b0, e, m, r)
    p1, f1 = mul_op(a1, b1, e, m, r)
    p2, f2 = mul_op(a2, b2, e, m, r)
    s01, f3 = add_op(p0, p1, e, m, r)
    s, f4 = add_op(s01, p2, e, m, r)
    return s, tally(f0) + tally(f1) + tally(f2) + tally(f3) + tally(f4)


@njit(cache=True)
def _cross_term(a, b, c, d, e, m, r):
    """``a*b - c*d``."""
    p, f0 = mul_op(a, b, e, m, r)
    q, f1 = mul_op(c, d, e, m, r)
    x, f2 = sub_op(p, q, e, m, r)
    return x, tally(f0) + tally(f1) + tally(f2)


@njit(cache=True)
def _field3(x, i, m, emf):
    """Largest biased exponent field of the three components of row ``i``."""
    return max(max((np.int64(x[i, 0]) >> m) & emf, (np.int64(x[i, 1]) >> m) & emf),
               (np.int64(x[i, 2]) >> m) & emf)


@njit(cache=True)
def pair_margins(o, oi, d, di, v0, e1, e2, nn, ti, e, m, mc):
    emf = (np.int64(1) << e) - 1
    return margin_k(_field3(o, oi, m, emf), _field3(d, di, m, emf), _field3(v0, ti, m, emf),
                    _field3(e1, ti, m, emf), _field3(e2, ti, m, emf), _field3(nn, ti, m, emf),
                    mc, e, m)


@njit(cache=True)
def _decide(det, tp, up, vp, s, w, bad, cons, margins, e, m):
    """The hit decision of either mode from the pair's results (module docstring)."""
    zero = np.uint32(0)
    if not cons:
        if lt_k(zero, det, e, m):
            return (le_k(zero, up, e, m) and le_k(zero, vp, e, m) and le_k(s, det, e, m)
                    and le_k(zero, tp, e, m))
        if lt_k(det, zero, e, m):
            return (le_k(up, zero, e, m) and le_k(vp, zero, e, m) and le_k(det, s, e, m)
                    and le_k(tp, zero, e, m))
        return False
    sign = np.uint32(1) << (e + m)
    m_det, m_t, m_u, m_v, m_w = margins
    pos = (le_k(m_u ^ sign, up, e, m) and le_k(m_v ^ sign, vp, e, m)
           and le_k(m_w ^ sign, w, e, m) and le_k(m_t ^ sign, tp, e, m))
    neg = (le_k(up, m_u, e, m) and le_k(vp, m_v, e, m) and le_k(w, m_w, e, m)
           and le_k(tp, m_t, e, m))
    return bad or (le_k(m_det ^ sign, det, e, m) and pos) or (le_k(det, m_det, e, m) and neg)


@njit(cache=True)
def pair_exact(o, oi, d, di, v0, e1, e2, nn, ti, e, m, r, cons, mc):
    """One pair through the reference kernels (any operands).

    The ray is row ``oi`` of ``o`` and row ``di`` of ``d``; the triangle is row ``ti`` of
    ``v0, e1, e2, nn``; ``cons`` selects the conservative mode, whose margin constants are
    ``mc`` (:func:`~raplas_hdl.model.conservative.margin_table`). Returns ``(hit, t', u',
    v', det, counts)``, ``counts`` the packed event counts (overflow in bits 0-7,
    underflow 8-15, invalid 16-23).
    """
    tx, f0 = sub_op(v0[ti, 0], o[oi, 0], e, m, r)
    ty, f1 = sub_op(v0[ti, 1], o[oi, 1], e, m, r)
    tz, f2 = sub_op(v0[ti, 2], o[oi, 2], e, m, r)
    det, c3 = _dot(nn[ti, 0], nn[ti, 1], nn[ti, 2], d[di, 0], d[di, 1], d[di, 2], e, m, r)
    tp, c4 = _dot(nn[ti, 0], nn[ti, 1], nn[ti, 2], tx, ty, tz, e, m, r)
    qx, c5 = _cross_term(d[di, 1], tz, d[di, 2], ty, e, m, r)
    qy, c6 = _cross_term(d[di, 2], tx, d[di, 0], tz, e, m, r)
    qz, c7 = _cross_term(d[di, 0], ty, d[di, 1], tx, e, m, r)
    qe2, c8 = _dot(qx, qy, qz, e2[ti, 0], e2[ti, 1], e2[ti, 2], e, m, r)
    up = neg_k(qe2, e, m)
    vp, c9 = _dot(qx, qy, qz, e1[ti, 0], e1[ti, 1], e1[ti, 2], e, m, r)
    s, f10 = add_op(up, vp, e, m, r)
    cnt = (tally(f0) + tally(f1) + tally(f2) + c3 + c4 + c5 + c6 + c7 + c8 + c9
           + tally(f10))
    w = np.uint32(0)
    bad = False
    margins = (w, w, w, w, w)
    if cons:
        w, f11 = sub_op(det, s, e, m, r)
        cnt += tally(f11)
        bad = (is_nan_k(det, e, m) or is_nan_k(tp, e, m) or is_nan_k(up, e, m)
               or is_nan_k(vp, e, m) or is_nan_k(w, e, m) or (cnt & 0xFF) != 0)
        margins = pair_margins(o, oi, d, di, v0, e1, e2, nn, ti, e, m, mc)
    h = _decide(det, tp, up, vp, s, w, bad, cons, margins, e, m)
    return h, tp, up, vp, det, cnt


@njit(cache=True)
def _fdot(a0, a1, a2, b0, b1, b2, E, M, R):
    p0 = fast_mul(np.int64(a0), np.int64(b0), E, M, R)
    p1 = fast_mul(np.int64(a1), np.int64(b1), E, M, R)
    p2 = fast_mul(np.int64(a2), np.int64(b2), E, M, R)
    s = fast_add(p0, p1, E, M, R)
    return fast_add(s, p2, E, M, R), p0 | p1 | p2 | s


@njit(cache=True)
def _fcross(a, b, c, dd, E, M, R):
    """``a*b - c*dd``."""
    p = fast_mul(np.int64(a), np.int64(b), E, M, R)
    q = fast_mul(np.int64(c), np.int64(dd), E, M, R)
    return fast_add(p, q ^ (np.int64(1) << (E + M)), E, M, R), p | q


@njit(cache=True)
def pair_fast(o, oi, d, di, v0, e1, e2, nn, ti, E, M, R, cons, mc):
    """:func:`pair_exact` when every operation of the pair is flag-free and takes the fast
    path of :mod:`raplas_hdl.fp.fast` (almost every pair); returns ``(ok, hit, t', u', v',
    det)``, and ``ok`` False when the caller must run :func:`pair_exact` instead. Callers
    pass ``E, M, R`` as compile-time constants."""
    sb = np.int64(1) << (E + M)
    tx = fast_add(np.int64(v0[ti, 0]), np.int64(o[oi, 0]) ^ sb, E, M, R)
    ty = fast_add(np.int64(v0[ti, 1]), np.int64(o[oi, 1]) ^ sb, E, M, R)
    tz = fast_add(np.int64(v0[ti, 2]), np.int64(o[oi, 2]) ^ sb, E, M, R)
    det, b1 = _fdot(nn[ti, 0], nn[ti, 1], nn[ti, 2], d[di, 0], d[di, 1], d[di, 2], E, M, R)
    tp, b2 = _fdot(nn[ti, 0], nn[ti, 1], nn[ti, 2], tx, ty, tz, E, M, R)
    qx, b3 = _fcross(d[di, 1], tz, d[di, 2], ty, E, M, R)
    qy, b4 = _fcross(d[di, 2], tx, d[di, 0], tz, E, M, R)
    qz, b5 = _fcross(d[di, 0], ty, d[di, 1], tx, E, M, R)
    qe2, b6 = _fdot(qx, qy, qz, e2[ti, 0], e2[ti, 1], e2[ti, 2], E, M, R)
    vp, b7 = _fdot(qx, qy, qz, e1[ti, 0], e1[ti, 1], e1[ti, 2], E, M, R)
    up = qe2 ^ sb
    s = fast_add(up, vp, E, M, R)
    w = np.int64(0)
    if cons:
        w = fast_add(det, s ^ sb, E, M, R)
    if (tx | ty | tz | det | tp | qx | qy | qz | qe2 | vp | s | w
            | b1 | b2 | b3 | b4 | b5 | b6 | b7) < 0:
        z = np.uint32(0)
        return False, False, z, z, z, z
    margins = (np.uint32(0), np.uint32(0), np.uint32(0), np.uint32(0), np.uint32(0))
    if cons:
        margins = pair_margins(o, oi, d, di, v0, e1, e2, nn, ti, E, M, mc)
    h = _decide(np.uint32(det), np.uint32(tp), np.uint32(up), np.uint32(vp), np.uint32(s),
                np.uint32(w), np.bool_(False), cons, margins, E, M)
    return True, h, np.uint32(tp), np.uint32(up), np.uint32(vp), np.uint32(det)


@njit(cache=True)
def _key(x, sb):
    """Order key of a finite pattern from the common case (normal or zero)."""
    mag = x & (sb - 1)
    return -mag if (x & sb) != 0 else mag


@njit(cache=True)
def hit_common(det, tp, up, vp, s, ww, cons, margins, sb):
    """The hit decision of a lane whose every operation took the common case (all values
    finite and normal or zero, no flag): the contract's comparisons as integer keys."""
    kd, kt, ku, kv, ks = (_key(np.int64(det), sb), _key(np.int64(tp), sb),
                          _key(np.int64(up), sb), _key(np.int64(vp), sb), _key(np.int64(s), sb))
    if not cons:
        if kd > 0:
            return ku >= 0 and kv >= 0 and ks <= kd and kt >= 0
        if kd < 0:
            return ku <= 0 and kv <= 0 and ks >= kd and kt <= 0
        return False
    m_det, m_t, m_u, m_v, m_w = margins
    kmd, kmt, kmu, kmv, kmw = (_key(np.int64(m_det), sb), _key(np.int64(m_t), sb),
                               _key(np.int64(m_u), sb), _key(np.int64(m_v), sb),
                               _key(np.int64(m_w), sb))
    kw = _key(np.int64(ww), sb)
    pos = -kmu <= ku and -kmv <= kv and -kmw <= kw and -kmt <= kt
    neg = ku <= kmu and kv <= kmv and kw <= kmw and kt <= kmt
    return (-kmd <= kd and pos) or (kd <= kmd and neg)


@njit(nogil=True, cache=True)
def pairs_loop(o, d, v0, e1, e2, nn, mc, lo, hi, hit, t_o, u_o, v_o, det_o, cnt_o, e, m, r, cons):
    """Pairs ``lo .. hi-1`` of :func:`intersect`, a block at a time (:func:`vpair`; lanes
    that leave the common case through :func:`pair_fast` and :func:`pair_exact`). The format
    ``(e, m)``, the rounding code ``r`` and the mode ``cons`` are runtime arguments: one
    compile serves them all."""
    g = np.empty((18, BLOCK), np.int64)
    w = np.empty((13, BLOCK), np.int64)
    sb = np.int64(1) << (e + m)
    zero = np.uint32(0)
    for start in range(lo, hi, BLOCK):
        n = min(BLOCK, hi - start)
        for k in range(n):
            i = start + k
            gather(g, k, o, i, d, i, v0, e1, e2, nn, i)
        vpair(g, w, n, cons, e, m, r)
        for k in range(n):
            i = start + k
            cnt = np.int64(0)
            if w[11, k] >= 0:
                margins = (zero, zero, zero, zero, zero)
                if cons:
                    margins = pair_margins(o, i, d, i, v0, e1, e2, nn, i, e, m, mc)
                h = hit_common(w[3, k], w[0, k], w[1, k], w[2, k], w[4, k], w[5, k], cons,
                               margins, sb)
                tp, up, vp, det = (np.uint32(w[0, k]), np.uint32(w[1, k]),
                                   np.uint32(w[2, k]), np.uint32(w[3, k]))
            else:
                ok, h, tp, up, vp, det = pair_fast(o, i, d, i, v0, e1, e2, nn, i, e, m, r,
                                                   cons, mc)
                if not ok:
                    h, tp, up, vp, det, cnt = pair_exact(o, i, d, i, v0, e1, e2, nn, i, e,
                                                         m, r, cons, mc)
            hit[i] = h
            store(i, tp, up, vp, det, cnt, t_o, u_o, v_o, det_o, cnt_o)


def operand_array(x, fmt, name):
    a = np.asarray(x)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), not {a.shape}")
    if a.dtype.kind not in "iu":
        raise ValueError(f"{name} must hold integer bit patterns, not dtype {a.dtype}")
    if a.size and (a.min() < 0 or a.max() > fmt.mask):
        raise ValueError(f"{name} holds patterns wider than the {fmt.width}-bit format "
                         f"{fmt.name}")
    return np.ascontiguousarray(a, dtype=np.uint32)


def intersect(o, d, v0, e1, e2, n, fmt: FPFormat, mode: str = "paper",
              margin_scale: float = 1.0, bound_variant: str | None = None) -> dict:
    """Run the ray-triangle unit's arithmetic on ``len(o)`` (ray, triangle) pairs.

    Parameters
    ----------
    o, d : array_like of uint32, shape (n, 3)
        Ray origin and direction, bit patterns of ``fmt``.
    v0, e1, e2, n : array_like of uint32, shape (n, 3)
        Triangle record (V0, E1 = V1 - V0, E2 = V2 - V0, N = E1 x E2), bit patterns.
    fmt : FPFormat
        Format and rounding.
    mode : {"paper", "conservative", "certified"}
        The paper's exact inequalities, the widened tests of the conservative mode, or the
        three-valued outcome of the certified mode.
    margin_scale : float
        ``s`` of the conservative margin, or the factor on every certified bound (1: the
        derivation; smaller only for the negative control); ignored in paper mode.
    bound_variant : str, optional
        Certified mode only: a key of :data:`raplas_hdl.model.certified.VARIANTS`
        (default :data:`~raplas_hdl.model.certified.DEFAULT_VARIANT`).

    Returns
    -------
    dict
        ``hit`` (bool), ``t``, ``u``, ``v``, ``det`` (uint32: t', u', v', det),
        ``flags`` (uint8, OR of the event flags of the pair's operations) and
        ``event_counts`` (uint8, shape (n, 3): the pair's operations that raised overflow,
        underflow and invalid, columns in the order of :data:`EVENTS`). Certified mode
        also ``outcome`` (uint8: 0 miss, 1 hit, 2 uncertain), and ``hit = outcome == 1``.

    Raises
    ------
    ValueError
        For a wrong shape, a pattern wider than the format, an unknown mode, or a format
        the conservative mode does not support.
    """
    check_format(fmt)
    check_mode(mode)
    arrs = [operand_array(x, fmt, name) for x, name in zip((o, d, v0, e1, e2, n),
                                                   ("o", "d", "v0", "e1", "e2", "n"))]
    count = arrs[0].shape[0]
    if any(a.shape[0] != count for a in arrs):
        raise ValueError("o, d, v0, e1, e2 and n must have the same number of rows")
    if mode == "certified":
        res = intersect_certified(arrs, fmt, margin_scale, bound_variant or DEFAULT_VARIANT)
        res["hit"] = res["outcome"] == 1
        res["flags"] = _flags(res["event_counts"])
        return res
    if bound_variant is not None:
        raise ValueError("bound_variant applies to the certified mode only")
    conservative = mode == "conservative"
    mc = (margin_table(margin_constants(fmt, margin_scale)) if conservative
          else np.zeros((3, 5), np.int64))
    hit = np.empty(count, dtype=np.bool_)
    outs = [np.empty(count, dtype=np.uint32) for _ in range(4)]
    counts = np.empty((count, 3), dtype=np.uint8)
    key = (np.int64(fmt.exp_bits), np.int64(fmt.man_bits), np.int64(rmode_code(fmt)),
           np.bool_(conservative))
    run_chunks(count, lambda lo, hi: pairs_loop(*arrs, mc, lo, hi, hit, *outs, counts, *key))
    return {"hit": hit, "t": outs[0], "u": outs[1], "v": outs[2], "det": outs[3],
            "flags": _flags(counts), "event_counts": counts}


def _flags(counts):
    return ((counts[:, 0] != 0) * FLAG_OVERFLOW | (counts[:, 1] != 0) * FLAG_UNDERFLOW
            | (counts[:, 2] != 0) * FLAG_INVALID).astype(np.uint8)
