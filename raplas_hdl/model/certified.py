"""The certified mode of the ray-triangle unit: a hit / miss / uncertain outcome per pair.

The unit runs the paper's 33 operations plus ``w = sub(det, s)`` (the conservative mode's
34th) and, beside every result, a **running error bound**: an upper bound ``B_x`` on
``|x_unit - x_R|``, where ``x_R`` is the same quantity in **R**, the exact test on the
original float64 geometry and the encoded ray (:mod:`raplas_hdl.host.exact`). The bounds
follow the pair's own magnitudes: every term is formed from the exponent (and, by variant,
a few leading fraction bits) of the operands and results the datapath already has, and
accumulated in a small *bound float* of ``k`` fraction bits that always rounds **up**. The
derivation is in ``docs/certified-mode.md``; in short, with ``U(x)`` an upper bound of
``|x|`` read from ``x``'s exponent field and its ``j`` leading fraction bits::

    inputs     O, D: exact (R uses the encoded ray).  V0: B = ulp(v0) (rne: ulp/2),
               E1, E2, N: the same times (1 + 2**-20) (the host's float64 rounding);
               a zero pattern: B = eta = 2**emin (a flushed value)
    mul a*b    B = U(a) B_b + (U(b) + B_b) B_a + rnd_mul
    add a+b    B = B_a + B_b + rnd_add
    rnd_mul    ulp(result) (rne: ulp/2); eta for a zero result (flush)
    rnd_add    0 if an operand is zero; rtz ulp(result), rne ulp(result)/2, chop
               ulp(max(|a|, |b|, |result|)); plus eta for a zero result

Outcome (``g`` the bound times ``scale``, 1 for the guarantee; comparisons exact)::

    ge(x) = x >= g_x   gt(x) = x > g_x   le(x) = x <= -g_x   lt(x) = x < -g_x
    hit  = (gt(det) & ge(u') & ge(v') & ge(w) & ge(t'))
         | (lt(det) & le(u') & le(v') & le(w) & le(t'))
    miss = (le(det) | lt(u') | lt(v') | lt(w) | lt(t'))      R's positive-det test fails
         & (ge(det) | gt(u') | gt(v') | gt(w) | gt(t'))      and so does its negative one
    outcome = 1 hit, 0 miss, 2 otherwise; also 2 when any operation overflowed or any of
              det, t', u', v', w is infinite or NaN.

R hits with a positive det exactly when ``det > 0, u' >= 0, v' >= 0, w = det - u' - v' >= 0,
t' >= 0``; ``ge(x)`` implies ``x_R >= x - B_x >= 0`` and so on, so a *hit* is an R hit and
a *miss* an R miss, for all three roundings, flushes included.

Domain: every coordinate of the original vertices within ``certified_domain(fmt)`` (then
no component of the record overflows when encoded; the ray may be any finite encoded
value), formats with ``exp_bits <= 9`` (the model evaluates the bound floats in float64,
whose range then holds every bound exactly).

Variants (:data:`VARIANTS`, ``(j, k)``): ``exp`` (``j = 0``: ``U(x) = 2**(ex+1)``, bound
products are exponent adds), ``lead3`` and ``lead6`` (3 or 6 leading fraction bits of every
operand: small LUT multipliers). :data:`DEFAULT_VARIANT` is the one the mode uses. Per
pair the bound datapath is 65 round-up bound adders, 27 bound products and 5 comparators, no
DSP48 (estimates per variant in ``docs/certified-mode.md``).

The model runs the pairs 128 at a time (:func:`block_pairs`: paper mode's vector loops for
the values, a vector loop of *screen bounds* that dominate the unit's and decide almost
every lane's outcome without the bound floats, :func:`pair_full` for the other lanes), the
same bits as one pair at a time (:func:`pairs_one`).
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from ..fp.fast import fast_add, fast_mul
from ..fp.format import FLAG_OVERFLOW, FPFormat, check_format
from ..fp.kernels import neg_k, rmode_code
from ..fp.numba_cache import drop_stale_cache
from ..parallel import run_chunks
from .pair_kernels import BLOCK, add_op, gather, mul_op, store, sub_op, tally, vpair

__all__ = ["VARIANTS", "DEFAULT_VARIANT", "N_OPS", "MAX_EXP_BITS", "certified_constants",
           "certified_domain", "check_certified_format", "pair_certified", "intersect_certified",
           "block_pairs", "block_screened", "exact_pairs", "pairs_listed", "pairs_one",
           "pair_bounds",
           "vscreen", "voutcome", "SCREEN_SLACK", "RECOMPUTE"]

#: Bound variants: name -> (j leading fraction bits read from each |x|, k fraction bits of
#: the bound float).
VARIANTS = {"exp": (0, 3), "lead3": (3, 5), "lead6": (6, 8)}
#: The variant of ``mode="certified"``.
DEFAULT_VARIANT = "lead3"
#: Operations per pair (the paper's 33 and ``w = det - s``).
N_OPS = 34
#: Largest exponent width the model certifies (float64 holds every bound exactly).
MAX_EXP_BITS = 9
#: ``E1, E2, N`` are rounded to float64 on the host before they are encoded: their bound
#: is the format's rounding error times ``1 + 2**-INPUT_SLACK_EXP``.
INPUT_SLACK_EXP = 20

drop_stale_cache(__file__)


def check_certified_format(fmt: FPFormat) -> FPFormat:
    """``fmt`` if the certified mode supports it.

    Raises
    ------
    ValueError
        If ``fmt`` has more than :data:`MAX_EXP_BITS` exponent bits.
    """
    check_format(fmt)
    if fmt.exp_bits > MAX_EXP_BITS:
        raise ValueError(f"the certified mode needs exp_bits <= {MAX_EXP_BITS}, "
                         f"not {fmt.exp_bits} ({fmt.name})")
    return fmt


def certified_domain(fmt: FPFormat) -> float:
    """The largest coordinate bound ``2**P`` (scene coordinates) of the guarantee.

    ``P = floor((emax - 3) / 2)``: with every vertex coordinate within ``2**P`` an edge
    component is within ``2**(P+1)`` and a normal component within ``2**(2P+3) <=
    2**emax``, so no component of the triangle record overflows when it is encoded (the
    bound of an encoded input needs that). Every other overflow is detected per pair and
    gives *uncertain*.
    """
    check_certified_format(fmt)
    return 2.0 ** ((fmt.emax - 3) // 2)


def certified_constants(fmt: FPFormat, scale: float = 1.0,
                        variant: str = DEFAULT_VARIANT) -> np.ndarray:
    """The constants table ``cc`` of :func:`pair_certified`: float64 ``[scale, j, k]``.

    Parameters
    ----------
    fmt : FPFormat
    scale : float
        Factor on every bound before the comparisons (1: the guarantee; the negative
        control of the campaign shrinks it).
    variant : str
        A key of :data:`VARIANTS`.

    Raises
    ------
    ValueError
        For an unsupported format, a scale that is not positive and finite, or an unknown
        variant.
    """
    check_certified_format(fmt)
    s = float(scale)
    if not (s > 0 and math.isfinite(s)):
        raise ValueError(f"the bound scale must be a positive finite number, not {scale!r}")
    if variant not in VARIANTS:
        raise ValueError(f"bound variant must be one of {', '.join(VARIANTS)}, "
                         f"not {variant!r}")
    j, k = VARIANTS[variant]
    return np.array([s, min(j, fmt.man_bits), k], dtype=np.float64)


# -- float64 bit patterns (the bound floats are handled through them, without libm calls) --
@intrinsic
def _f2i(typingctx, x):
    """The bits of a float64 as an int64."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))
    return types.int64(types.float64), codegen


