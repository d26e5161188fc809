"""Ordering certain hits exactly: the certified unit's ``tight`` bit and the reducer's *near* test.

A certified *hit* (``outcome`` 1, :mod:`raplas_hdl.model.certified`) bounds the signs of
``t'``, ``det``, ``u'``, ``v'`` and ``w``, not the error of ``t = t'/det``: ``t'`` may exceed
its bound ``B_t'`` by a hair, and then the unit's ``t'/det`` says little about R's. Two
certain hits of one ray could then be folded by the on-chip reduction in the wrong order, or
a certain hit near ``tmin`` or ``tmax`` windowed unlike R, and the hit R chooses would never
leave the unit. Two pieces close that:

- **tight** (a bit of ``RT_RESULT_CERTIFIED`` and ``RESULT_CERTIFIED``): the pair is a certain
  hit whose ``t'`` and ``det`` are each within a relative ``delta = 2**-q`` of R's,
  ``q = tight_bits(fmt)``: ``|t'| >= 2**q g_t'`` and ``|det| >= 2**q g_det`` (``g`` the bound
  the outcome compares with; the comparison is ``_classify``'s, against the bound with ``q``
  added to its exponent). Then R's ``t`` lies within a factor ``(1 + delta) / (1 - delta)``
  of the unit's ``t'/det``. The reducer folds only tight hits; a certain hit that is not
  tight leaves the unit as an uncertain pair, for the host to decide.
- **near** (:func:`near`): the reducer compares ratios by exact products with keys
  (:func:`product_key`, the RTL's ``key_of``): a sign and a magnitude ``mag`` that is the
  exponent sum above the normalised significand product. Two keys are *near* when their signs
  agree and ``mag >> S`` differ by at most 1, ``S = near_shift(fmt)``. Two keys that are not
  near differ in ``mag`` by more than ``2**S``, so their values differ by a factor above
  ``1 + 2**(S - 2M - 2)`` (``M`` fraction bits: along the key, ``log(value)`` grows by at
  least ``2**-(2M+2)`` per unit), which ``near_shift`` makes at least
  ``((1 + delta) / (1 - delta))**2``: the order of two tight hits' R ``t`` is then the order
  of the unit's ratios, and a tight hit's R ``t`` is on the same side of a window bound as
  the unit's ratio (the window bound is exact; the host's float64 window differs from the
  unit's patterns by less than one ulp, ``2**-M`` relative, well inside the near zone).

The reducer (:mod:`raplas_hdl.model.reduction`, ``rtl/unit/reducer.py``) passes a candidate
on to the host as an uncertain pair, instead of folding or dropping it, when it is near
``tmin`` or ``tmax`` or near the ray's current answer. So every certain hit either leaves the
unit or was dropped behind an answer certainly nearer in R (or certainly outside the window),
and the host, resolving what leaves exactly, finds R's nearest hit.

No Amaranth.
"""

from __future__ import annotations

from fractions import Fraction
from functools import lru_cache

import numpy as np
from numba import njit

from ..fp.format import FPFormat
from ..fp.kernels import rmode_code
from .certified import _classify, certified_constants, pair_bounds

__all__ = ["TIGHT_SLACK", "tight_bits", "near_shift", "tight_flags", "product_key", "near",
           "key_int", "near_int", "key_lt"]

#: ``tight_bits(fmt) = man_bits - TIGHT_SLACK`` (at least 2): a tight hit's ``t'`` and ``det``
#: are within ``2**TIGHT_SLACK`` ulps of R's, relative to their own magnitude.
TIGHT_SLACK = 6


def tight_bits(fmt: FPFormat) -> int:
    """``q``: a tight hit's ``t'`` and ``det`` are within a relative ``2**-q`` of R's."""
    return max(2, fmt.man_bits - TIGHT_SLACK)


@lru_cache(maxsize=None)
def near_shift(fmt: FPFormat) -> int:
    """``S``, the smallest shift with ``1 + 2**(S - 2M - 2) >= ((1 + d) / (1 - d))**2``,
    ``d = 2**-tight_bits(fmt)`` (exact rationals): keys whose magnitudes ``>> S`` differ by
    two or more order the ratios of two tight hits as R orders their ``t``."""
    m = fmt.man_bits
    d = Fraction(1, 2 ** tight_bits(fmt))
    need = ((1 + d) / (1 - d)) ** 2 - 1
    s = 0
    while Fraction(2) ** (s - 2 * m - 2) < need:
        s += 1
    return s


