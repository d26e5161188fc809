"""A float64 filter for the exact reference R: decides most pairs with certainty, says when
it cannot.

R (:mod:`raplas_hdl.host.exact`) is the division-free Moller-Trumbore test in exact
arithmetic on the original float64 vertices ``V0, V1, V2`` and the encoded ray ``O, D``.
Exact integer arithmetic costs about 10 us a pair; this filter evaluates the same formulas
in float64 beside a *running absolute value* (the same expression with every subtraction
made an addition of magnitudes, every operand its magnitude) and decides an inequality
only when the computed value is further from zero than its certified error:

- every float64 operation has a relative error of at most ``u = 2**-53`` (round to
  nearest; no overflow in the domain, underflow covered by an absolute term ``2**-1000``);
- the longest chain of operations from an input to a decided quantity is 8 (``w = det -
  (u' + v')``: the vertex difference, a product, the cross-product difference, a product,
  two adds of the dot product, ``u' + v'``, the final subtraction); along it each monomial
  of the expanded polynomial carries at most 8 factors ``(1 + delta)``, so
  ``|computed - exact| <= gamma_8 * A`` with ``A`` the exact absolute value and
  ``gamma_k = k u / (1 - k u)``;
- ``A`` is itself computed in float64 from non-negative terms, so ``A <= A_hat (1 +
  gamma_8)``; the filter's bound ``16 u A_hat + 2**-1000`` covers ``gamma_8 A`` with room.

An inequality whose computed value lies within its bound of zero (an exact zero, a ray
through an edge or a vertex, included) is *undecided*: the caller resolves the pair in
exact arithmetic. For a decided hit the filter also returns an interval that contains the
exact ``t = t'/det``.
"""

from __future__ import annotations

from numba import njit

from ..fp.numba_cache import drop_stale_cache

drop_stale_cache(__file__)

__all__ = ["filter_pair", "MISS", "HIT", "UNDECIDED", "F64_FILTER_K"]

MISS, HIT, UNDECIDED = 0, 1, 2
#: The bound's multiple of u = 2**-53 (twice gamma_8; module docstring).
F64_FILTER_K = 16.0
_U = 2.0 ** -53
_TINY = 2.0 ** -1000


@njit(cache=True)
def _dot_abs(a0, a1, a2, b0, b1, b2, aa0, aa1, aa2, ab0, ab1, ab2):
    """``a.b`` and its absolute track."""
    return a0 * b0 + a1 * b1 + a2 * b2, aa0 * ab0 + aa1 * ab1 + aa2 * ab2


@njit(cache=True)
def _cross_abs(a0, a1, a2, b0, b1, b2, aa0, aa1, aa2, ab0, ab1, ab2):
    """``a x b`` and its absolute track."""
    return (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0,
            aa1 * ab2 + aa2 * ab1, aa2 * ab0 + aa0 * ab2, aa0 * ab1 + aa1 * ab0)


@njit(cache=True)
def _sign(x, bound):
    """1 or -1 when ``x`` is certainly positive or negative, 0 when undecided."""
    if x > bound:
        return 1
    if x < -bound:
        return -1
    return 0


@njit(cache=True)
def filter_pair(ox, oy, oz, dx, dy, dz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """R for one pair, filtered: ``(status, t_lo, t_hi)``.

    The ray is ``O + t D``; the triangle's original vertices are ``A = V0, B = V1, C =
    V2`` (float64, finite). ``status`` is :data:`HIT` (R hits; ``t_lo <= t'/det <= t_hi``),
    :data:`MISS` (R misses) or :data:`UNDECIDED` (resolve exactly).
    """
    k = F64_FILTER_K * _U
    # vertex differences and T = V0 - O, with magnitudes
    e1x, e1y, e1z = bx - ax, by - ay, bz - az
    e2x, e2y, e2z = cx - ax, cy - ay, cz - az
    tx, ty, tz = ax - ox, ay - oy, az - oz
    ae1x, ae1y, ae1z = abs(bx) + abs(ax), abs(by) + abs(ay), abs(bz) + abs(az)
    ae2x, ae2y, ae2z = abs(cx) + abs(ax), abs(cy) + abs(ay), abs(cz) + abs(az)
    atx, aty, atz = abs(ax) + abs(ox), abs(ay) + abs(oy), abs(az) + abs(oz)
    adx, ady, adz = abs(dx), abs(dy), abs(dz)
    # N = E1 x E2
    nx, ny, nz, anx, any_, anz = _cross_abs(e1x, e1y, e1z, e2x, e2y, e2z, ae1x, ae1y, ae1z,
                                            ae2x, ae2y, ae2z)
    det, adet = _dot_abs(nx, ny, nz, dx, dy, dz, anx, any_, anz, adx, ady, adz)
    bdet = k * adet + _TINY
    sd = _sign(det, bdet)
    if sd == 0:
        return UNDECIDED, 0.0, 0.0
    # Q = D x T
    qx, qy, qz, aqx, aqy, aqz = _cross_abs(dx, dy, dz, tx, ty, tz, adx, ady, adz, atx, aty,
                                           atz)
    qe2, aup = _dot_abs(qx, qy, qz, e2x, e2y, e2z, aqx, aqy, aqz, ae2x, ae2y, ae2z)
    up = -qe2
    vp, avp = _dot_abs(qx, qy, qz, e1x, e1y, e1z, aqx, aqy, aqz, ae1x, ae1y, ae1z)
    su = _sign(up * sd, k * aup + _TINY)
    sv = _sign(vp * sd, k * avp + _TINY)
    if su < 0 or sv < 0:
        return MISS, 0.0, 0.0
    w = det - (up + vp)
    sw = _sign(w * sd, k * (adet + aup + avp) + _TINY)
    if sw < 0:
        return MISS, 0.0, 0.0
    tp, atp = _dot_abs(nx, ny, nz, tx, ty, tz, anx, any_, anz, atx, aty, atz)
    btp = k * atp + _TINY
    st = _sign(tp * sd, btp)
    if st < 0:
        return MISS, 0.0, 0.0
    if su == 0 or sv == 0 or sw == 0 or st == 0:
        return UNDECIDED, 0.0, 0.0
    # t = t'/det with |t' - t'_exact| <= btp and |det - det_exact| <= bdet, same signs
    lo = (abs(tp) - btp) / (abs(det) + bdet) * (1.0 - 8.0 * _U)
    hi = (abs(tp) + btp) / (abs(det) - bdet) * (1.0 + 8.0 * _U)
    return HIT, lo, hi
