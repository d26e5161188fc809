"""The arithmetic contract (``docs/fp-format.md``) as SMT terms over bit patterns.

:func:`reference` gives, for symbolic (or constant) operand bit patterns, the result bit
pattern and the three event flags that the contract prescribes, as z3 bit-vector terms.

``rtz`` and ``rne`` are built on z3's FloatingPoint theory, with the contract's
adaptations:

- operands are decoded by hand: an exponent field of 0 is a signed zero whatever the
  fraction (subnormal inputs flush to zero), all ones with a fraction is a NaN;
- the operation is done in ``FPSort(E + 2, M + 1)``: the same significand, two more
  exponent bits. Every sum and product of two format values is a normal number of that
  sort (or zero), so its IEEE rounding is rule 1's rounding to ``M+1`` bits *with an
  unbounded exponent*; the format's own sort would round tiny products as subnormals;
- rules 2 and 3 are then applied to the rounded exponent: above ``emax`` gives the
  signed max finite value (``rtz``) or infinity (``rne``) and the overflow flag, below
  ``emin`` the signed zero and the underflow flag;
- every NaN result is the canonical NaN; ``invalid`` is raised when no operand was a NaN.

``chop`` is not an IEEE rounding: the adder is written from the contract's ``chop``
section as bit-vector arithmetic (order by magnitude, shift the smaller significand right
dropping the bits, add or subtract, normalise, saturate, flush), and the multiplier is
``rtz`` (the contract says they are identical). The ``chop`` adder uses only bit-vector
operations, so :mod:`.concrete` can evaluate it on arrays of operands and the tests
compare it with the golden model on every operand pair of a small format.

``bitvector=True`` gives the multiplier's contract as bit vectors too (every rounding):
the exact significand product as one ``bvmul``, normalised, rounded, saturated, flushed.
That is the form the multiplier proofs use (:mod:`.cut` replaces the product, on both
sides, by one uninterpreted function); its equality with the FloatingPoint-theory form is
proved at small formats and checked against the golden model (``tests/formal/test_formal.py``).
"""

from __future__ import annotations

import z3

from ..fp.format import FPFormat, check_format

__all__ = ["OPS", "reference", "fields"]

#: The operations :func:`reference` knows (``add`` takes a ``sub`` bit; ``neg`` one
#: operand).
OPS = ("add", "mul", "le", "lt", "neg")


def fields(fmt: FPFormat, bits):
    """``(sign, exp, frac)`` of a ``W``-bit term (1, ``E`` and ``M`` bits)."""
    m, e, w = fmt.man_bits, fmt.exp_bits, fmt.width
    return z3.Extract(w - 1, w - 1, bits), z3.Extract(m + e - 1, m, bits), \
        z3.Extract(m - 1, 0, bits) if m else None


class _Class:
    """Classification of one operand pattern (z3 Booleans)."""

    def __init__(self, fmt, bits):
        self.sign, self.exp, self.frac = fields(fmt, bits)
        self.zero = self.exp == 0
        ones = self.exp == fmt.exp_max_field
        self.inf = z3.And(ones, self.frac == 0)
        self.nan = z3.And(ones, self.frac != 0)


def _bv(value, width):
    return z3.BitVecVal(value, width)


def _pack(fmt, sign, exp, frac):
    """``sign | exp | frac`` as one ``W``-bit term."""
    return z3.Concat(sign, exp, frac)


def _result(fmt, *, nan, invalid, inf, inf_sign, zero, zero_sign, overflow, underflow,
            sign, normal):
    """The contract's priority: NaN, infinity, exact zero, overflow, underflow, normal."""
    w = fmt.width
    big = fmt.inf if fmt.rounding == "rne" else fmt.max_finite
    bits = z3.If(nan, _bv(fmt.nan, w),
           z3.If(inf, z3.Concat(inf_sign, _bv(fmt.inf, w - 1)),
           z3.If(zero, z3.Concat(zero_sign, _bv(0, w - 1)),
           z3.If(overflow, z3.Concat(sign, _bv(big, w - 1)),
           z3.If(underflow, z3.Concat(sign, _bv(0, w - 1)), normal)))))
    finite = z3.Not(z3.Or(nan, inf, zero))
    flags = z3.Concat(
        z3.If(z3.And(nan, invalid), _bv(1, 1), _bv(0, 1)),
        z3.If(z3.And(finite, z3.Not(overflow), underflow), _bv(1, 1), _bv(0, 1)),
        z3.If(z3.And(finite, overflow), _bv(1, 1), _bv(0, 1)))
    return bits, flags