@njit(cache=True)
def _tight_lanes(o, d, v0, e1, e2, nn, idx, e, m, r, cc, q, out):
    sc = cc[0] * 2.0 ** q
    for i in idx:
        tp, up, vp, det, w, gdet, gt, gu, gv, gw, cnt = pair_bounds(o, i, d, i, v0, e1, e2,
                                                                    nn, i, e, m, r, cc)
        t_ge, t_gt, t_le, t_lt = _classify(tp, gt * sc, e, m)
        d_ge, d_gt, d_le, d_lt = _classify(det, gdet * sc, e, m)
        out[i] = (t_ge or t_le) and (d_ge or d_le)


def tight_flags(arrs, outcome, fmt: FPFormat, scale: float = 1.0,
                variant: str = "exp") -> np.ndarray:
    """The ``tight`` bit of every pair (bool): its certain hits (``outcome`` 1) whose
    ``t'`` and ``det`` pass the test above, from the unit's own bounds (:func:`pair_bounds`;
    ``arrs`` the pair arrays ``(o, d, v0, e1, e2, n)``, patterns of shape (n, 3); ``scale``
    and ``variant`` those of the outcome, :func:`~raplas_hdl.model.certified.certified_constants`;
    ``exp`` is the RTL's)."""
    out = np.zeros(np.asarray(outcome).size, np.bool_)
    idx = np.flatnonzero(np.asarray(outcome) == 1).astype(np.int64)
    if idx.size:
        arrs = [np.ascontiguousarray(a, np.uint32) for a in arrs]
        _tight_lanes(*arrs, idx, np.int64(fmt.exp_bits), np.int64(fmt.man_bits),
                     np.int64(rmode_code(fmt)), certified_constants(fmt, scale, variant),
                     np.float64(tight_bits(fmt)), out)
    return out


def product_key(fmt: FPFormat, x, y, sign):
    """``(s, mag)`` of ``(-1)**sign * |x| * |y|`` for patterns ``x``, ``y`` (arrays), as the
    RTL's ``key_of`` forms it: ``mag`` the exponent-field sum (plus the product's carry)
    above the significand product without its leading one (``2M + 1`` bits), 0 when either
    is zero (exponent field 0), and ``s`` 0 for a zero. ``mag`` orders as ``|x| * |y|``."""
    mb, eb = fmt.man_bits, fmt.exp_bits
    x = np.asarray(x, np.int64)
    y = np.asarray(y, np.int64)
    ex, ey = (x >> mb) & ((1 << eb) - 1), (y >> mb) & ((1 << eb) - 1)
    one = np.int64(1) << mb
    p = ((x & (one - 1)) | one) * ((y & (one - 1)) | one)        # 2M + 2 bits, exact
    top = (p >> (2 * mb + 1)) & 1
    low = np.int64(1) << (2 * mb + 1)
    sig = np.where(top == 1, p & (low - 1), (p << 1) & (low - 1))
    zero = (ex == 0) | (ey == 0)
    mag = np.where(zero, 0, ((ex + ey + top) << (2 * mb + 1)) | sig)
    s = np.where(zero, 0, np.asarray(sign, np.int64) & 1)
    return s, mag


def near(fmt: FPFormat, a, b):
    """Whether keys ``a`` and ``b`` (:func:`product_key`) are near: equal signs, and
    ``mag >> near_shift(fmt)`` differing by at most 1 (bool array)."""
    (sa, ma), (sb, mb) = a, b
    s = near_shift(fmt)
    ha, hb = np.asarray(ma) >> s, np.asarray(mb) >> s
    return (np.asarray(sa) == np.asarray(sb)) & (np.abs(ha - hb) <= 1)


def key_int(fmt: FPFormat, x: int, y: int, sign: int) -> tuple:
    """:func:`product_key` of one pair of patterns, in Python integers (the fold's loop)."""
    mb, eb = fmt.man_bits, fmt.exp_bits
    ex, ey = (x >> mb) & ((1 << eb) - 1), (y >> mb) & ((1 << eb) - 1)
    if ex == 0 or ey == 0:
        return 0, 0
    one = 1 << mb
    p = ((x & (one - 1)) | one) * ((y & (one - 1)) | one)
    top = (p >> (2 * mb + 1)) & 1
    low = (1 << (2 * mb + 1)) - 1
    sig = p & low if top else (p << 1) & low
    return sign & 1, ((ex + ey + top) << (2 * mb + 1)) | sig


def near_int(fmt: FPFormat, a: tuple, b: tuple) -> bool:
    """:func:`near` of two :func:`key_int` keys."""
    s = near_shift(fmt)
    return a[0] == b[0] and abs((a[1] >> s) - (b[1] >> s)) <= 1


def key_lt(a: tuple, b: tuple) -> bool:
    """``a < b`` for two :func:`key_int` keys (the order of the products' values)."""
    (sa, ma), (sb, mb) = a, b
    return bool((sa and not sb) or (not sa and not sb and ma < mb) or (sa and sb and mb < ma))
