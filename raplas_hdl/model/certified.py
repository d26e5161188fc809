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
the values, vector loops for the bounds of the lanes in the common case, :func:`pair_full`
for the other lanes), the same bits as one pair at a time (:func:`pairs_one`).
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from ..fp.fast import common_add, common_mul
from ..fp.format import FLAG_OVERFLOW, FPFormat, check_format
from ..fp.kernels import neg_k, rmode_code
from ..fp.numba_cache import drop_stale_cache
from ..parallel import run_chunks
from .pair_kernels import BLOCK, add_op, mul_op, store, sub_op, tally, vpair

__all__ = ["VARIANTS", "DEFAULT_VARIANT", "N_OPS", "MAX_EXP_BITS", "certified_constants",
           "certified_domain", "check_certified_format", "pair_certified", "intersect_certified",
           "block_pairs", "pairs_one", "vbounds", "N_BOUND_ROWS"]

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
def pair_full(o, oi, d, di, v0, e1, e2, nn, ti, e, m, r, cc):
    """:func:`pair_certified` with every result: ``(outcome, t', u', v', det, counts)``."""
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
# operations as vector loops of the common case, BLOCK lanes); their bounds from the loops
# below, one per stage of :func:`pair_full`, over every lane. In a lane whose operations all
# took the common case every operand and result is a normal number and no flag is raised, so
# no zero test of the bound terms applies (:func:`_rnd_add_nz`, :func:`_ulp`), the counts are
# 0 and no result is special: the lane's bounds are :func:`pair_full`'s, bit for bit. The
# products and partial sums of the dot products, which vpair does not keep, are recomputed
# with the same common-case kernels. Every other lane is recomputed alone by
# :func:`pair_full`. Rows of the bound block ``gb`` (float64, (N_BOUND_ROWS, BLOCK)):
_BV, _B1, _B2, _BN = 0, 3, 6, 9        # input bounds of V0, E1, E2, N (x, y, z)
_GT = 12                               # T = V0 - O (x, y, z)
_GDET, _GTP = 15, 16
_GQ = 17                               # Q = D x T (x, y, z)
_GU, _GV, _GS, _GW, _ZERO = 20, 21, 22, 23, 24
N_BOUND_ROWS = 25


# Branch-free forms of the bound operations for those lanes (LLVM vectorises their loops):
# every bound there is finite (below 2**800 for exp_bits <= 9) and non-negative, and every
# pattern normal, so the tests of :func:`_ru`, :func:`_badd` and :func:`_upper` for zero,
# infinite and NaN values never apply; the results are the same floats.
@njit(cache=True)
def _ru_nz(x, k):
    """:func:`_ru` of a finite ``x >= 0``."""
    mask = (np.int64(1) << (52 - k)) - 1
    return _i2f((_f2i(x) + mask) & ~mask)


@njit(cache=True)
def _badd_nz(a, b, k):
    """:func:`_badd` of finite bound floats with a finite sum."""
    s = a + b
    bb = s - a
    err = (a - (s - bb)) + (b - bb)
    r = _ru_nz(s, k)
    bump = np.int64((err > 0.0) & (r == s))
    return _i2f(_f2i(r) + (bump << (52 - k)))


@njit(cache=True)
def _upper_nz(x, e, m, j):
    """:func:`_upper` of a pattern that is not zero, built as float64 bits: exponent ``ex``,
    fraction the ``j`` leading bits plus one unit of the ``j``-th (a carry adds into the
    exponent)."""
    x = np.int64(x)
    field = (x >> m) & ((np.int64(1) << e) - 1)
    bias = (np.int64(1) << (e - 1)) - 1
    lead = (x & ((np.int64(1) << m) - 1)) >> (m - j)
    return _i2f((((field - bias + 1023) << 52) | (lead << (52 - j))) + (np.int64(1) << (52 - j)))


@njit(cache=True)
def _mul_nz(a, ba, b, bb, p, e, m, r, j, k):
    """:func:`_mul_b` of normal patterns (:func:`_mul_bound`)."""
    t1 = _ru_nz(_upper_nz(a, e, m, j) * bb, k)
    t2 = _ru_nz(_badd_nz(_upper_nz(b, e, m, j), bb, k) * ba, k)
    return _badd_nz(_badd_nz(t1, t2, k), _ulp(p, e, m, r), k)