@intrinsic
def _i2f(typingctx, x):
    """The float64 of an int64's bits."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())
    return types.float64(types.int64), codegen


@njit(cache=True)
def _pow2(n):
    """``2.0**n`` for ``-1022 <= n <= 1023`` (every exponent the bounds use for
    ``exp_bits <= 9``)."""
    return _i2f((np.int64(n) + 1023) << 52)


# -- bound floats: non-negative values of k+1 significant bits, every operation rounds up --
@njit(cache=True)
def _ru(x, k):
    """``x >= 0`` rounded up to ``k + 1`` significant bits (0, inf and NaN unchanged; ``x``
    is a normal float64)."""
    b = _f2i(x)
    if b == 0 or (b >> 52) >= 2047:
        return x
    mask = (np.int64(1) << (52 - k)) - 1
    return _i2f((b + mask) & ~mask)


@njit(cache=True)
def _badd(a, b, k):
    """``a + b`` of bound floats, the exact sum rounded up to ``k + 1`` bits."""
    s = a + b
    if not math.isfinite(s):
        return s
    bb = s - a
    err = (a - (s - bb)) + (b - bb)           # a + b = s + err exactly (two-sum)
    r = _ru(s, k)
    if err > 0.0 and r == s:                  # s already on the grid, the sum above it
        r = _i2f(_f2i(s) + (np.int64(1) << (52 - k)))
    return r


@njit(cache=True)
def _bmul(a, b, k):
    """``a * b`` of bound floats rounded up (exact in float64 before the rounding: both
    have at most 24 significant bits)."""
    return _ru(a * b, k)


# -- what the datapath's patterns tell about magnitudes ---------------------------------------
@njit(cache=True)
def _value(x, e, m):
    """The value of a finite pattern (a denormal pattern is zero)."""
    x = np.int64(x)
    field = (x >> m) & ((np.int64(1) << e) - 1)
    if field == 0:
        return 0.0
    bias = (np.int64(1) << (e - 1)) - 1
    bits = (((field - bias + 1023) << 52) | ((x & ((np.int64(1) << m) - 1)) << (52 - m))
            | (((x >> (e + m)) & 1) << 63))
    return _i2f(bits)


@njit(cache=True)
def _upper(x, e, m, j):
    """``U(x) > |x|`` from the exponent field and ``j`` leading fraction bits:
    ``(1.f_j + 2**-j) * 2**ex`` (``j = 0``: ``2**(ex+1)``); 0 for a zero pattern."""
    x = np.int64(x)
    field = (x >> m) & ((np.int64(1) << e) - 1)
    if field == 0:
        return 0.0
    bias = (np.int64(1) << (e - 1)) - 1
    lead = ((x & ((np.int64(1) << m) - 1)) >> (m - j)) | (np.int64(1) << j)
    return float(lead + 1) * _pow2(field - bias - j)


@njit(cache=True)
def _exp(x, e, m):
    """Unbiased exponent of a pattern's field (the field itself for zero: never used)."""
    return ((np.int64(x) >> m) & ((np.int64(1) << e) - 1)) - ((np.int64(1) << (e - 1)) - 1)


@njit(cache=True)
def _is_zero(x, e, m):
    return ((np.int64(x) >> m) & ((np.int64(1) << e) - 1)) == 0


@njit(cache=True)
def _eta(e):
    return _pow2(2 - (np.int64(1) << (e - 1)))                     # 2**emin


@njit(cache=True)
def _ulp(x, e, m, r):
    """ulp (rne: ulp/2) of a pattern that is not zero."""
    return _pow2(_exp(x, e, m) - m - (1 if r == 1 else 0))


@njit(cache=True)
def _slack(b, slack, k):
    """``b``, times ``1 + 2**-INPUT_SLACK_EXP`` rounded up when ``slack``."""
    if slack:
        b = _ru(b + b * _pow2(-INPUT_SLACK_EXP), k)
    return b


@njit(cache=True)
def _input_bound(x, e, m, r, slack, k):
    """Bound of an encoded input against its original value: ulp (rne: ulp/2), eta for a
    zero pattern; times ``1 + 2**-INPUT_SLACK_EXP`` when ``slack``."""
    return _slack(_eta(e) if _is_zero(x, e, m) else _ulp(x, e, m, r), slack, k)