# -- rtz, rne: IEEE FloatingPoint in a wider exponent -----------------------------------
def _wide_sort(fmt):
    return z3.FPSort(fmt.exp_bits + 2, fmt.man_bits + 1)


def _wide_offset(fmt):
    """Wide biased exponent minus the format's biased exponent."""
    return (1 << (fmt.exp_bits + 1)) - 1 - fmt.bias


def _to_wide(fmt, bits, cls):
    sort = _wide_sort(fmt)
    e = fmt.exp_bits
    wexp = z3.ZeroExt(2, cls.exp) + _wide_offset(fmt)
    normal = z3.fpFP(cls.sign, wexp, cls.frac)
    zero = z3.fpFP(cls.sign, _bv(0, e + 2), _bv(0, fmt.man_bits))
    inf = z3.fpFP(cls.sign, _bv((1 << (e + 2)) - 1, e + 2), _bv(0, fmt.man_bits))
    return z3.If(cls.zero, zero, z3.If(cls.inf, inf, z3.If(cls.nan, z3.fpNaN(sort), normal)))


def _ieee(fmt, op, ca, cb, a, b, sub):
    rm = z3.RTZ() if fmt.rounding in ("rtz", "chop") else z3.RNE()
    x, y = _to_wide(fmt, a, ca), _to_wide(fmt, b, cb)
    if op == "add":
        if sub is not None:
            y = z3.If(sub == 1, z3.fpNeg(y), y)
        r = z3.fpAdd(rm, x, y)
        inf_in = z3.Or(ca.inf, cb.inf)
    else:
        r = z3.fpMul(rm, x, y)
        inf_in = z3.Or(ca.inf, cb.inf)
    m, e = fmt.man_bits, fmt.exp_bits
    rb = z3.fpToIEEEBV(r)
    sign = z3.Extract(m + e + 2, m + e + 2, rb)
    wexp = z3.Extract(m + e + 1, m, rb)
    frac = z3.Extract(m - 1, 0, rb)
    off = _wide_offset(fmt)
    # z3 leaves fpToIEEEBV of a NaN unspecified; NaN is decided first in _result.
    return _result(
        fmt, nan=z3.fpIsNaN(r), invalid=z3.Not(z3.Or(ca.nan, cb.nan)),
        inf=inf_in, inf_sign=sign, zero=z3.fpIsZero(r), zero_sign=sign,
        overflow=z3.UGE(wexp, fmt.exp_max_field + off), underflow=z3.ULE(wexp, off),
        sign=sign, normal=z3.Concat(sign, z3.Extract(e - 1, 0, wexp - off), frac))


# -- chop: the paper's truncating adder, as bit vectors -----------------------------------
def _leading_zeros(value, width, out_width):
    """Leading zeros of a ``width``-bit term (``width`` when it is 0), ``out_width`` bits."""
    count = _bv(width, out_width)
    for k in range(width):      # the lowest set bit first, the highest wins
        count = z3.If(z3.Extract(k, k, value) == 1, _bv(width - 1 - k, out_width), count)
    return count


