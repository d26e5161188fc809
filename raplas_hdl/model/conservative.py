"""The closed-form margin of the ray-triangle unit's conservative mode, and its domain.

The conservative mode widens every test of the hit decision by a margin that bounds the
difference between what the unit computes and what the exact reference **R** computes
(:mod:`raplas_hdl.host.exact`: exact arithmetic on the host's float64 vertices and the
encoded ray). If every computed quantity lies within its margin of R's value, a pair that R
hits passes the widened tests: no false miss, hence no leak through a shared edge (a leak
is a ray that R hits on at least one side). The derivation is repeated, with the numbers,
in ``docs/conservative-mode.md``.

Notation
--------
``eps = 2**-M`` bounds the relative error of one operation in all three roundings (``rtz``
and ``rne`` by the contract; ``chop`` adds ``a + b`` with an error below one ulp of the
larger operand, so ``|err| <= eps * (|a| + |b|)``, which is the form used below for every
add). ``eta = 2**emin`` bounds the absolute error of a flush to zero.

For each input vector ``X`` of the pair (``O``, ``D``, ``V0``, ``E1``, ``E2``, ``N``) the
unit takes ``fX``, the largest biased exponent field of its three components, and
``L_X = fX - bias + 1``, so that ``|X_i| < 2**L_X`` for every component (a zero or a
denormal pattern has field 0 and ``2**emin`` is still an upper bound). Write
``o, d, v, e1, e2, n = 2**L_O, ...``, ``vo = 2**max(L_V0, L_O)`` and
``e12 = 2**max(L_E1, L_E2)``. R's values differ from the encoded ones by at most ``eps``
relative per component (``E1 = V1 - V0``, ``E2``, ``N = E1 x E2`` are formed exactly on the
host, then rounded once to float64 and once to the format; ``O`` and ``D`` *are* the
encoded ray, exact in R).

Error of each quantity against R (first order in ``eps``; every dot product
``(a0*b0 + a1*b1) + a2*b2`` contributes ``3 eps sum|a_i b_i|``: ``eps`` from the products,
``eps`` from each add over at most the whole sum):

=========  ==============================================================  ==============
quantity   bound on ``|unit - R|``                                         closed form
=========  ==============================================================  ==============
T = V0-O   ``eps v`` (V0 encoded) ``+ eps (v + o)`` (the sub)               ``3 eps vo``
det = N.D  ``3 eps n d`` (N encoded) ``+ 3 eps * 3 n d`` (dot)              ``12 eps n d``
t' = N.T   ``3 eps n 2vo + 3 n 3eps vo + 3 eps 3 n 2vo``                   ``33 eps n vo``
Q = D x T  ``2 d 3eps vo`` (T) ``+ 2 eps 2d 2vo`` (2 mul, 1 sub)            ``14 eps d vo``
u' = -Q.E2 ``3 e2 14eps d vo + 3 (4 d vo) eps e2 + 3eps 3 (4 d vo) e2``    ``90 eps d vo e2``
v' = Q.E1  as u' with ``e1``                                                ``90 eps d vo e1``
s = u'+v'  ``90 eps d vo (e1+e2) + eps (12 d vo)(e1+e2)``                  ``204 eps d vo e12``
w = det-s  ``12 eps n d + 204 eps d vo e12 + eps (3 n d + 24 d vo e12)``   ``243 eps d M_w``
=========  ==============================================================  ==============

(``|T_i| <= 2 vo``, ``|Q_i| <= 4 d vo``, ``|u'| <= 12 d vo e2``, ``|det| <= 3 n d``,
``M_w = max(n, vo e12)``.) The
margins are these closed forms times ``F = 5/4``, which covers the second-order terms
(``(1 + eps)**k`` for the at most 10 operations on a path, and R's magnitudes being up to
``1 + 2 eps`` above the encoded ones) for ``M >= 8``: a smaller fraction is refused.

Flushes add absolute errors: every operation and every encoded triangle component can
lose up to ``eta``. Inside the domain (below) the magnitudes they are multiplied by are
bounded (``|D| <= 1``, ``|E| <= 2**(P+1)``, ``|N| <= 2**(2P+3)``, ``|T| <= 2**(P+1)``,
``|Q| <= 2**(P+2)``), which gives constants (``det: 8 eta``, ``t': (3*2**(P+1) +
6*2**(2P+3) + 5) eta``, ``u', v': (54*2**P + 5) eta``, ``w: det + 2 u' + 2 eta``). The
margin must cover both parts. With ``Y`` the per-pair exponent of the closed form
(``Y_det = L_N + L_D``, ``Y_t = L_N + L_VO``, ``Y_u = L_D + L_VO + L_E2``,
``Y_v = L_D + L_VO + L_E1``, ``Y_w = L_D + max(L_N, L_E12 + L_VO)``) and ``Yf`` the
smallest integer with ``C eps 2**Yf >= flush bound``::

    margin = s * F * C * eps * (1 + 2**-g) * 2**max(Y, Yf + g),      g = 4

which is at least ``F C eps 2**Y + F C eps 2**Yf`` in both cases of the max. The constant
``K = s F C eps (1 + 2**-g)`` is rounded *up* into the format at build time; the margin is
then K's bit pattern with ``max(Y, Yf + g)`` added to its exponent field (a field that
reaches the all-ones value gives ``+inf``): exponent arithmetic, maxima and adds of small
integers, no multiply. ``s`` (``margin_scale``) is 1 for the derivation; the benchmark
bisects it.

The conservative decision (``m_*`` the margins, comparisons are the contract's ``le``)::

    pos = le(-m_u, u') & le(-m_v, v') & le(-m_w, w) & le(-m_t, t')
    neg = le(u', m_u) & le(v', m_v) & le(w, m_w) & le(t', m_t)
    hit = nan_or_overflow | (le(-m_det, det) & pos) | (le(det, m_det) & neg)

with ``w = sub(det, s)`` (one more adder, the 34th operation). When R's det is positive and
R hits, ``det >= -m_det`` and each widened test holds; likewise for a negative det; so
the mode accepts either sign of det while ``|det| <= m_det``. ``nan_or_overflow`` is set
when any of det, t', u', v', w is a NaN or an operation of the pair overflowed: the mode
fails safe outside its guarantees.

Domain (scene coordinates, see raplas.md "Coordinates")
-------------------------------------------------------
``|O_i|, |V0_i|, |V1_i|, |V2_i| <= 2**P`` with ``P = floor((emax - 7) / 3)`` (so ``t'``,
the largest intermediate, stays below ``3 * 2**(3P+4) < 2**emax``), ``|D_i| <= 1`` (a unit
direction), a non-degenerate triangle, and every edge at least ``2**-Lmin`` long with
``Lmin = floor((-emin - M) / 3)`` (so that ``det ~ L**2`` and ``t' ~ L**3`` of a triangle of
size ``L`` seen from a distance ``L`` keep their ``M`` bits above the flush level; the
bound above holds without it, it only keeps the margin from being dominated by the flush
floor). FP24: ``P = 18``, ``Lmin = 15``; FP32: ``P = 40``, ``Lmin = 34``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from numba import njit

from ..fp.format import FPFormat, check_format

__all__ = ["Domain", "domain", "MarginConstants", "margin_constants", "margin_exponents",
           "margins", "MARGIN_NAMES", "SAFETY", "GUARD_EXP", "C_DET", "C_T", "C_UV", "C_W",
           "MIN_MAN_BITS", "margin_table", "margin_k"]

#: Names of the five margins, in the order the tuples of this module use.
MARGIN_NAMES = ("det", "t", "u", "v", "w")
#: Constants of the closed forms (see the table in the module docstring).
C_DET, C_T, C_UV, C_W = 12, 33, 90, 243
#: The safety factor ``F`` on the first-order bounds.
SAFETY = Fraction(5, 4)
#: ``g``: the flush floor is folded in as ``(1 + 2**-g) * 2**max(Y, Yf + g)``.
GUARD_EXP = 4
#: The derivation's second-order allowance needs at least this many fraction bits.
MIN_MAN_BITS = 8


@dataclass(frozen=True)
class Domain:
    """The region of scene coordinates in which the conservative margin is guaranteed.

    Attributes
    ----------
    pos_exp : int
        ``P``: every coordinate of ``O``, ``V0``, ``V1``, ``V2`` is at most ``2**P`` in magnitude.
    min_edge_exp : int
        ``Lmin``: every edge is at least ``2**-Lmin`` long.
    """

    pos_exp: int
    min_edge_exp: int

    @property
    def max_coord(self) -> float:
        return 2.0 ** self.pos_exp

    @property
    def min_edge(self) -> float:
        return 2.0 ** -self.min_edge_exp


def domain(fmt: FPFormat) -> Domain:
    """The stated domain of ``fmt`` (see the module docstring)."""
    return Domain(pos_exp=(fmt.emax - 7) // 3, min_edge_exp=(-fmt.emin - fmt.man_bits) // 3)


def _flush_bounds(fmt: FPFormat) -> dict:
    """Absolute flush-error bounds of det, t', u', v', w inside the domain (as Fractions)."""
    eta = Fraction(2) ** fmt.emin
    p2 = Fraction(2) ** domain(fmt).pos_exp
    det = 8 * eta
    t = (3 * 2 * p2 + 6 * 8 * p2 * p2 + 5) * eta
    uv = (54 * p2 + 5) * eta
    w = det + 2 * uv + 2 * eta
    return {"det": det, "t": t, "u": uv, "v": uv, "w": w}