@njit(cache=True)
def _rnd_mul(p, e, m, r):
    if _is_zero(p, e, m):
        return _eta(e)
    return _ulp(p, e, m, r)


@njit(cache=True)
def _rnd_add_nz(a, b, s, e, m, r):
    """:func:`_rnd_add` when none of ``a, b, s`` is a zero pattern."""
    if r == 2:                                          # chop: ulp of the largest
        return _pow2(max(max(_exp(a, e, m), _exp(b, e, m)), _exp(s, e, m)) - m)
    return _ulp(s, e, m, r)


@njit(cache=True)
def _rnd_add(a, b, s, e, m, r, k):
    """Rounding error bound of ``s = a + b`` (operand patterns as the adder sees them)."""
    if _is_zero(a, e, m) or _is_zero(b, e, m):
        return 0.0                                      # x + 0 = x in every rounding
    if not _is_zero(s, e, m):
        return _rnd_add_nz(a, b, s, e, m, r)
    if r == 2:                                          # chop: ulp of the largest
        top = max(_exp(a, e, m), _exp(b, e, m))
        return _badd(_pow2(top - m), _eta(e), k)
    return _eta(e)


@njit(cache=True)
def _mul_bound(a, ba, b, bb, rnd, e, m, j, k):
    """``U(a) B_b + (U(b) + B_b) B_a + rnd``, the bound of ``mul(a, b)`` with rounding
    term ``rnd``."""
    t1 = _bmul(_upper(a, e, m, j), bb, k)
    t2 = _bmul(_badd(_upper(b, e, m, j), bb, k), ba, k)
    return _badd(_badd(t1, t2, k), rnd, k)


@njit(cache=True)
def _mul_b(a, ba, b, bb, p, e, m, r, j, k):
    """Bound of the product ``p = mul(a, b)``: ``U(a) B_b + (U(b) + B_b) B_a + rnd``."""
    return _mul_bound(a, ba, b, bb, _rnd_mul(p, e, m, r), e, m, j, k)


@njit(cache=True)
def _add_b(a, ba, b, bb, s, e, m, r, k):
    """Bound of ``s = add(a, b)``."""
    return _badd(_badd(ba, bb, k), _rnd_add(a, b, s, e, m, r, k), k)


@njit(cache=True)
def _dot_b(a0, a1, a2, ba0, ba1, ba2, b0, b1, b2, bb0, bb1, bb2, e, m, r, j, k):
    """``(a0*b0 + a1*b1) + a2*b2`` with its bound; returns ``(pattern, bound, counts)``."""
    p0, f0 = mul_op(a0, b0, e, m, r)
    p1, f1 = mul_op(a1, b1, e, m, r)
    p2, f2 = mul_op(a2, b2, e, m, r)
    s01, f3 = add_op(p0, p1, e, m, r)
    s, f4 = add_op(s01, p2, e, m, r)
    q0 = _mul_b(a0, ba0, b0, bb0, p0, e, m, r, j, k)
    q1 = _mul_b(a1, ba1, b1, bb1, p1, e, m, r, j, k)
    q2 = _mul_b(a2, ba2, b2, bb2, p2, e, m, r, j, k)
    g01 = _add_b(p0, q0, p1, q1, s01, e, m, r, k)
    g = _add_b(s01, g01, p2, q2, s, e, m, r, k)
    return s, g, tally(f0) + tally(f1) + tally(f2) + tally(f3) + tally(f4)


@njit(cache=True)
def _cross_b(a, b, bb, c, d, bd, e, m, r, j, k):
    """``a*b - c*d`` with ``a, c`` exact (D) and its bound."""
    p, f0 = mul_op(a, b, e, m, r)
    q, f1 = mul_op(c, d, e, m, r)
    x, f2 = sub_op(p, q, e, m, r)
    gp = _mul_b(b, bb, a, 0.0, p, e, m, r, j, k)
    gq = _mul_b(d, bd, c, 0.0, q, e, m, r, j, k)
    g = _add_b(p, gp, neg_k(q, e, m), gq, x, e, m, r, k)
    return x, g, tally(f0) + tally(f1) + tally(f2)


@njit(cache=True)
def _classify(x, g, e, m):
    """``(ge, gt, le, lt)`` of a value against its scaled bound (module docstring)."""
    v = _value(x, e, m)
    return v >= g, v > g, v <= -g, v < -g