@njit(cache=True)
def _add_nz(a, ba, b, bb, s, e, m, r, k):
    """:func:`_add_b` of normal patterns."""
    return _badd_nz(_badd_nz(ba, bb, k), _rnd_add_nz(a, b, s, e, m, r), k)


@njit(cache=True)
def _vinput(x, out, slack, n, e, m, r, k):
    for q in range(n):
        b = _ulp(x[q], e, m, r)
        out[q] = _ru_nz(b + b * _pow2(-INPUT_SLACK_EXP), k) if slack else b


@njit(cache=True)
def _vsub_b(a, ba, b, s, out, n, e, m, r, k):
    """Bound of ``s = sub(a, b)``, ``b`` exact."""
    for q in range(n):
        out[q] = _add_nz(a[q], ba[q], b[q], 0.0, s[q], e, m, r, k)


@njit(cache=True)
def _vdot_b(a0, a1, a2, ba0, ba1, ba2, b0, b1, b2, bb0, bb1, bb2, s, out, n, e, m, r, j, k):
    """Bound of ``s = (a0*b0 + a1*b1) + a2*b2`` (:func:`_dot_b`)."""
    for q in range(n):
        p0 = common_mul(a0[q], b0[q], e, m, r)
        p1 = common_mul(a1[q], b1[q], e, m, r)
        p2 = common_mul(a2[q], b2[q], e, m, r)
        s01 = common_add(p0, p1, e, m, r)
        q0 = _mul_nz(a0[q], ba0[q], b0[q], bb0[q], p0, e, m, r, j, k)
        q1 = _mul_nz(a1[q], ba1[q], b1[q], bb1[q], p1, e, m, r, j, k)
        q2 = _mul_nz(a2[q], ba2[q], b2[q], bb2[q], p2, e, m, r, j, k)
        g01 = _add_nz(p0, q0, p1, q1, s01, e, m, r, k)
        out[q] = _add_nz(s01, g01, p2, q2, s[q], e, m, r, k)


@njit(cache=True)
def _vcross_b(a, b, bb, c, d, bd, x, out, n, e, m, r, j, k):
    """Bound of ``x = a*b - c*d``, ``a, c`` exact (:func:`_cross_b`)."""
    for q in range(n):
        p = common_mul(a[q], b[q], e, m, r)
        pq = common_mul(c[q], d[q], e, m, r)
        gp = _mul_nz(b[q], bb[q], a[q], 0.0, p, e, m, r, j, k)
        gq = _mul_nz(d[q], bd[q], c[q], 0.0, pq, e, m, r, j, k)
        out[q] = _add_nz(p, gp, pq, gq, x[q], e, m, r, k)


@njit(cache=True)
def vbounds(g, w, gb, n, e, m, r, cc):
    """The bounds of a block after :func:`~raplas_hdl.model.pair_kernels.vpair` (``g``
    the operands, ``w`` its results, conservative layout), into ``gb``; exact for the lanes
    whose ``w[11]`` is not negative."""
    j = np.int64(cc[1])
    k = np.int64(cc[2])
    for c in range(3):
        _vinput(g[6 + c], gb[_BV + c], False, n, e, m, r, k)
        _vinput(g[9 + c], gb[_B1 + c], True, n, e, m, r, k)
        _vinput(g[12 + c], gb[_B2 + c], True, n, e, m, r, k)
        _vinput(g[15 + c], gb[_BN + c], True, n, e, m, r, k)
        _vsub_b(g[6 + c], gb[_BV + c], g[c], w[6 + c], gb[_GT + c], n, e, m, r, k)
    z = gb[_ZERO]
    z[:] = 0.0
    bn = gb[_BN], gb[_BN + 1], gb[_BN + 2]
    _vdot_b(g[15], g[16], g[17], *bn, g[3], g[4], g[5], z, z, z, w[3], gb[_GDET], n,
            e, m, r, j, k)
    _vdot_b(g[15], g[16], g[17], *bn, w[6], w[7], w[8], gb[_GT], gb[_GT + 1], gb[_GT + 2],
            w[0], gb[_GTP], n, e, m, r, j, k)
    tx, ty, tz = w[6], w[7], w[8]
    gtx, gty, gtz = gb[_GT], gb[_GT + 1], gb[_GT + 2]
    _vcross_b(g[4], tz, gtz, g[5], ty, gty, w[9], gb[_GQ], n, e, m, r, j, k)
    _vcross_b(g[5], tx, gtx, g[3], tz, gtz, w[10], gb[_GQ + 1], n, e, m, r, j, k)
    _vcross_b(g[3], ty, gty, g[4], tx, gtx, w[12], gb[_GQ + 2], n, e, m, r, j, k)
    gq = gb[_GQ], gb[_GQ + 1], gb[_GQ + 2]
    _vdot_b(g[12], g[13], g[14], gb[_B2], gb[_B2 + 1], gb[_B2 + 2], w[9], w[10], w[12], *gq,
            w[1], gb[_GU], n, e, m, r, j, k)
    _vdot_b(g[9], g[10], g[11], gb[_B1], gb[_B1 + 1], gb[_B1 + 2], w[9], w[10], w[12], *gq,
            w[2], gb[_GV], n, e, m, r, j, k)
    gu, gv, gs, gw = gb[_GU], gb[_GV], gb[_GS], gb[_GW]
    for q in range(n):
        gs[q] = _add_nz(w[1, q], gu[q], w[2, q], gv[q], w[4, q], e, m, r, k)
        gw[q] = _add_nz(w[3, q], gb[_GDET, q], w[4, q], gs[q], w[5, q], e, m, r, k)


