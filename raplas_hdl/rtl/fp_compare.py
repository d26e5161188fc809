"""The contract's ordered comparisons and negation: as logic for a unit to use inline, and
as small units of their own that ``raplas-hdl verilog`` emits and ``raplas-hdl prove``
proves.

``docs/fp-format.md``: ``le(a, b)`` and ``lt(a, b)`` are the ordered comparisons of the
values (any NaN operand gives false, +0 equals -0, a denormal pattern compares as zero);
``neg(x)`` flips the sign bit of a non-NaN ``x`` and gives the canonical NaN for a NaN.
The ray-triangle unit's decision is made of these (:mod:`.ray_triangle` calls
:func:`le`, :func:`lt` and :func:`neg`), so the units below are the same logic alone:

:class:`FPCompare` (``fp-le``, ``fp-lt``)
    ``o = le(a, b)`` or ``lt(a, b)`` on a register, as the ray-triangle unit registers each
    comparison: latency 1.
:class:`FPNeg` (``fp-neg``)
    ``o = neg(a)`` on a register: latency 1 (the ray-triangle unit uses it without one).

Both have the FP units' handshake: ``i_valid`` and the operands are taken on a clock edge
with ``en``, ``o_valid`` follows; a clock edge without ``en`` changes nothing.
"""

from __future__ import annotations

from amaranth.hdl import Const, Module, Mux, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..fp.format import FPFormat, check_format

__all__ = ["is_nan", "compare", "le", "lt", "neg", "FPCompare", "FPNeg", "COMPARISONS"]

#: The comparisons :class:`FPCompare` builds.
COMPARISONS = ("le", "lt")


def is_nan(v: Value, fmt: FPFormat) -> Value:
    """Whether the pattern ``v`` is a NaN (exponent all ones, fraction not zero)."""
    return (v[fmt.man_bits:fmt.width - 1] == fmt.exp_max_field) & (v[:fmt.man_bits] != 0)


def compare(m: Module, a: Value, b: Value, fmt: FPFormat, strict: bool) -> Value:
    """``key(a) <= key(b)`` (``<`` if ``strict``) of the contract's ordering key, where a
    zero or denormal pattern (exponent field 0) is +0 and the key is ``0``, ``-mag`` or
    ``+mag``; NaNs are not excluded here (:func:`le`, :func:`lt` do).

    Both raw magnitude comparisons run straight from the operands, side by side; the zero
    flags, the signs and the choice between them follow in one small function of six bits.
    (A zero test and a sign mux in front of one comparison put two carry chains in series:
    the whole intersection unit's critical path at speed 8 on an ECP5.)"""
    f = fmt
    za, zb = (v[f.man_bits:f.width - 1] == 0 for v in (a, b))
    sa, sb = a[f.width - 1] & ~za, b[f.width - 1] & ~zb
    a_le_b, b_le_a = Signal(), Signal()
    m.d.comb += [a_le_b.eq(a[:f.width - 1] <= b[:f.width - 1]),
                 b_le_a.eq(b[:f.width - 1] <= a[:f.width - 1])]
    # both nonzero with one sign: the magnitudes' order, flipped when both are negative
    mag = Mux(sa, ~a_le_b, ~b_le_a) if strict else Mux(sa, b_le_a, a_le_b)
    return Mux(za & zb, Const(int(not strict), 1),
               Mux(za, ~sb, Mux(zb, sa, Mux(sa ^ sb, sa, mag))))


def le(m: Module, a: Value, b: Value, fmt: FPFormat) -> Value:
    """The contract's ``le(a, b)`` as a combinational value."""
    return ~is_nan(a, fmt) & ~is_nan(b, fmt) & compare(m, a, b, fmt, strict=False)


def lt(m: Module, a: Value, b: Value, fmt: FPFormat) -> Value:
    """The contract's ``lt(a, b)`` as a combinational value."""
    return ~is_nan(a, fmt) & ~is_nan(b, fmt) & compare(m, a, b, fmt, strict=True)


def neg(v: Value, fmt: FPFormat) -> Value:
    """The contract's ``neg(v)``: the sign bit flipped, the canonical NaN for a NaN."""
    return Mux(is_nan(v, fmt), fmt.nan, v ^ fmt.sign_bit)


class FPCompare(wiring.Component):
    """``o = le(a, b)`` (``op="le"``) or ``lt(a, b)`` (``op="lt"``), registered.

    Parameters
    ----------
    fmt : FPFormat
    op : {"le", "lt"}

    Members
    -------
    a, b : In(W)
    i_valid, en : In(1)
    o : Out(1)
    o_valid : Out(1)
    latency : int
        1.
    """

    def __init__(self, fmt: FPFormat, op: str = "le"):
        self.fmt = check_format(fmt)
        if op not in COMPARISONS:
            raise ValueError(f"op must be one of {', '.join(COMPARISONS)}, not {op!r}")
        self.op = op
        self.latency = 1
        w = self.fmt.width
        super().__init__({"a": In(w), "b": In(w), "i_valid": In(1), "en": In(1),
                          "o": Out(1), "o_valid": Out(1)})

    def elaborate(self, platform):
        m = Module()
        fn = le if self.op == "le" else lt
        value = Signal()
        m.d.comb += value.eq(fn(m, self.a, self.b, self.fmt))
        with m.If(self.en):
            m.d.sync += [self.o.eq(value), self.o_valid.eq(self.i_valid)]
        return m


class FPNeg(wiring.Component):
    """``o = neg(a)``, registered.

    Parameters
    ----------
    fmt : FPFormat

    Members
    -------
    a : In(W)
    i_valid, en : In(1)
    o : Out(W)
    o_valid : Out(1)
    latency : int
        1.
    """

    def __init__(self, fmt: FPFormat):
        self.fmt = check_format(fmt)
        self.latency = 1
        w = self.fmt.width
        super().__init__({"a": In(w), "i_valid": In(1), "en": In(1), "o": Out(w),
                          "o_valid": Out(1)})

    def elaborate(self, platform):
        m = Module()
        with m.If(self.en):
            m.d.sync += [self.o.eq(neg(self.a, self.fmt)), self.o_valid.eq(self.i_valid)]
        return m


def build_fp_le(fmt: FPFormat) -> FPCompare:
    """The ``fp-le`` unit of the registry."""
    return FPCompare(fmt, "le")


def build_fp_lt(fmt: FPFormat) -> FPCompare:
    """The ``fp-lt`` unit of the registry."""
    return FPCompare(fmt, "lt")