@njit(cache=True)
def pair_bounds(o, oi, d, di, v0, e1, e2, nn, ti, e, m, r, cc):
    """The pair's results and their bounds, as the unit forms them: ``(t', u', v', det, w,
    B_det, B_t', B_u', B_v', B_w, counts)``."""
    j = np.int64(cc[1])
    k = np.int64(cc[2])
    bv = np.empty(3)
    b1 = np.empty(3)
    b2 = np.empty(3)
    bn = np.empty(3)
    for c in range(3):
        bv[c] = _input_bound(v0[ti, c], e, m, r, False, k)
        b1[c] = _input_bound(e1[ti, c], e, m, r, True, k)
        b2[c] = _input_bound(e2[ti, c], e, m, r, True, k)
        bn[c] = _input_bound(nn[ti, c], e, m, r, True, k)
    tx, f0 = sub_op(v0[ti, 0], o[oi, 0], e, m, r)
    ty, f1 = sub_op(v0[ti, 1], o[oi, 1], e, m, r)
    tz, f2 = sub_op(v0[ti, 2], o[oi, 2], e, m, r)
    gtx = _add_b(v0[ti, 0], bv[0], neg_k(o[oi, 0], e, m), 0.0, tx, e, m, r, k)
    gty = _add_b(v0[ti, 1], bv[1], neg_k(o[oi, 1], e, m), 0.0, ty, e, m, r, k)
    gtz = _add_b(v0[ti, 2], bv[2], neg_k(o[oi, 2], e, m), 0.0, tz, e, m, r, k)
    det, gdet, c3 = _dot_b(nn[ti, 0], nn[ti, 1], nn[ti, 2], bn[0], bn[1], bn[2],
                           d[di, 0], d[di, 1], d[di, 2], 0.0, 0.0, 0.0, e, m, r, j, k)
    tp, gt, c4 = _dot_b(nn[ti, 0], nn[ti, 1], nn[ti, 2], bn[0], bn[1], bn[2],
                        tx, ty, tz, gtx, gty, gtz, e, m, r, j, k)
    qx, gqx, c5 = _cross_b(d[di, 1], tz, gtz, d[di, 2], ty, gty, e, m, r, j, k)
    qy, gqy, c6 = _cross_b(d[di, 2], tx, gtx, d[di, 0], tz, gtz, e, m, r, j, k)
    qz, gqz, c7 = _cross_b(d[di, 0], ty, gty, d[di, 1], tx, gtx, e, m, r, j, k)
    qe2, gu, c8 = _dot_b(e2[ti, 0], e2[ti, 1], e2[ti, 2], b2[0], b2[1], b2[2],
                         qx, qy, qz, gqx, gqy, gqz, e, m, r, j, k)
    up = neg_k(qe2, e, m)
    vp, gv, c9 = _dot_b(e1[ti, 0], e1[ti, 1], e1[ti, 2], b1[0], b1[1], b1[2],
                        qx, qy, qz, gqx, gqy, gqz, e, m, r, j, k)
    s, f10 = add_op(up, vp, e, m, r)
    gs = _add_b(up, gu, vp, gv, s, e, m, r, k)
    w, f11 = sub_op(det, s, e, m, r)
    gw = _add_b(det, gdet, neg_k(s, e, m), gs, w, e, m, r, k)
    cnt = (tally(f0) + tally(f1) + tally(f2) + c3 + c4 + c5 + c6 + c7 + c8 + c9
           + tally(f10) + tally(f11))
    return tp, up, vp, det, w, gdet, gt, gu, gv, gw, cnt


@njit(cache=True)
def pair_full(o, oi, d, di, v0, e1, e2, nn, ti, e, m, r, cc):
    """:func:`pair_certified` with every result: ``(outcome, t', u', v', det, counts)``."""
    tp, up, vp, det, w, gdet, gt, gu, gv, gw, cnt = pair_bounds(o, oi, d, di, v0, e1, e2, nn,
                                                                ti, e, m, r, cc)
    emf = (np.int64(1) << e) - 1
    special = False
    for x in (det, tp, up, vp, w):
        special = special or ((np.int64(x) >> m) & emf) == emf
    if special or (cnt & 0xFF) != 0:
        return np.uint8(2), tp, up, vp, det, cnt
    oc = _outcome(det, tp, up, vp, w, gdet, gt, gu, gv, gw, cc[0], e, m)
    return oc, tp, up, vp, det, cnt


@njit(cache=True)
def _outcome(det, tp, up, vp, w, gdet, gt, gu, gv, gw, sc, e, m):
    """Outcome (uint8) of finite results without overflow from their bounds, each scaled
    by ``sc`` (module docstring)."""
    d_ge, d_gt, d_le, d_lt = _classify(det, gdet * sc, e, m)
    t_ge, t_gt, t_le, t_lt = _classify(tp, gt * sc, e, m)
    u_ge, u_gt, u_le, u_lt = _classify(up, gu * sc, e, m)
    v_ge, v_gt, v_le, v_lt = _classify(vp, gv * sc, e, m)
    w_ge, w_gt, w_le, w_lt = _classify(w, gw * sc, e, m)
    if ((d_gt and u_ge and v_ge and w_ge and t_ge)
            or (d_lt and u_le and v_le and w_le and t_le)):
        return np.uint8(1)
    if ((d_le or u_lt or v_lt or w_lt or t_lt)
            and (d_ge or u_gt or v_gt or w_gt or t_gt)):
        return np.uint8(0)
    return np.uint8(2)


@njit(cache=True)
def pair_certified(o, oi, d, di, v0, e1, e2, nn, ti, e, m, r, cc):
    """One pair of the certified mode (the array conventions of
    :func:`~raplas_hdl.model.ray_triangle.pair_exact`: the ray is row ``oi`` of ``o`` and
    row ``di`` of ``d``, the triangle row ``ti`` of ``v0, e1, e2, nn``; ``cc`` the
    :func:`certified_constants`). Returns ``(outcome, t', det, counts)``: outcome 0 miss,
    1 hit, 2 uncertain (uint8); t' and det bit patterns; ``counts`` the packed event counts
    of the 34 operations (overflow in bits 0-7, underflow 8-15, invalid 16-23)."""
    out, tp, up, vp, det, cnt = pair_full(o, oi, d, di, v0, e1, e2, nn, ti, e, m, r, cc)
    return out, tp, det, cnt