def _chop_add(fmt, ca, cb, a, b, sub):
    m, e = fmt.man_bits, fmt.exp_bits
    ew = e + 7                      # signed working exponent (z3's >= and <= on it are signed)
    sign_b = cb.sign ^ sub if sub is not None else cb.sign
    any_nan = z3.Or(ca.nan, cb.nan)
    inf_inf = z3.And(ca.inf, cb.inf, ca.sign != sign_b)
    # order by magnitude (exponent, then significand): x is the larger
    swap = z3.UGT(z3.Concat(cb.exp, cb.frac), z3.Concat(ca.exp, ca.frac))
    sx = z3.If(swap, sign_b, ca.sign)
    ex = z3.If(swap, cb.exp, ca.exp)
    ey = z3.If(swap, ca.exp, cb.exp)
    big_a = z3.Concat(_bv(1, 1), z3.If(swap, cb.frac, ca.frac))       # A, M+1 bits
    big_b = z3.Concat(_bv(1, 1), z3.If(swap, ca.frac, cb.frac))       # B
    sw = max(m + 1, e)
    d = z3.ZeroExt(sw - e, ex - ey)
    shifted = z3.Extract(m, 0, z3.LShR(z3.ZeroExt(sw - m - 1, big_b), d))    # B >> d
    exp_x = z3.ZeroExt(ew - e, ex)
    # same signs: S = A + B', one bit right on a carry
    total = z3.ZeroExt(1, big_a) + z3.ZeroExt(1, shifted)
    carry = z3.Extract(m + 1, m + 1, total)
    sig_add = z3.If(carry == 1, z3.Extract(m + 1, 1, total), z3.Extract(m, 0, total))
    exp_add = exp_x + z3.ZeroExt(ew - 1, carry)
    # opposite signs: S = A - B', normalised left
    diff = big_a - shifted
    lz = _leading_zeros(diff, m + 1, ew)
    sig_sub = diff << z3.ZeroExt(m + 1 - ew, lz) if m + 1 > ew else \
        z3.Extract(m, 0, z3.ZeroExt(ew - m - 1, diff) << lz)
    exp_sub = exp_x - lz
    same = sx == z3.If(swap, ca.sign, sign_b)
    sig = z3.If(same, sig_add, sig_sub)
    exp = z3.If(same, exp_add, exp_sub)
    cancel = z3.And(z3.Not(same), diff == 0)
    # a zero operand is not aligned: x + 0 = x
    a_pass = z3.Concat(ca.sign, ca.exp, ca.frac)
    b_pass = z3.Concat(sign_b, cb.exp, cb.frac)
    normal = z3.If(cb.zero, a_pass, z3.If(ca.zero, b_pass, z3.Concat(
        sx, z3.Extract(e - 1, 0, exp), z3.Extract(m - 1, 0, sig))))
    one_zero = z3.Xor(ca.zero, cb.zero)
    return _result(
        fmt, nan=z3.Or(any_nan, inf_inf), invalid=z3.Not(any_nan),
        inf=z3.Or(ca.inf, cb.inf), inf_sign=z3.If(ca.inf, ca.sign, sign_b),
        zero=z3.Or(z3.And(ca.zero, cb.zero), z3.And(cancel, z3.Not(one_zero))),
        zero_sign=z3.If(z3.And(ca.zero, cb.zero), ca.sign & sign_b, _bv(0, 1)),
        overflow=z3.And(z3.Not(one_zero), exp >= fmt.exp_max_field),
        underflow=z3.And(z3.Not(one_zero), exp <= 0),
        sign=sx, normal=normal)


# -- mul as bit vectors: exact product, normalise, round ----------------------------------
def _bv_mul(fmt, ca, cb):
    m, e = fmt.man_bits, fmt.exp_bits
    ew = e + 3                                  # signed working exponent
    big_a = z3.ZeroExt(m + 1, z3.Concat(_bv(1, 1), ca.frac))
    big_b = z3.ZeroExt(m + 1, z3.Concat(_bv(1, 1), cb.frac))
    prod = big_a * big_b                        # exact: 2M+2 bits, in [2^2M, 2^(2M+2))
    top = z3.Extract(2 * m + 1, 2 * m + 1, prod)
    norm = z3.If(top == 1, prod, prod << 1)
    sig = z3.Extract(2 * m + 1, m + 1, norm)
    guard = z3.Extract(m, m, norm)
    sticky = z3.Extract(m - 1, 0, norm) != 0
    exp = z3.ZeroExt(ew - e, ca.exp) + z3.ZeroExt(ew - e, cb.exp) - fmt.bias \
        + z3.ZeroExt(ew - 1, top)
    if fmt.rounding == "rne":
        up = z3.And(guard == 1, z3.Or(sticky, z3.Extract(0, 0, sig) == 1))
        total = z3.ZeroExt(1, sig) + z3.If(up, _bv(1, m + 2), _bv(0, m + 2))
        carry = z3.Extract(m + 1, m + 1, total)
        sig = z3.If(carry == 1, _bv(1 << m, m + 1), z3.Extract(m, 0, total))
        exp = exp + z3.ZeroExt(ew - 1, carry)
    sign = ca.sign ^ cb.sign
    any_nan = z3.Or(ca.nan, cb.nan)
    zero_inf = z3.Or(z3.And(ca.zero, cb.inf), z3.And(ca.inf, cb.zero))
    return _result(
        fmt, nan=z3.Or(any_nan, zero_inf), invalid=z3.Not(any_nan),
        inf=z3.Or(ca.inf, cb.inf), inf_sign=sign, zero=z3.Or(ca.zero, cb.zero),
        zero_sign=sign, overflow=exp >= fmt.exp_max_field, underflow=exp <= 0, sign=sign,
        normal=z3.Concat(sign, z3.Extract(e - 1, 0, exp), z3.Extract(m - 1, 0, sig)))