@dataclass(frozen=True)
class MarginConstants:
    """Build-time constants of the five margins for one format and scale.

    Attributes
    ----------
    fmt : FPFormat
    scale : float
        ``s``.
    k_bits : dict
        Bit pattern of ``K = s F C eps (1 + 2**-g)`` (rounded up into ``fmt``) per margin.
    floor : dict
        ``Yf + g`` per margin: the smallest ``Y`` the margin uses.
    coeff : dict
        The closed-form constant ``C`` per margin.
    """

    fmt: FPFormat
    scale: float
    k_bits: dict
    floor: dict
    coeff: dict

    @property
    def k_field(self) -> dict:
        m = self.fmt.man_bits
        return {k: (v >> m) & self.fmt.exp_max_field for k, v in self.k_bits.items()}

    @property
    def k_frac(self) -> dict:
        return {k: v & self.fmt.man_mask for k, v in self.k_bits.items()}


def _round_up(x: Fraction, fmt: FPFormat) -> int:
    """Bit pattern of the smallest format value >= the positive rational ``x``."""
    if x <= 0:
        raise ValueError("margin constants must be positive")
    e = math.floor(math.log2(x))
    while Fraction(2) ** e > x:
        e -= 1
    while Fraction(2) ** (e + 1) <= x:
        e += 1
    q = x / Fraction(2) ** e * (1 << fmt.man_bits)        # in [2^M, 2^(M+1))
    sig = math.ceil(q)
    if sig == 1 << (fmt.man_bits + 1):
        sig >>= 1
        e += 1
    field = e + fmt.bias
    if field >= fmt.exp_max_field:
        return fmt.inf
    if field < 1:
        return fmt.min_normal
    return (field << fmt.man_bits) | (sig & fmt.man_mask)