# -- pairs a block at a time ------------------------------------------------------------------
# The values of a block come from :func:`~raplas_hdl.model.pair_kernels.vpair` (the 34
# operations as vector loops of the common case, BLOCK lanes); a lane that leaves the common
# case only through zero operands or an exact zero sum (axis-aligned geometry: a floor, a
# wall) is recomputed alone with the flag-free fast paths of :mod:`raplas_hdl.fp.fast`
# (:func:`_lane_fast`), which give the same bits. The outcome of each of these lanes is
# decided from *screen bounds* ``G_x >= B_x`` (:func:`vscreen`), one vector loop of plain
# float64 arithmetic over the block; a lane the screen leaves uncertain, and every lane with
# an event flag or a special value, is recomputed alone by :func:`pair_full` with the
# unit's bounds. The outcome is the same bits either way (the screen's argument, below).
#
# **Why a screen decision is the unit's.** ``_outcome`` is monotone in the bounds: each of
# ``ge, gt, le, lt`` with a larger bound implies the same comparison with a smaller one,
# and *hit* and *miss* are ANDs and ORs of them; *hit* and *miss* exclude each other for
# any bounds ``>= 0``. So if the outcome from bounds ``G >= B`` is hit (miss), the outcome
# from ``B`` is hit (miss) too, and only where the screen says *uncertain* is ``B`` needed.
# ``G >= B``, per step of :func:`pair_bounds`, with ``K = 1 + 2**-k``:
#
# - the bound floats round up to ``k + 1`` bits: ``badd(a, b) <= K (a + b)``,
#   ``bmul(a, b) <= K a b`` (exact products), and each bound operation is monotone in its
#   operands, so a step's screen formula over screen operands dominates the step;
# - ``mul_b = badd(badd(bmul(U(a), B_b), bmul(badd(U(b), B_b), B_a)), rnd)`` is at most
#   ``K^3 U(a) B_b + K^4 (U(b) + B_b) B_a + K rnd``; ``add_b = badd(badd(B_a, B_b), rnd)``
#   at most ``K^2 (B_a + B_b) + K rnd``; the input bounds at most ``(ulp + eta)`` times
#   ``(1 + 2**-20) K`` (``K`` and the slack only for E1, E2, N);
# - rounding terms, with ``ulp_r`` the ulp (rne: half of it) and ``eta`` the flush
#   bound: each of the unit's terms is 0, ``eta`` or ``ulp_r`` of the result for rtz and rne
#   (at most ``ulp_r(s) + eta``); for chop ``2**(max exponent - m)`` or
#   ``badd(2**(top - m), eta)`` (at most ``K (2**-m A + 2**(e_s - m) + eta)`` with ``A``
#   an upper bound of ``|a| + |b|``). Inside the dot products and cross products the
#   products and the first partial sum are not kept, so their magnitudes are bounded from
#   the operands: ``|p| <= (1 + 2**-m) U(a) U(b)`` (rne may round up by half an ulp) and
#   ``|s01| <= (1 + 2**-m) (|p0| + |p1|)``; a product's term is at most ``2**-m |p| +
#   eta``, the partial sum's at most ``K (2**-m |s01| + eta)`` in every rounding;
# - float64 evaluates these sums and products of non-negative numbers (none below
#   ``eta**2``, none near overflow for ``exp_bits <= 9``) each at most ``2**-53`` low, a few
#   hundred of them per bound: the final factor :data:`SCREEN_SLACK` covers them, and the
#   comparison ``x >= G * scale`` rounds monotonically.
#
# ``tests/model/test_certified_screen.py`` checks ``G >= B`` against :func:`pair_bounds` lane
# by lane (stress families, specials, every format and variant).

#: Factor on every screen bound: float64's rounding of the screen's arithmetic.
SCREEN_SLACK = 1.0 + 2.0 ** -30


# The screen's helpers are inlined into its one loop (calls would keep LLVM from
# vectorising it).
@njit(inline="always")
def _s_pow2(n):
    return _i2f((np.int64(n) + 1023) << 52)


@njit(inline="always")
def _s_exp(x, e, m):
    return ((np.int64(x) >> m) & ((np.int64(1) << e) - 1)) - ((np.int64(1) << (e - 1)) - 1)


@njit(inline="always")
def _s_upper(x, e, m, j):
    """:func:`_upper` of any finite pattern, branch-free, built as float64 bits: exponent
    ``ex``, fraction the ``j`` leading bits plus one unit of the ``j``-th (a carry adds into
    the exponent)."""
    x = np.int64(x)
    field = (x >> m) & ((np.int64(1) << e) - 1)
    bias = (np.int64(1) << (e - 1)) - 1
    lead = (x & ((np.int64(1) << m) - 1)) >> (m - j)
    u = _i2f((((field - bias + 1023) << 52) | (lead << (52 - j))) + (np.int64(1) << (52 - j)))
    return u if field != 0 else 0.0


@njit(inline="always")
def _s_ulp(x, e, m, r, eta):
    """``ulp_r(x) + eta`` of any finite pattern: at least ``ulp_r(x)`` and at least ``eta``
    (a zero pattern's exponent is the field's, ``-bias``)."""
    return _s_pow2(_s_exp(x, e, m) - m - (1 if r == 1 else 0)) + eta


@njit(inline="always")
def _s_rnd(s, a_mag, e, m, r, kk, eta):
    """Screen of an adder's rounding term, result pattern ``s``, ``a_mag`` an upper bound
    of the operands' ``|a| + |b|``."""
    if r == 2:
        return kk * (_s_pow2(-m) * a_mag + _s_pow2(_s_exp(s, e, m) - m) + eta)
    return _s_ulp(s, e, m, r, eta)


@njit(inline="always")
def _s_mul(ua, ba, ub, bb, m, kk, eta):
    """Screen of ``_mul_b`` (``U(a) B_b + (U(b) + B_b) B_a + rnd``, rounded up thrice) from
    the operands' magnitudes ``U`` and screen bounds ``B``; returns ``(G, P)``, ``P >= |p|``
    the product's magnitude bound, which its rounding term and the sums after it use."""
    um = _s_pow2(-m)
    p = (1.0 + um) * ua * ub
    k3 = kk * kk * kk
    return k3 * ua * bb + k3 * kk * (ub + bb) * ba + kk * (um * p + eta), p


@njit(inline="always")
def _s_dot(ua0, ua1, ua2, ba0, ba1, ba2, ub0, ub1, ub2, bb0, bb1, bb2, s, e, m, r, kk, eta):
    """Screen of ``_dot_b``: ``(a0*b0 + a1*b1) + a2*b2`` with the operands' magnitudes ``U``
    and screen bounds ``B``, result pattern ``s``."""
    q0, p0 = _s_mul(ua0, ba0, ub0, bb0, m, kk, eta)
    q1, p1 = _s_mul(ua1, ba1, ub1, bb1, m, kk, eta)
    q2, p2 = _s_mul(ua2, ba2, ub2, bb2, m, kk, eta)
    s01 = (1.0 + _s_pow2(-m)) * (p0 + p1)
    g01 = kk * kk * (q0 + q1) + kk * kk * (_s_pow2(-m) * s01 + eta)
    return kk * kk * (g01 + q2) + kk * _s_rnd(s, s01 + p2, e, m, r, kk, eta)


