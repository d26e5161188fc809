"""Scalar numba kernels of the FP contract (``docs/fp-format.md``), bit for bit.

Every kernel is an ``@njit(cache=True)`` function of plain integers, generic in the
format: ``e`` (exponent bits), ``m`` (fraction bits) and ``rmode`` (:data:`RTZ`,
:data:`RNE` or :data:`CHOP`, see :func:`rmode_code`) are runtime integers. They are
meant to be called from other numba code (the unit models compose dozens of them per
element inside one compiled loop) as well as from :mod:`raplas_hdl.fp.model`.

Arithmetic kernels return ``(bits, flags)``: ``bits`` a ``uint32`` pattern of the
format, ``flags`` a ``uint8`` mask of :data:`~raplas_hdl.fp.format.FLAG_OVERFLOW`,
:data:`~raplas_hdl.fp.format.FLAG_UNDERFLOW` and :data:`~raplas_hdl.fp.format.FLAG_INVALID`.

Compile cost: the kernels are *not* inlined at numba's IR level (``inline="always"``):
numba would type and lower a kernel's whole body again at every call site (the
ray-triangle loop's 33 operations took 165 s of CPU to compile that way). Each kernel is
compiled once per signature (a fraction of a second) and LLVM inlines the calls in the
optimised callers; callers that pass the format as compile-time constants get its shifts
and masks folded (:mod:`raplas_hdl.fp.fast` has the branch-free common case for them).
Caveat of numba's disk cache: a caller's cache entry does not notice edits to these
kernels; :mod:`raplas_hdl.fp.numba_cache` drops the callers' entries when this file
changes.

Operands must be valid patterns of the format (at most ``1 + e + m`` bits); the
NumPy API checks that, the kernels do not.

Internals: everything is ``int64`` arithmetic. The adder aligns the smaller significand
into a field three bits wider than the significand (guard, round and a sticky bit
that ORs everything shifted out), which is enough for a correct ``rtz``/``rne``
rounding of sums and differences; ``chop`` is the same datapath with the three extra
bits cleared before the add (the bits shifted out are simply dropped). The
multiplier forms the exact ``(m+1) x (m+1)``-bit product (at most 60 bits for
``m <= 29``) and rounds it once.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .format import FLAG_INVALID, FLAG_OVERFLOW, FLAG_UNDERFLOW

__all__ = ["RTZ", "RNE", "CHOP", "UP", "DOWN", "rmode_code", "add_k", "sub_k", "mul_k",
           "add_int_k", "mul_int_k", "add_f64_k", "mul_f64_k", "fast_path_ok",
           "neg_k", "le_k", "lt_k", "abs_le_k", "is_nan_k", "encode_k", "decode_k"]

#: Rounding codes of the kernels (``rmode``).
RTZ = 0
RNE = 1
CHOP = 2
#: Extra rounding codes used by :func:`encode_k` only (directed rounding).
UP = 3
DOWN = 4

_RMODES = {"rtz": RTZ, "rne": RNE, "chop": CHOP}

_OVF = np.uint8(FLAG_OVERFLOW)
_UNF = np.uint8(FLAG_UNDERFLOW)
_INV = np.uint8(FLAG_INVALID)
_NOF = np.uint8(0)


def rmode_code(fmt) -> int:
    """The kernels' ``rmode`` integer of a format's rounding (``rtz`` 0, ``rne`` 1, ``chop`` 2).

    Raises
    ------
    ValueError
        When ``fmt.rounding`` is not one of the contract's roundings.
    """
    try:
        return _RMODES[fmt.rounding]
    except KeyError:
        raise ValueError(f"rounding must be one of rtz, rne, chop, not {fmt.rounding!r}") \
            from None


@njit(cache=True)
def _pack(s, ex, q, e, m, rmode):
    """Pack sign ``s``, biased exponent ``ex`` and significand ``q`` (hidden one included),
    applying overflow (rule 2) and flush-to-zero (rule 3)."""
    emf = (np.int64(1) << e) - 1
    sh = e + m
    if ex >= emf:
        if rmode == RNE:
            return np.uint32((s << sh) | (emf << m)), _OVF
        return np.uint32((s << sh) | (((emf - 1) << m) | ((np.int64(1) << m) - 1))), _OVF
    if ex <= 0:
        return np.uint32(s << sh), _UNF
    return np.uint32((s << sh) | (ex << m) | (q & ((np.int64(1) << m) - 1))), _NOF


@njit(cache=True)
def _nan(e, m):
    return np.uint32((((np.int64(1) << e) - 1) << m) | (np.int64(1) << (m - 1)))


@njit(cache=True)
def _bitlen(v):
    """Bit length of ``0 <= v < 2**63`` without branches (a binary search by selects)."""
    n = np.int64(0)
    for k in (32, 16, 8, 4, 2, 1):
        t = np.int64(k) if (v >> k) != 0 else np.int64(0)
        v >>= t
        n += t
    return n + v


@njit(cache=True)
def _add_special(sa, xa, fa, sb, xb, fb, e, m):
    """``a + b`` when an operand is zero, infinite or NaN (rules 4 and 5)."""
    emf = (np.int64(1) << e) - 1
    sh = e + m
    if (xa == emf and fa != 0) or (xb == emf and fb != 0):
        return _nan(e, m), _NOF
    if xa == emf and xb == emf:
        if sa != sb:
            return _nan(e, m), _INV
        return np.uint32((sa << sh) | (emf << m)), _NOF
    if xa == emf:
        return np.uint32((sa << sh) | (emf << m)), _NOF
    if xb == emf:
        return np.uint32((sb << sh) | (emf << m)), _NOF
    if xa == 0 and xb == 0:
        return np.uint32((sa & sb) << sh), _NOF
    if xa == 0:
        return np.uint32((sb << sh) | (xb << m) | fb), _NOF
    return np.uint32((sa << sh) | (xa << m) | fa), _NOF


@njit(cache=True)
def add_int_k(a, b, e, m, rmode):
    """``a + b`` by integer arithmetic, any format; returns ``(bits, flags)``.

    The path of two normal operands is written with selects rather than branches
    (order by magnitude, align with sticky, add or subtract, normalise by a bit-length
    count, round), so it vectorises and does not mispredict on random data.
    """
    a = np.int64(a)
    b = np.int64(b)
    e = np.int64(e)
    m = np.int64(m)
    emf = (np.int64(1) << e) - 1
    mm = (np.int64(1) << m) - 1
    sh = e + m
    sa = (a >> sh) & 1
    sb = (b >> sh) & 1
    xa = (a >> m) & emf
    xb = (b >> m) & emf
    fa = a & mm
    fb = b & mm
    if xa == 0 or xb == 0 or xa == emf or xb == emf:
        return _add_special(sa, xa, fa, sb, xb, fb, e, m)
    # Both normal: order so that |a| >= |b| (the sign of the result is the larger's).
    mag_a = a & ((np.int64(1) << sh) - 1)
    mag_b = b & ((np.int64(1) << sh) - 1)
    swap = mag_b > mag_a
    s = sb if swap else sa
    hi = mag_b if swap else mag_a
    lo = mag_a if swap else mag_b
    ex = hi >> m
    d = min(ex - (lo >> m), m + 4)      # (B << 3) >> (m + 4) is already 0
    ax = ((np.int64(1) << m) | (hi & mm)) << 3
    bx = ((np.int64(1) << m) | (lo & mm)) << 3
    bal = bx >> d
    sticky = np.int64(1) if (bx & ((np.int64(1) << d) - 1)) != 0 else np.int64(0)
    if rmode == CHOP:
        bal &= ~np.int64(7)              # shifted-out bits are dropped
    else:
        bal |= sticky
    s3 = ax - bal if sa != sb else ax + bal
    if s3 == 0:
        return np.uint32(0), _NOF        # exact zero sum: +0 (rule 4)
    # Normalise so that bit m+3 leads: shift right by one (keeping the sticky bit) after
    # a carry, or left (zeros in) after cancellation.
    lsh = m + 4 - _bitlen(s3)            # -1 .. m+3
    s3 = ((s3 >> 1) | (s3 & 1)) if lsh < 0 else (s3 << max(lsh, 0))
    ex -= lsh
    q = s3 >> 3
    if rmode == RNE:
        r = s3 & 7
        q += np.int64(1) if (r > 4 or (r == 4 and (q & 1) != 0)) else np.int64(0)
        c = q >> (m + 1)
        q >>= c
        ex += c
    return _pack(s, ex, q, e, m, rmode)


@njit(cache=True)
def neg_k(a, e, m):
    """``-a``: flips the sign of a non-NaN ``a``; a NaN gives the canonical NaN."""
    a = np.int64(a)
    if is_nan_k(a, e, m):
        return _nan(e, m)
    return np.uint32(a ^ (np.int64(1) << (e + m)))


@njit(cache=True)
def sub_k(a, b, e, m, rmode):
    """``a - b = a + neg(b)``; returns ``(bits, flags)``."""
    return add_k(a, np.int64(neg_k(b, e, m)), e, m, rmode)


@njit(cache=True)
def mul_int_k(a, b, e, m, rmode):
    """``a * b`` by integer arithmetic, any format; returns ``(bits, flags)``.

    ``chop`` multiplies exactly like ``rtz`` (the contract says so).
    """
    a = np.int64(a)
    b = np.int64(b)
    e = np.int64(e)
    m = np.int64(m)
    emf = (np.int64(1) << e) - 1
    mm = (np.int64(1) << m) - 1
    sh = e + m
    xa = (a >> m) & emf
    xb = (b >> m) & emf
    fa = a & mm
    fb = b & mm
    s = ((a ^ b) >> sh) & 1
    if xa == emf or xb == emf:
        if (xa == emf and fa != 0) or (xb == emf and fb != 0):
            return _nan(e, m), _NOF
        if xa == 0 or xb == 0:
            return _nan(e, m), _INV
        return np.uint32((s << sh) | (emf << m)), _NOF
    if xa == 0 or xb == 0:
        return np.uint32(s << sh), _NOF
    p = ((np.int64(1) << m) | fa) * ((np.int64(1) << m) | fb)     # in [2^2m, 2^(2m+2))
    t = p >> (2 * m + 1)                                         # 1 when p >= 2^(2m+1)
    ex = xa + xb - ((np.int64(1) << (e - 1)) - 1) + t
    shift = m + t
    q = p >> shift
    if rmode == RNE:
        rem = p & ((np.int64(1) << shift) - 1)
        half = np.int64(1) << (shift - 1)
        q += np.int64(1) if (rem > half or (rem == half and (q & 1) != 0)) else np.int64(0)
        c = q >> (m + 1)
        q >>= c
        ex += c
    return _pack(s, ex, q, e, m, rmode)


# -- float64 path -------------------------------------------------------------------------
# For E <= 8 and M <= 25 every value, every exact product and every TwoSum error term of
# the format is a normal float64, so the operations can run on float64 with the rounding
# done on the float64 bit pattern, without a data-dependent branch (LLVM vectorises the
# loops). The integer kernels above are the reference path for every other format and
# the tests hold both paths to the oracle.

@njit(cache=True)
def fast_path_ok(e, m):
    """True when :func:`add_k`/:func:`mul_k` use the float64 path for format ``(e, m)``."""
    return e <= 8 and m <= 25


@njit(cache=True)
def _to_f64(a, e, m):
    """Exact float64 of a pattern (denormal patterns as signed zeros), branch-free."""
    emf = (np.int64(1) << e) - 1
    sh = e + m
    ex = (a >> m) & emf
    f = a & ((np.int64(1) << m) - 1)
    sign = ((a >> sh) & 1) << 63
    bits = sign | ((ex + (1023 - ((np.int64(1) << (e - 1)) - 1))) << 52) | (f << (52 - m))
    bits = sign if ex == 0 else bits
    bits = (sign | (np.int64(0x7FF) << 52) | (f << (52 - m))) if ex == emf else bits
    return np.int64(bits).view(np.float64)


@njit(cache=True)
def _round_f64(v, err, nan_in, e, m, rmode):
    """Round ``v + err`` (``err``: a float64 much smaller than one float64 ulp of ``v``
    or 0, of any sign) into the format by ``rmode``; NaN results become the canonical
    NaN, flagged invalid unless ``nan_in``."""
    emf = (np.int64(1) << e) - 1
    bias = (np.int64(1) << (e - 1)) - 1
    sh = e + m
    cut = 52 - m
    vb = np.float64(v).view(np.int64)
    s = (vb >> 63) & 1
    low = vb & ((np.int64(1) << cut) - 1)
    base = vb - low
    # The sign of the error relative to v's magnitude: -1 (exact is smaller), 0, +1.
    eb = np.float64(err).view(np.int64)
    rel = np.int64(0) if err == 0.0 else (np.int64(1) if ((eb >> 63) & 1) == s
                                          else np.int64(-1))
    half = np.int64(1) << (cut - 1)
    if rmode == RNE:
        odd = (vb >> cut) & 1
        up = low > half or (low == half and (rel > 0 or (rel == 0 and odd != 0)))
        q = base + ((np.int64(1) << cut) if up else np.int64(0))
    else:
        q = base - ((np.int64(1) << cut) if (low == 0 and rel < 0) else np.int64(0))
    fe = (q >> 52) & 0x7FF
    ux = fe - 1023
    frac = (q >> cut) & ((np.int64(1) << m) - 1)
    normal = (s << sh) | ((ux + bias) << m) | frac
    over = (ux > emf - 1 - bias) and fe != 0x7FF
    under = ux < 1 - bias and v != 0.0
    sat = (s << sh) | (((emf - 1) << m) | ((np.int64(1) << m) - 1))
    inf = (s << sh) | (emf << m)
    r = normal
    r = (inf if rmode == RNE else sat) if over else r
    r = (s << sh) if (under or v == 0.0) else r
    r = inf if fe == 0x7FF else r
    is_nan = v != v
    r = ((emf << m) | (np.int64(1) << (m - 1))) if (is_nan or nan_in) else r
    fl = np.uint8(0)
    fl = (fl | _OVF) if over else fl
    fl = (fl | _UNF) if under else fl
    fl = (fl | _INV) if (is_nan and not nan_in) else fl
    return np.uint32(r), fl


@njit(cache=True)
def mul_f64_k(a, b, e, m, rmode):
    """``a * b`` by float64 (E <= 8, M <= 25 only); returns ``(bits, flags)``."""
    a = np.int64(a)
    b = np.int64(b)
    p = _to_f64(a, e, m) * _to_f64(b, e, m)          # exact
    nan_in = is_nan_k(a, e, m) or is_nan_k(b, e, m)
    return _round_f64(p, 0.0, nan_in, e, m, RTZ if rmode == CHOP else rmode)


@njit(cache=True)
def add_f64_k(a, b, e, m, rmode):
    """``a + b`` by float64 and TwoSum (E <= 8, M <= 25 only); ``chop`` truncates the
    smaller operand to the larger one's last place first, as the contract says."""
    a = np.int64(a)
    b = np.int64(b)
    x = _to_f64(a, e, m)
    y = _to_f64(b, e, m)
    nan_in = is_nan_k(a, e, m) or is_nan_k(b, e, m)
    if rmode == CHOP and not nan_in:                 # (a NaN operand has no exponent to align to)
        swap = abs(y) > abs(x)
        hi = y if swap else x
        lo = x if swap else y
        hb = np.float64(hi).view(np.int64)
        lb = np.float64(lo).view(np.int64)
        d = ((hb >> 52) & 0x7FF) - ((lb >> 52) & 0x7FF)
        keep = m - d                                 # fraction bits of lo that survive
        lb = (lb & (np.int64(1) << 63)) if keep < 0 else \
            (lb & ~((np.int64(1) << (52 - max(keep, 0))) - 1))
        ss = hi + np.int64(lb).view(np.float64)      # exact: both on hi's grid
        return _round_f64(ss, 0.0, nan_in, e, m, np.int64(RTZ))
    ss = x + y
    bb = ss - x
    err = (x - (ss - bb)) + (y - bb)                 # x + y = ss + err exactly
    err = 0.0 if err != err else err                 # infinities: no error term
    return _round_f64(ss, err, nan_in, e, m, rmode)