def _ordered(fmt, op, ca, cb, a, b):
    """``le``/``lt``: IEEE's ordered comparison of the decoded values (a denormal pattern
    is a signed zero, +0 equals -0, a NaN compares false), as one bit."""
    x, y = _to_wide(fmt, a, ca), _to_wide(fmt, b, cb)
    holds = z3.fpLEQ(x, y) if op == "le" else z3.fpLT(x, y)
    return z3.If(holds, _bv(1, 1), _bv(0, 1)), None


def _neg(fmt, ca, a):
    """``neg``: the sign bit flipped, the canonical NaN for a NaN (the contract's rule 6,
    which is about patterns: a denormal pattern keeps its fraction)."""
    w = fmt.width
    return z3.If(ca.nan, _bv(fmt.nan, w), a ^ _bv(1 << (w - 1), w)), None


def reference(fmt: FPFormat, op: str, a, b, sub=None, *, bitvector: bool = False):
    """The contract's result of ``a op b`` as z3 terms.

    Parameters
    ----------
    fmt : FPFormat
        Format and rounding.
    op : {"add", "mul", "le", "lt", "neg"}
        ``add`` is ``a + b``, or ``a - b`` where ``sub`` is 1; ``le`` and ``lt`` the
        ordered comparisons (one bit, no flags); ``neg`` ignores ``b`` (no flags).
    a, b : z3.BitVecRef
        ``W``-bit operand patterns (variables or constants).
    sub : z3.BitVecRef, optional
        1-bit subtract select of ``add`` (``None``: add only).
    bitvector : bool
        ``mul`` only: the contract written as bit vectors (the exact ``2M+2``-bit
        significand product, normalised by its top bit, rounded with guard and sticky
        bits, then rules 2 and 3) instead of the FloatingPoint theory. Its one product is
        a ``bvmul`` that :mod:`.cut` can replace by an uninterpreted function.

    Returns
    -------
    (bits, flags)
        ``W``-bit result pattern (one bit for a comparison) and 3-bit flags (``overflow``
        bit 0, ``underflow`` bit 1, ``invalid`` bit 2, as ``FLAG_*``; ``None`` for the
        operations that raise none: ``le``, ``lt``, ``neg``).

    Raises
    ------
    ValueError
        For an unknown ``op``, a format with fewer than 2 fraction bits, ``sub`` given to
        ``mul`` or ``bitvector`` to ``add``.
    """
    fmt = check_format(fmt)
    if op not in OPS:
        raise ValueError(f"op must be one of {', '.join(OPS)}, not {op!r}")
    if fmt.man_bits < 2:
        raise ValueError(f"the reference needs at least 2 fraction bits, not {fmt.man_bits}")
    if op != "add" and sub is not None:
        raise ValueError("sub applies to add only")
    if op != "mul" and bitvector:
        raise ValueError("bitvector applies to mul only (the chop adder is always bit vectors)")
    ca = _Class(fmt, a)
    if op == "neg":
        return _neg(fmt, ca, a)
    cb = _Class(fmt, b)
    if op in ("le", "lt"):
        return _ordered(fmt, op, ca, cb, a, b)
    if op == "mul" and bitvector:
        return _bv_mul(fmt, ca, cb)
    if op == "add" and fmt.rounding == "chop":
        return _chop_add(fmt, ca, cb, a, b, sub)
    return _ieee(fmt, op, ca, cb, a, b, sub)