@njit(inline="always")
def _s_cross(ua, ub, bb, uc, ud, bd, x, e, m, r, kk, eta):
    """Screen of ``_cross_b``: ``a*b - c*d``, ``a, c`` exact (``_mul_b(b, B_b, a, 0)``)."""
    gp, pp = _s_mul(ub, bb, ua, 0.0, m, kk, eta)
    gq, pq = _s_mul(ud, bd, uc, 0.0, m, kk, eta)
    return kk * kk * (gp + gq) + kk * _s_rnd(x, pp + pq, e, m, r, kk, eta)


#: Rows of the screen block ``gs`` (float64, (N_SCREEN_ROWS, BLOCK)): the five screen
#: bounds (det, t', u', v', w); then, x, y, z each, the magnitudes ``U`` and screen bounds
#: ``G`` of D, E1, E2, N (the inputs, in that order), of T and of Q; a row of zeros (D's
#: bound).
_UIN, _BIN, _UT, _BT, _UQ, _BQ, _ZERO = 5, 17, 29, 32, 35, 38, 41
N_SCREEN_ROWS = 42
_D, _E1, _E2, _N = 0, 3, 6, 9                  # offsets of the inputs in _UIN and _BIN


@njit(cache=True)
def vscreen(g, w, gs, n, e, m, r, cc):
    """Screen bounds of a block's lanes (after :func:`~raplas_hdl.model.pair_kernels.vpair`
    and :func:`_lane_fast`: ``g`` the operands, ``w`` the results) into rows 0-4 of ``gs``:
    ``G`` of det, t', u', v', w, each at least the unit's bound where the lane's operations
    are flag-free (the section comment). Branch-free loops over the lanes (LLVM vectorises
    them), each written once and run over the rows it serves (the compile stays short)."""
    j = np.int64(cc[1])
    kk = 1.0 + _s_pow2(-np.int64(cc[2]))
    slack = (1.0 + _s_pow2(-INPUT_SLACK_EXP)) * kk
    eta = _eta(e)
    k2 = kk * kk
    for q in range(n):
        gs[_ZERO, q] = 0.0
    for x in range(12):                         # D, E1, E2, N: g's rows 3-5 and 9-17
        row = 3 + x + 3 * (x >= 3)
        for q in range(n):
            gs[_UIN + x, q] = _s_upper(g[row, q], e, m, j)
            gs[_BIN + x, q] = slack * _s_ulp(g[row, q], e, m, r, eta)
    for c in range(3):                          # T = V0 - O
        for q in range(n):
            gs[_UT + c, q] = _s_upper(w[6 + c, q], e, m, j)
            gs[_BT + c, q] = kk * (kk * _s_ulp(g[6 + c, q], e, m, r, eta) + _s_rnd(
                w[6 + c, q], _s_upper(g[6 + c, q], e, m, j) + _s_upper(g[c, q], e, m, j),
                e, m, r, kk, eta))
    for c in range(3):                          # Q = D x T (w's rows 9, 10, 12)
        c1 = (c + 1) % 3
        c2 = (c + 2) % 3
        wr = 9 + c + (c == 2)
        for q in range(n):
            gs[_BQ + c, q] = _s_cross(gs[_UIN + _D + c1, q], gs[_UT + c2, q], gs[_BT + c2, q],
                                      gs[_UIN + _D + c2, q], gs[_UT + c1, q], gs[_BT + c1, q],
                                      w[wr, q], e, m, r, kk, eta)
            gs[_UQ + c, q] = _s_upper(w[wr, q], e, m, j)
    for x in range(4):                          # det = N.D, t' = N.T, u' = -(E2.Q), v' = E1.Q
        a = _N if x < 2 else (_E2 if x == 2 else _E1)
        ub = (_UIN + _D, _UT, _UQ, _UQ)[x]
        bb = (_ZERO, _BT, _BQ, _BQ)[x]
        step = 0 if x == 0 else 1               # the zero row serves x, y and z
        wr = (3, 0, 1, 2)[x]
        for q in range(n):
            gs[x, q] = _s_dot(gs[_UIN + a, q], gs[_UIN + a + 1, q], gs[_UIN + a + 2, q],
                              gs[_BIN + a, q], gs[_BIN + a + 1, q], gs[_BIN + a + 2, q],
                              gs[ub, q], gs[ub + 1, q], gs[ub + 2, q], gs[bb, q],
                              gs[bb + step, q], gs[bb + 2 * step, q], w[wr, q], e, m, r, kk,
                              eta)
    for q in range(n):                          # s = u' + v', w = det - s
        gsum = k2 * (gs[2, q] + gs[3, q]) + kk * _s_rnd(
            w[4, q], _s_upper(w[1, q], e, m, j) + _s_upper(w[2, q], e, m, j), e, m, r, kk, eta)
        gs[4, q] = (k2 * (gs[0, q] + gsum) + kk * _s_rnd(
            w[5, q], _s_upper(w[3, q], e, m, j) + _s_upper(w[4, q], e, m, j), e, m, r, kk,
            eta)) * SCREEN_SLACK
    for x in range(4):
        for q in range(n):
            gs[x, q] *= SCREEN_SLACK


@njit(inline="always")
def _s_value(x, e, m):
    """:func:`_value`, branch-free."""
    x = np.int64(x)
    field = (x >> m) & ((np.int64(1) << e) - 1)
    bias = (np.int64(1) << (e - 1)) - 1
    v = _i2f(((field - bias + 1023) << 52) | ((x & ((np.int64(1) << m) - 1)) << (52 - m))
             | (((x >> (e + m)) & 1) << 63))
    return v if field != 0 else 0.0