@njit(cache=True)
def add_k(a, b, e, m, rmode):
    """``a + b`` in the format ``(e, m)`` with rounding ``rmode``; returns ``(bits, flags)``.

    Uses :func:`add_f64_k` when :func:`fast_path_ok`, else :func:`add_int_k`: the same
    bits either way.
    """
    if fast_path_ok(e, m):
        return add_f64_k(a, b, e, m, rmode)
    return add_int_k(a, b, e, m, rmode)


@njit(cache=True)
def mul_k(a, b, e, m, rmode):
    """``a * b`` in the format ``(e, m)`` with rounding ``rmode``; returns ``(bits, flags)``.

    ``chop`` multiplies like ``rtz``. Uses :func:`mul_f64_k` when :func:`fast_path_ok`,
    else :func:`mul_int_k`.
    """
    if fast_path_ok(e, m):
        return mul_f64_k(a, b, e, m, rmode)
    return mul_int_k(a, b, e, m, rmode)


@njit(cache=True)
def _key(a, e, m):
    """Order key of a non-NaN pattern: signed magnitude, denormal patterns and -0 as 0."""
    a = np.int64(a)
    sh = e + m
    mag = a & ((np.int64(1) << sh) - 1)
    if (mag >> m) == 0:
        return np.int64(0)
    if ((a >> sh) & 1) != 0:
        return -mag
    return mag