def margin_constants(fmt: FPFormat, margin_scale: float = 1.0) -> MarginConstants:
    """The constants of the conservative margin of ``fmt`` scaled by ``margin_scale``.

    Raises
    ------
    ValueError
        If ``fmt`` has fewer than 8 fraction bits or ``margin_scale`` is not positive.
    """
    check_format(fmt)
    if fmt.man_bits < MIN_MAN_BITS:
        raise ValueError(f"the conservative mode needs man_bits >= {MIN_MAN_BITS}, "
                         f"not {fmt.man_bits}")
    s = float(margin_scale)
    if not (s > 0 and math.isfinite(s)):
        raise ValueError(f"margin_scale must be a positive finite number, not {margin_scale!r}")
    coeff = {"det": C_DET, "t": C_T, "u": C_UV, "v": C_UV, "w": C_W}
    eps = Fraction(1, 1 << fmt.man_bits)
    flush = _flush_bounds(fmt)
    k_bits, floor = {}, {}
    for name, c in coeff.items():
        k = Fraction(s) * SAFETY * c * eps * (1 + Fraction(1, 1 << GUARD_EXP))
        k_bits[name] = _round_up(k, fmt)
        yf = math.ceil(math.log2(flush[name] / (c * eps))) - 2
        while c * eps * Fraction(2) ** yf < flush[name]:
            yf += 1
        floor[name] = yf + GUARD_EXP
    return MarginConstants(fmt, s, k_bits, floor, coeff)