#: The block path's outcome of a lane it leaves to :func:`pair_full` (one that left the fast
#: paths; a lane the screen leaves uncertain has outcome 2).
RECOMPUTE = 3


@njit(cache=True)
def voutcome(w, gs, oc, n, sc, e, m):
    """:func:`_outcome` of a block's lanes from their screen bounds into ``oc``, and
    :data:`RECOMPUTE` where ``w[11]`` marks a lane that left the fast paths. One vector
    loop."""
    for q in range(n):
        vd, vt, vu, vv, vw = (_s_value(w[3, q], e, m), _s_value(w[0, q], e, m),
                              _s_value(w[1, q], e, m), _s_value(w[2, q], e, m),
                              _s_value(w[5, q], e, m))
        gd, gt, gu, gv, gw = gs[0, q] * sc, gs[1, q] * sc, gs[2, q] * sc, gs[3, q] * sc, \
            gs[4, q] * sc
        hit = (((vd > gd) & (vu >= gu) & (vv >= gv) & (vw >= gw) & (vt >= gt))
               | ((vd < -gd) & (vu <= -gu) & (vv <= -gv) & (vw <= -gw) & (vt <= -gt)))
        miss = (((vd <= -gd) | (vu < -gu) | (vv < -gv) | (vw < -gw) | (vt < -gt))
                & ((vd >= gd) | (vu > gu) | (vv > gv) | (vw > gw) | (vt > gt)))
        out = np.int64(1) if hit else (np.int64(0) if miss else np.int64(2))
        oc[q] = out if w[11, q] >= 0 else np.int64(RECOMPUTE)


@njit(cache=True)
def _fdot(a0, a1, a2, b0, b1, b2, e, m, r):
    """``(a0*b0 + a1*b1) + a2*b2`` by the fast paths (the order of ``vpair``'s ``_vdot``);
    -1 when one of them needs the reference kernel."""
    p0 = fast_mul(a0, b0, e, m, r)
    p1 = fast_mul(a1, b1, e, m, r)
    p2 = fast_mul(a2, b2, e, m, r)
    if p0 < 0 or p1 < 0 or p2 < 0:
        return np.int64(-1)
    s = fast_add(p0, p1, e, m, r)
    if s < 0:
        return np.int64(-1)
    return fast_add(s, p2, e, m, r)


@njit(cache=True)
def _fcross(a, b, c, d, e, m, r):
    """``a*b - c*d`` by the fast paths (the order of ``vpair``'s ``_vcross``), or -1."""
    p = fast_mul(a, b, e, m, r)
    pq = fast_mul(c, d, e, m, r)
    if p < 0 or pq < 0:
        return np.int64(-1)
    return fast_add(p, pq ^ (np.int64(1) << (e + m)), e, m, r)


@njit(cache=True)
def _lane_fast(g, w, q, e, m, r):
    """Lane ``q``'s results (``w``'s rows as :func:`vpair` writes them) by the flag-free
    fast paths of :mod:`raplas_hdl.fp.fast`, which also take zero operands and exact zero
    sums; the reference's bits. False when an operation needs the reference kernel (an
    event flag, an infinite or NaN operand)."""
    sb = np.int64(1) << (e + m)
    for c in range(3):
        t = fast_add(g[6 + c, q], g[c, q] ^ sb, e, m, r)
        if t < 0:
            return False
        w[6 + c, q] = t
    det = _fdot(g[15, q], g[16, q], g[17, q], g[3, q], g[4, q], g[5, q], e, m, r)
    tp = _fdot(g[15, q], g[16, q], g[17, q], w[6, q], w[7, q], w[8, q], e, m, r)
    qx = _fcross(g[4, q], w[8, q], g[5, q], w[7, q], e, m, r)
    qy = _fcross(g[5, q], w[6, q], g[3, q], w[8, q], e, m, r)
    qz = _fcross(g[3, q], w[7, q], g[4, q], w[6, q], e, m, r)
    if det < 0 or tp < 0 or qx < 0 or qy < 0 or qz < 0:
        return False
    qe2 = _fdot(qx, qy, qz, g[12, q], g[13, q], g[14, q], e, m, r)
    vp = _fdot(qx, qy, qz, g[9, q], g[10, q], g[11, q], e, m, r)
    if qe2 < 0 or vp < 0:
        return False
    up = qe2 ^ sb
    s = fast_add(up, vp, e, m, r)
    if s < 0:
        return False
    ww = fast_add(det, s ^ sb, e, m, r)
    if ww < 0:
        return False
    w[0, q], w[1, q], w[2, q], w[3, q], w[4, q], w[5, q] = tp, up, vp, det, s, ww
    w[9, q], w[10, q], w[12, q] = qx, qy, qz
    w[11, q] = 0
    return True


@njit(nogil=True, cache=True)
def pairs_one(o, d, v0, e1, e2, nn, cc, lane_o, lane_d, lane_t, lo, hi, outc, t_o, u_o, v_o,
              det_o, cnt_o, e, m, r):
    """:func:`block_pairs` one pair at a time (:func:`pair_full`): the reference of the
    block path."""
    for i in range(lo, hi):
        oc, tp, up, vp, det, cnt = pair_full(o, lane_o[i], d, lane_d[i], v0, e1, e2, nn,
                                             lane_t[i], e, m, r, cc)
        outc[i] = oc
        store(i, tp, up, vp, det, cnt, t_o, u_o, v_o, det_o, cnt_o)