@njit(cache=True)
def gather(g, q, o, oi, d, di, v0, e1, e2, nn, ti):
    """Lane ``q`` of a block's operands ``g`` (18, BLOCK): ray row ``oi`` of ``o``, ``di``
    of ``d``, triangle row ``ti`` (the layout of
    :func:`~raplas_hdl.model.pair_kernels.vpair`)."""
    g[0:3, q] = o[oi]
    g[3:6, q] = d[di]
    g[6:9, q] = v0[ti]
    g[9:12, q] = e1[ti]
    g[12:15, q] = e2[ti]
    g[15:18, q] = nn[ti]


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
def block_pairs(o, d, v0, e1, e2, nn, cc, lane_o, lane_d, lane_t, lo, hi, outc, t_o, u_o, v_o,
                det_o, cnt_o, e, m, r):
    """Pairs ``lo .. hi-1`` of the lane lists (pair ``i``: ``o`` row ``lane_o[i]``, ``d``
    row ``lane_d[i]``, triangle row ``lane_t[i]``) a block at a time; row ``i`` of the
    outputs as :func:`intersect_certified`, the same bits as :func:`pair_full`.

    Per block: the operands gathered (:func:`gather`), the values by
    :func:`~raplas_hdl.model.pair_kernels.vpair`, the bounds by :func:`vbounds`, the
    outcome of each common-case lane; the other lanes (and every lane of a block with fewer
    than a quarter of its lanes in the common case, where the bounds are skipped) by
    :func:`pair_full`. The one compiled kernel of the block path (each level of compiled
    callers would optimise the vector loops again): :func:`intersect_certified` and the
    renderer's certified pass both run it."""
    g = np.empty((18, BLOCK), np.int64)
    w = np.empty((13, BLOCK), np.int64)
    gb = np.empty((N_BOUND_ROWS, BLOCK), np.float64)
    sc = cc[0]
    for start in range(lo, hi, BLOCK):
        n = min(BLOCK, hi - start)
        for q in range(n):
            i = start + q
            gather(g, q, o, lane_o[i], d, lane_d[i], v0, e1, e2, nn, lane_t[i])
        vpair(g, w, n, True, e, m, r)
        common = 0
        for q in range(n):
            common += w[11, q] >= 0
        vector = 4 * common >= n
        if vector:
            vbounds(g, w, gb, n, e, m, r, cc)
        for q in range(n):
            i = start + q
            if vector and w[11, q] >= 0:
                oc = _outcome(w[3, q], w[0, q], w[1, q], w[2, q], w[5, q], gb[_GDET, q],
                              gb[_GTP, q], gb[_GU, q], gb[_GV, q], gb[_GW, q], sc, e, m)
                outc[i] = oc
                store(i, np.uint32(w[0, q]), np.uint32(w[1, q]), np.uint32(w[2, q]),
                      np.uint32(w[3, q]), 0, t_o, u_o, v_o, det_o, cnt_o)
            else:
                oc, tp, up, vp, det, cnt = pair_full(o, lane_o[i], d, lane_d[i], v0, e1, e2,
                                                     nn, lane_t[i], e, m, r, cc)
                outc[i] = oc
                store(i, tp, up, vp, det, cnt, t_o, u_o, v_o, det_o, cnt_o)


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