def _max_field(x, fmt):
    x = np.asarray(x, dtype=np.int64)
    return ((x >> fmt.man_bits) & fmt.exp_max_field).max(axis=-1)


def margin_exponents(o, d, v0, e1, e2, n, fmt: FPFormat) -> dict:
    """Per-pair exponents ``Y`` of the closed forms (int64 arrays), from the input fields."""
    lo, ld, lv = (_max_field(x, fmt) - fmt.bias + 1 for x in (o, d, v0))
    le1, le2, ln = (_max_field(x, fmt) - fmt.bias + 1 for x in (e1, e2, n))
    lvo = np.maximum(lv, lo)
    return {"det": ln + ld, "t": ln + lvo, "u": ld + lvo + le2, "v": ld + lvo + le1,
            "w": ld + np.maximum(ln, np.maximum(le1, le2) + lvo)}


def margins(o, d, v0, e1, e2, n, fmt: FPFormat, margin_scale: float = 1.0,
            constants: MarginConstants | None = None) -> dict:
    """The five margins (``uint32`` bit patterns, positive) of every pair.

    Parameters
    ----------
    o, d, v0, e1, e2, n : array_like of uint32, shape (n, 3)
        Encoded ray and triangle record.
    fmt : FPFormat
    margin_scale : float
        ``s``.
    constants : MarginConstants, optional
        Precomputed constants (they must match ``fmt`` and ``margin_scale``).
    """
    c = constants or margin_constants(fmt, margin_scale)
    ys = margin_exponents(o, d, v0, e1, e2, n, fmt)
    out = {}
    for name in MARGIN_NAMES:
        field = c.k_field[name] + np.maximum(ys[name], c.floor[name])
        bits = (np.clip(field, 1, fmt.exp_max_field) << fmt.man_bits) | c.k_frac[name]
        bits = np.where(field >= fmt.exp_max_field, fmt.inf, bits)
        out[name] = bits.astype(np.uint32)
    return out


def margin_table(constants: MarginConstants) -> np.ndarray:
    """The constants as the compiled kernels take them: ``int64`` (3, 5), rows ``k_field``,
    ``k_frac`` and ``floor``, columns in :data:`MARGIN_NAMES` order."""
    return np.array([[constants.k_field[k] for k in MARGIN_NAMES],
                     [constants.k_frac[k] for k in MARGIN_NAMES],
                     [constants.floor[k] for k in MARGIN_NAMES]], dtype=np.int64)


@njit(cache=True)
def _margin_bits(mc, k, y, e, m):
    emf = (np.int64(1) << e) - 1
    field = mc[0, k] + max(y, mc[2, k])
    if field >= emf:
        return np.uint32(emf << m)
    return np.uint32((max(field, np.int64(1)) << m) | mc[1, k])


@njit(cache=True)
def margin_k(fo, fd, fv, fe1, fe2, fn, mc, e, m):
    """The five margins of one pair (``det, t, u, v, w`` bit patterns), the scalar form of
    :func:`margins`: ``fX`` is the largest exponent field of vector ``X``'s components,
    ``mc`` the :func:`margin_table`."""
    b1 = (np.int64(1) << (e - 1)) - 2               # bias - 1: L = field - bias + 1
    lo, ld, lv = fo - b1, fd - b1, fv - b1
    le1, le2, ln = fe1 - b1, fe2 - b1, fn - b1
    lvo = max(lv, lo)
    k = np.int64(0)         # one compiled signature (a literal index compiles one each)
    return (_margin_bits(mc, k, ln + ld, e, m), _margin_bits(mc, k + 1, ln + lvo, e, m),
            _margin_bits(mc, k + 2, ld + lvo + le2, e, m),
            _margin_bits(mc, k + 3, ld + lvo + le1, e, m),
            _margin_bits(mc, k + 4, ld + max(ln, max(le1, le2) + lvo), e, m))