@njit(nogil=True, cache=True)
def block_screened(o, d, v0, e1, e2, nn, cc, lane_o, lane_d, lane_t, lo, hi, outc, t_o, u_o,
                   v_o, det_o, cnt_o, e, m, r):
    """:func:`block_pairs` but for the lanes it leaves to :func:`pair_full` (the screen's
    uncertain ones and those that left the fast paths): their outcome is :data:`RECOMPUTE`
    (their other outputs unset). Returns how many there are.

    Per block: the operands gathered (:func:`~raplas_hdl.model.pair_kernels.gather`), the
    values by
    :func:`~raplas_hdl.model.pair_kernels.vpair` (lanes with zero operands again by
    :func:`_lane_fast`), the screen bounds by :func:`vscreen` and each lane's outcome from
    them (:func:`voutcome`). ``pair_full`` is not called from here: compiled into this
    kernel, LLVM would optimise its code a second time (seconds of a cold start)."""
    g = np.empty((18, BLOCK), np.int64)
    w = np.empty((13, BLOCK), np.int64)
    gs = np.empty((N_SCREEN_ROWS, BLOCK), np.float64)
    oc = np.empty(BLOCK, np.int64)
    sc = cc[0]
    left = 0
    for start in range(lo, hi, BLOCK):
        n = min(BLOCK, hi - start)
        for q in range(n):
            i = start + q
            gather(g, q, o, lane_o[i], d, lane_d[i], v0, e1, e2, nn, lane_t[i])
        vpair(g, w, n, True, e, m, r)
        for q in range(n):
            if w[11, q] < 0:
                _lane_fast(g, w, q, e, m, r)
        vscreen(g, w, gs, n, e, m, r, cc)
        voutcome(w, gs, oc, n, sc, e, m)
        for q in range(n):
            i = start + q
            if oc[q] < 2:
                outc[i] = oc[q]
                store(i, np.uint32(w[0, q]), np.uint32(w[1, q]), np.uint32(w[2, q]),
                      np.uint32(w[3, q]), 0, t_o, u_o, v_o, det_o, cnt_o)
            else:
                outc[i] = RECOMPUTE
                left += 1
    return left


@njit(nogil=True, cache=True)
def pairs_listed(o, d, v0, e1, e2, nn, cc, lane_o, lane_d, lane_t, rows, outc, t_o, u_o, v_o,
                 det_o, cnt_o, e, m, r):
    """:func:`pair_full` for the pairs ``rows`` of the lane lists (the outputs' rows)."""
    for i in rows:
        oc, tp, up, vp, det, cnt = pair_full(o, lane_o[i], d, lane_d[i], v0, e1, e2, nn,
                                             lane_t[i], e, m, r, cc)
        outc[i] = oc
        store(i, tp, up, vp, det, cnt, t_o, u_o, v_o, det_o, cnt_o)


def exact_pairs(o, d, v0, e1, e2, nn, cc, lane_o, lane_d, lane_t, lo, hi, outc, t_o, u_o, v_o,
                det_o, cnt_o, e, m, r):
    """:func:`block_pairs` with every pair through :func:`pair_full` (:func:`pairs_listed`):
    the same results, without the block kernel (the warm-up's pass while another process
    compiles it, :mod:`raplas_hdl.engine.compile_ahead`)."""
    pairs_listed(o, d, v0, e1, e2, nn, cc, lane_o, lane_d, lane_t, np.arange(lo, hi), outc,
                 t_o, u_o, v_o, det_o, cnt_o, e, m, r)


def block_pairs(o, d, v0, e1, e2, nn, cc, lane_o, lane_d, lane_t, lo, hi, outc, t_o, u_o, v_o,
                det_o, cnt_o, e, m, r):
    """Pairs ``lo .. hi-1`` of the lane lists (pair ``i``: ``o`` row ``lane_o[i]``, ``d``
    row ``lane_d[i]``, triangle row ``lane_t[i]``) a block at a time; row ``i`` of the
    outputs as :func:`intersect_certified`, the same bits as :func:`pair_full`.

    :func:`block_screened` decides almost every lane from the screen bounds (the section
    comment above); the lanes it leaves (uncertain to the screen, or with an event or a
    special value) then go through :func:`pair_full` (:func:`pairs_listed`).
    :func:`intersect_certified` and the renderer's certified pass both run it."""
    left = block_screened(o, d, v0, e1, e2, nn, cc, lane_o, lane_d, lane_t, lo, hi, outc, t_o,
                          u_o, v_o, det_o, cnt_o, e, m, r)
    if left:
        rows = np.flatnonzero(outc[lo:hi] == RECOMPUTE) + lo
        pairs_listed(o, d, v0, e1, e2, nn, cc, lane_o, lane_d, lane_t, rows, outc, t_o, u_o,
                     v_o, det_o, cnt_o, e, m, r)


def intersect_certified(arrs, fmt: FPFormat, scale: float = 1.0,
                        variant: str = DEFAULT_VARIANT, block: bool = True) -> dict:
    """The certified mode over validated pair arrays ``(o, d, v0, e1, e2, n)`` (uint32,
    shape (n, 3) each); :func:`raplas_hdl.model.ray_triangle.intersect` is the public
    entry. ``block``: a block at a time (:func:`block_pairs`), else one pair at a time
    (:func:`pairs_one`); the results are the same bits. Returns ``outcome`` (uint8), ``t``,
    ``u``, ``v``, ``det`` (uint32) and ``event_counts`` (uint8, (n, 3))."""
    cc = certified_constants(fmt, scale, variant)
    count = arrs[0].shape[0]
    outc = np.empty(count, dtype=np.uint8)
    outs = [np.empty(count, dtype=np.uint32) for _ in range(4)]
    counts = np.empty((count, 3), dtype=np.uint8)
    key = (np.int64(fmt.exp_bits), np.int64(fmt.man_bits), np.int64(rmode_code(fmt)))
    lane = np.arange(count, dtype=np.int64)
    kernel = block_pairs if block else pairs_one
    run_chunks(count, lambda lo, hi: kernel(*arrs, cc, lane, lane, lane, lo, hi, outc, *outs,
                                            counts, *key))
    return {"outcome": outc, "t": outs[0], "u": outs[1], "v": outs[2], "det": outs[3],
            "event_counts": counts}


assert FLAG_OVERFLOW == 1        # the outcome reads overflow counts from bits 0-7
