"""Combinational building blocks shared by the floating-point units.

Every function here builds an Amaranth expression for one format of the contract
(``docs/fp-format.md``); none of them adds registers. :mod:`.fp_add` and
:mod:`.fp_mul` share unpacking and classification (:func:`unpack`), the rounding of a
normalised significand with guard and sticky bits (:func:`round_significand`) and the
final packing with overflow, underflow and special values (:func:`pack`), so each rule of
the contract is written once.

The normalised intermediate result that :func:`round_significand` and :func:`pack` work
on is ``(sign, exp, sig, guard, sticky)``: ``sig`` is ``M+1`` bits with the leading one
at bit ``M``, ``exp`` the *biased* exponent of ``sig`` (a signed value), ``guard`` the
first bit below ``sig`` and ``sticky`` the OR of all bits below the guard bit (of the
exact result). Exponent expressions grow with each operation (Amaranth widens sums and
differences), so they never wrap.
"""

from __future__ import annotations

from typing import NamedTuple

from amaranth.hdl import Cat, Const, Mux, Value

from ..fp.format import FLAG_INVALID, FLAG_OVERFLOW, FLAG_UNDERFLOW, FPFormat, check_format

__all__ = ["Unpacked", "check_format", "unpack", "leading_zeros",
           "shift_right_sticky", "round_significand", "round_significand_ranged",
           "exponent_range", "pack"]


class Unpacked(NamedTuple):
    """Fields and class of one operand (all Amaranth values).

    Attributes
    ----------
    sign : 1 bit
    exp : E bits, the biased exponent field
    sig : M+1 bits, the significand with its hidden one; 0 for a zero (or denormal pattern)
    mag : E+M bits, exponent and fraction as one unsigned integer that orders magnitudes
        (a denormal pattern counts as zero)
    is_zero, is_inf, is_nan : 1 bit each
    """

    sign: Value
    exp: Value
    sig: Value
    mag: Value
    is_zero: Value
    is_inf: Value
    is_nan: Value


def unpack(fmt: FPFormat, bits) -> Unpacked:
    """Split a bit pattern into fields and classify it (denormal patterns are zeros)."""
    bits = Value.cast(bits)
    m, e = fmt.man_bits, fmt.exp_bits
    frac = bits[:m]
    exp = bits[m:m + e]
    sign = bits[m + e]
    is_zero = exp == 0
    exp_ones = exp == fmt.exp_max_field
    frac_z = Mux(is_zero, 0, frac)
    return Unpacked(
        sign=sign,
        exp=exp,
        sig=Cat(frac_z, ~is_zero),
        mag=Cat(frac_z, exp),
        is_zero=is_zero,
        is_inf=exp_ones & (frac == 0),
        is_nan=exp_ones & (frac != 0),
    )


def leading_zeros(value) -> tuple[Value, Value]:
    """Count the leading zeros of ``value`` with a tree of 2:1 multiplexers.

    Returns
    -------
    (count, all_zero)
        ``count`` (unsigned, wide enough for the width) equals the number of zero bits
        above the most significant one; when ``all_zero`` is set it is undefined.
    """
    value = Value.cast(value)
    width = len(value)
    levels = max(1, (width - 1).bit_length())
    # Pad at the bottom to a power of two; padding only matters when value is zero.
    padded = Cat(Const(0, (1 << levels) - width), value) if (1 << levels) > width else value

    def tree(v, k):  # v has 2**k bits; returns (count: k bits, zero)
        if k == 0:
            return Const(0, 0), ~v[0]
        half = 1 << (k - 1)
        c_hi, z_hi = tree(v[half:], k - 1)
        c_lo, z_lo = tree(v[:half], k - 1)
        count = Mux(z_hi, Cat(c_lo, Const(1, 1)), Cat(c_hi, Const(0, 1)))
        return count, z_hi & z_lo

    count, zero = tree(padded, levels)
    return count, zero


def shift_right_sticky(value, amount, limit: int | None = None) -> tuple[Value, Value]:
    """Shift ``value`` right by ``amount`` and OR every bit shifted out into a sticky bit.

    ``amount`` is clamped to ``limit`` (default: the width of ``value``, which shifts
    everything out), so an exponent difference of any size can be passed in.

    Returns
    -------
    (shifted, sticky)
        ``shifted`` has the width of ``value``.
    """
    value = Value.cast(value)
    width = len(value)
    limit = width if limit is None else limit
    amount = Value.cast(amount)
    clamped = Mux(amount > limit, limit, amount)
    wide = Cat(Const(0, width), value) >> clamped
    return wide[width:], wide[:width] != 0