@njit(cache=True)
def is_nan_k(a, e, m):
    """True when ``a`` is a NaN pattern of the format (all-ones exponent, non-zero
    fraction): the one NaN test of the kernels and the models."""
    a = np.int64(a)
    emf = (np.int64(1) << e) - 1
    return ((a >> m) & emf) == emf and (a & ((np.int64(1) << m) - 1)) != 0


@njit(cache=True)
def le_k(a, b, e, m):
    """``a <= b`` (ordered: any NaN gives False; -0 == +0; denormal patterns are zero)."""
    if is_nan_k(a, e, m) or is_nan_k(b, e, m):
        return False
    return _key(a, e, m) <= _key(b, e, m)


@njit(cache=True)
def lt_k(a, b, e, m):
    """``a < b`` (ordered: any NaN gives False; -0 == +0; denormal patterns are zero)."""
    if is_nan_k(a, e, m) or is_nan_k(b, e, m):
        return False
    return _key(a, e, m) < _key(b, e, m)


@njit(cache=True)
def abs_le_k(a, b, e, m):
    """``|a| <= |b|`` (any NaN gives False; denormal patterns are zero)."""
    if is_nan_k(a, e, m) or is_nan_k(b, e, m):
        return False
    ka = _key(a, e, m)
    kb = _key(b, e, m)
    return abs(ka) <= abs(kb)