def _round_up(fmt: FPFormat, sig, guard, sticky) -> tuple[Value, Value]:
    """``rne``'s round-up of ``sig``: the rounded ``M+1`` bits and the carry out of them."""
    m = fmt.man_bits
    up = guard & (sticky | sig[0])
    total = sig + up  # m + 2 bits
    carry = total[m + 1]
    return Mux(carry, Const(1 << m, m + 1), total[:m + 1]), carry


def round_significand(fmt: FPFormat, sig, exp, guard, sticky) -> tuple[Value, Value]:
    """Round a normalised significand to ``M+1`` bits by the format's rounding.

    ``rtz`` and ``chop`` keep ``sig``; ``rne`` adds one when the guard bit is set and
    either the sticky bit or the last bit of ``sig`` is (ties to even). A carry out of the
    significand gives ``1.000...`` with the exponent raised by one.

    Returns
    -------
    (sig, exp)
        The rounded significand (leading one at bit ``M``) and its exponent (one bit
        wider than ``exp`` for ``rne``).
    """
    sig, exp = Value.cast(sig), Value.cast(exp)
    if fmt.rounding != "rne":
        return sig, exp
    sig, carry = _round_up(fmt, sig, guard, sticky)
    return sig, exp + carry


def round_significand_ranged(fmt: FPFormat, sig, exp, guard,
                             sticky) -> tuple[Value, Value, Value, Value]:
    """:func:`round_significand`, with :func:`pack`'s range tests of the rounded exponent.

    The tests are made on ``exp`` and on ``exp + 1`` beside the round-up's carry chain, and
    the carry only picks one (``exp + carry >= K`` is ``exp >= K - carry``), so a pipeline
    register between this and :func:`pack` (given ``exp_range=(overflow, underflow)``) leaves
    ``pack`` without a comparison: its stage is the result multiplexer alone.

    Returns
    -------
    (sig, exp, overflow, underflow)
    """
    sig, exp = Value.cast(sig), Value.cast(exp)
    if fmt.rounding != "rne":
        return (sig, exp) + exponent_range(fmt, exp)
    sig, carry = _round_up(fmt, sig, guard, sticky)
    overflow = Mux(carry, exp >= fmt.exp_max_field - 1, exp >= fmt.exp_max_field)
    underflow = Mux(carry, exp <= -1, exp <= 0)
    return sig, exp + carry, overflow, underflow


def exponent_range(fmt: FPFormat, exp) -> tuple[Value, Value]:
    """``(overflow, underflow)`` of a rounded exponent: ``exp >= 2**E - 1``, ``exp <= 0``."""
    exp = Value.cast(exp)
    return exp >= fmt.exp_max_field, exp <= 0


def pack(fmt: FPFormat, *, sign, exp, sig, zero, inf, nan, invalid,
         exp_range=None) -> tuple[Value, Value]:
    """Assemble the result bit pattern and the event flags.

    Priority: ``nan`` (canonical NaN; ``invalid`` raises the invalid flag), then ``inf``
    (infinity of ``sign``), then ``zero`` (exact zero of ``sign``, no flag), then the
    rounded finite result: overflow (``exp >= 2**E - 1``) gives the signed max finite value
    for ``rtz`` and ``chop`` and the signed infinity for ``rne``; underflow (``exp <= 0``)
    gives the signed zero; each raises its flag. ``exp_range``, when given, is
    ``(overflow, underflow)``: those two tests made earlier (:func:`round_significand_ranged`).

    Returns
    -------
    (bits, flags)
        ``W`` bits and 3 flag bits (``FLAG_OVERFLOW | FLAG_UNDERFLOW | FLAG_INVALID``).
    """
    m, e, w = fmt.man_bits, fmt.exp_bits, fmt.width
    exp = Value.cast(exp)
    overflow, underflow = exponent_range(fmt, exp) if exp_range is None else exp_range
    normal = Cat(Value.cast(sig)[:m], exp[:e], sign)
    signed_zero = Cat(Const(0, w - 1), sign)
    big = Cat(Const(fmt.inf if fmt.rounding == "rne" else fmt.max_finite, w - 1), sign)
    bits = Mux(nan, Const(fmt.nan, w),
           Mux(inf, Cat(Const(fmt.inf, w - 1), sign),
           Mux(zero, signed_zero,
           Mux(overflow, big,
           Mux(underflow, signed_zero, normal)))))
    finite = ~(nan | inf | zero)
    events = {FLAG_OVERFLOW: finite & overflow,
              FLAG_UNDERFLOW: finite & ~overflow & underflow,
              FLAG_INVALID: nan & invalid}
    flags = Cat(*(events[1 << i] for i in range(3)))
    return bits, flags