@njit(cache=True)
def encode_k(xbits, e, m, mode):
    """Round a float64, given as its ``int64`` bit pattern, into the format.

    ``mode`` is :data:`RTZ`, :data:`RNE`, :data:`UP` (toward +inf) or :data:`DOWN`
    (toward -inf); callers map ``chop`` to ``RTZ``. Returns ``(bits, flags)``:
    overflow when a finite value's rounded exponent exceeds ``emax``, underflow when a
    non-zero value's rounded magnitude is below the normal range.
    """
    x = np.int64(xbits)
    e = np.int64(e)
    m = np.int64(m)
    emf = (np.int64(1) << e) - 1
    bias = (np.int64(1) << (e - 1)) - 1
    sh = e + m
    s = (x >> 63) & 1
    ef = (x >> 52) & 0x7FF
    fr = x & ((np.int64(1) << 52) - 1)
    if ef == 0x7FF:
        if fr != 0:
            return _nan(e, m), _NOF
        return np.uint32((s << sh) | (emf << m)), _NOF
    if ef == 0:
        if fr == 0:
            return np.uint32(s << sh), _NOF
        sig = fr
        ux = np.int64(-1022)
        while sig < (np.int64(1) << 52):
            sig <<= 1
            ux -= 1
    else:
        sig = fr | (np.int64(1) << 52)
        ux = ef - 1023
    cut = 52 - m
    q = sig >> cut
    rem = sig & ((np.int64(1) << cut) - 1)
    away = (mode == UP and s == 0) or (mode == DOWN and s == 1)
    inc = False
    if mode == RNE:
        half = np.int64(1) << (cut - 1)
        inc = rem > half or (rem == half and (q & 1) != 0)
    elif away:
        inc = rem != 0
    if inc:
        q += 1
        if (q >> (m + 1)) != 0:
            q >>= 1
            ux += 1
    if ux > emf - 1 - bias:
        if mode == RNE or away:
            return np.uint32((s << sh) | (emf << m)), _OVF
        return np.uint32((s << sh) | ((emf - 1) << m) | ((np.int64(1) << m) - 1)), _OVF
    if ux < 1 - bias:
        if away:
            return np.uint32((s << sh) | (np.int64(1) << m)), _UNF
        return np.uint32(s << sh), _UNF
    return np.uint32((s << sh) | ((ux + bias) << m) | (q & ((np.int64(1) << m) - 1))), _NOF


@njit(cache=True)
def decode_k(a, e, m):
    """The float64 bit pattern (``int64``) of a format pattern; exact (denormals decode as
    signed zeros, every NaN as a quiet NaN)."""
    a = np.int64(a)
    emf = (np.int64(1) << e) - 1
    sh = e + m
    s = (a >> sh) & 1
    ex = (a >> m) & emf
    f = a & ((np.int64(1) << m) - 1)
    sign = s << 63
    if ex == 0:
        return sign
    if ex == emf:
        if f != 0:
            return np.int64(0x7FF8) << 48
        return sign | (np.int64(0x7FF) << 52)
    bias = (np.int64(1) << (e - 1)) - 1
    return sign | ((ex - bias + 1023) << 52) | (f << (52 - m))
