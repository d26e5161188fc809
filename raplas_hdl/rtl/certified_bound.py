"""Bound floats of the certified mode in gateware: the running error bounds beside the FP
datapath (:mod:`raplas_hdl.model.certified`, ``docs/certified-mode.md``).

A bound float is a non-negative number ``(1 + f / 2**k) * 2**e`` or zero: ``k`` fraction
bits ``f``, a signed exponent ``e`` (``exp_bits + 4`` bits: every bound of a pair in the
certified domain, and outside it, fits) and a zero bit ``z``. Every operator here rounds
**up** to ``k + 1`` significant bits, exactly as the model's ``_badd`` / ``_bmul`` round
the exact result in float64, so the gateware's bounds equal the model's bit for bit.
No multiplier is inferred: the ``(k+1) x (k+1)`` significand product is a sum of shifted
partial products (a few LUTs), the rest is exponent arithmetic.

Only the ``exp`` variant (``j = 0``: ``U(x) = 2**(ex+1)``) has a gateware form so far.

Every function returns a combinational value; the caller places the registers. The two
operators and chop's rounding term come in two halves, so that a caller can put a register
between them (each half a few short carry chains, to meet the FP units' clock):

- ``add = add_sum(align(a, b))``: exponent differences and both orders' shifts side by
  side, the larger exponent | the significand sum plus 0, 1 and 2 and the exponent plus
  0, 1 and 2 side by side, the rounded sum and the exponent chosen;
- ``mul = mul_round(mul_product(a, b))``: the partial-product sum and the exponent sum |
  rounding up and the exponent sum plus 0, 1 and 2, the exponent chosen;
- ``rnd_add = rnd_add_finish(rnd_add_top(rnd_add_operands(a, b), s))``: what the term
  needs of the operands, taken as they enter the adder | what it needs of the sum |
  the term (:attr:`BoundOps.rnd_add_stages`: the last two want a register between them
  in chop, which takes the largest of three exponents and adds two powers of two).

The first halves read each operand's exponent into as few carry chains as they can (the
differences, or the sum): an operand's register then has few loads to be placed near, which
is what the certified whole unit's clock wanted (``docs/pnr.md``).
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import data

from ..fp.format import FPFormat

__all__ = ["RTL_VARIANTS", "BoundOps"]

#: The bound variants the gateware implements (keys of ``model.certified.VARIANTS``).
RTL_VARIANTS = ("exp",)


class BoundOps:
    """The bound-float operators of one format (combinational, into module ``m``).

    Parameters
    ----------
    fmt : FPFormat
        The FP datapath's format and rounding.
    k : int
        Fraction bits of a bound float.
    """

    def __init__(self, fmt: FPFormat, k: int):
        self.fmt = fmt
        self.k = k
        self.ew = fmt.exp_bits + 4
        self.layout = data.StructLayout({"f": k, "e": signed(self.ew), "z": 1})
        self._n = 0

    # -- construction --------------------------------------------------------------------
    def _new(self, m: Module, name: str, z, e, f):
        self._n += 1
        r = Signal(self.layout, name=f"b{name}{self._n}")
        m.d.comb += [r.z.eq(z), r.e.eq(e), r.f.eq(f)]
        return r

    def view(self, value):
        """A packed bound (``Value``) as a view with ``f``, ``e``, ``z``."""
        return data.View(self.layout, value)

    @property
    def width(self) -> int:
        return self.layout.size

    # -- what a pattern tells ------------------------------------------------------------
    def _field(self, x):
        f = self.fmt
        return x[f.man_bits:f.man_bits + f.exp_bits]

    def _exp(self, x):
        """Unbiased exponent of a pattern's field, as a signed value."""
        return Cat(self._field(x), Const(0, 2)).as_signed() - self.fmt.bias

    def is_zero(self, x):
        return self._field(x) == 0

    def pow2(self, m, name, e, z=0):
        return self._new(m, name, z, e, 0)

    def eta(self, m):
        """``2**emin`` (a flushed value)."""
        return self.pow2(m, "eta", 1 - self.fmt.bias)

    def upper(self, m, x):
        """``U(x) = 2**(ex+1)`` (``exp`` variant), zero for a zero pattern."""
        return self.pow2(m, "u", self._exp(x) + 1, z=self.is_zero(x))

    def _ulp_exp(self, x):
        """Exponent of the rounding error of a result ``x``: ulp, halved under rne."""
        f = self.fmt
        return self._exp(x) - f.man_bits - (1 if f.rounding == "rne" else 0)

    def input_bound(self, m, x, slack: bool):
        """Bound of an encoded input (the model's ``_input_bound``): ulp (rne: ulp/2), eta
        for a zero pattern; with ``slack`` times ``1 + 2**-20`` rounded up (fraction 1)."""
        e = Mux(self.is_zero(x), 1 - self.fmt.bias, self._ulp_exp(x))
        return self._new(m, "in", 0, e, 1 if slack else 0)

    def rnd_mul(self, m, p):
        """Rounding error bound of a product ``p``: ulp (rne: ulp/2), eta when zero."""
        return self.pow2(m, "rm", Mux(self.is_zero(p), 1 - self.fmt.bias, self._ulp_exp(p)))

    @property
    def rnd_add_stages(self) -> int:
        """Cycles the rounding term of an add wants (chop: a register between
        :meth:`rnd_add_top` and :meth:`rnd_add_finish`)."""
        return 2 if self.fmt.rounding == "chop" else 1

    @property
    def operand_layout(self):
        """What :meth:`rnd_add_operands` hands to :meth:`rnd_add_top`: whether an operand is
        zero (``opz``), and in chop the larger operand exponent field ``f`` and the term's
        exponent built on it (``fe``)."""
        fields = {"opz": 1}
        if self.fmt.rounding == "chop":
            fields["f"] = self.fmt.exp_bits
            fields["fe"] = signed(self.ew)
        return data.StructLayout(fields)

    @property
    def top_layout(self):
        """What :meth:`rnd_add_top` hands to :meth:`rnd_add_finish`."""
        return data.StructLayout({"e": signed(self.ew), "sz": 1, "opz": 1})

    def rnd_add_operands(self, m, a, b):
        """What the rounding term of ``a + b`` needs of the operands (taken when they enter
        the adder, so that only these few bits wait for the sum)."""
        self._n += 1
        r = Signal(self.operand_layout, name=f"bopd{self._n}")
        m.d.comb += r.opz.eq(self.is_zero(a) | self.is_zero(b))
        if self.fmt.rounding == "chop":          # the larger field is the larger exponent
            fa, fb = self._field(a), self._field(b)
            a_larger = fa > fb           # beside both exponents, then one choice
            m.d.comb += [r.f.eq(Mux(a_larger, fa, fb)),
                         r.fe.eq(Mux(a_larger, self._chop_exp(fa), self._chop_exp(fb)))]
        return r

    def _chop_exp(self, field):
        """chop's rounding-term exponent built on an exponent field: ``field - bias - M``."""
        f = self.fmt
        return Cat(field, Const(0, 2)).as_signed() - f.bias - f.man_bits

    def rnd_add_top(self, m, opnd, s):
        """First half of the rounding term, from :meth:`rnd_add_operands`' record ``opnd``
        and the sum ``s``: zero bits, and the exponent the term is built on (chop: the
        largest of the operands' and, unless zero, the sum's, less the fraction bits; else
        the ulp exponent of ``s``)."""
        f = self.fmt
        self._n += 1
        r = Signal(self.top_layout, name=f"btop{self._n}")
        sz = self.is_zero(s)
        if f.rounding == "chop":
            # the compare and the sum's exponent side by side, then one choice (the
            # operands' exponent came with them)
            fs = self._field(s)
            e = Mux(~sz & (fs > opnd.f), self._chop_exp(fs), opnd.fe)
        else:
            e = self._ulp_exp(s)
        m.d.comb += [r.e.eq(e), r.sz.eq(sz), r.opz.eq(opnd.opz)]
        return r

    def rnd_add_finish(self, m, top):
        """The rounding error bound of ``s = a + b`` (operand patterns as the adder sees them;
        signs do not matter), from :meth:`rnd_add_top`'s record ``top``."""
        f = self.fmt
        if f.rounding == "chop":
            ulp = self.pow2(m, "ct", top.e)
            zero_case = self.add_pow2(m, top.e, 1 - f.bias)
            r = Signal(self.layout, name=f"brc{self._n}")
            m.d.comb += r.eq(Mux(top.sz, zero_case, ulp))
            return self._new(m, "ra", top.opz | r.z, r.e, r.f)
        return self._new(m, "ra", top.opz, Mux(top.sz, 1 - f.bias, top.e), 0)

    # -- arithmetic, rounding up ---------------------------------------------------------
    @property
    def align_layout(self):
        """What :meth:`align` hands to :meth:`add_sum`: the larger operand's ``f`` and
        ``e``, the smaller's shifted significand ``lo`` and ``sticky``, and, when an operand
        is zero (``zero``), the other (``pass_``), which is the sum."""
        k = self.k
        return data.StructLayout({"f": k, "e": signed(self.ew), "lo": k + 1,
                                  "sticky": 1, "zero": 1, "pass_": self.layout})

    def align(self, m, a, b):
        """First half of a bound sum ``a + b``, rounded up to ``k + 1`` significant bits:
        order the operands by exponent and shift the smaller
        one's significand (its bits beyond ``k + 1`` ORed into ``sticky``). Both orders are
        shifted side by side and the exponent compare chooses after the shift.

        The shifter takes the difference's low ``nb`` bits only, which arrive first: a
        shift of ``k + 1`` up to ``2**nb - 1 <= 2k + 1`` already leaves ``lo`` zero and
        the leading one in ``sticky``. A difference of ``2**nb`` or more, known last (the
        chains' high bits), zeroes ``lo`` and sets ``sticky`` after the shifter, not
        before it."""
        k = self.k
        ew = self.ew
        nb = (k + 1).bit_length()                  # 2**(nb-1) <= k + 1: see above
        self._n += 1
        n = self._n

        def shifted(f, d):
            """``f``'s significand shifted right by ``d``'s low bits: ``(lo, sticky)``."""
            ext = Cat(Const(0, k + 1), f, Const(1, 1)) >> d[:nb]
            return ext[k + 1:], ext[:k + 1] != 0

        dab = Signal(signed(ew + 1), name=f"bdab{n}")
        dba = Signal(signed(ew + 1), name=f"bdba{n}")
        m.d.comb += [dab.eq(a.e - b.e), dba.eq(b.e - a.e)]
        swap = dab[-1]                             # b.e > a.e: b is the larger
        lo_a, st_a = shifted(b.f, dab)             # a the larger
        lo_b, st_b = shifted(a.f, dba)
        over = Signal(name=f"bov{n}")              # the larger's difference >= 2**nb
        m.d.comb += over.eq(Mux(swap, dba[nb:] != 0, dab[nb:] != 0))
        r = Signal(self.align_layout, name=f"bal{n}")
        m.d.comb += [r.f.eq(Mux(swap, b.f, a.f)), r.e.eq(Mux(swap, b.e, a.e)),
                     r.lo.eq(Mux(over, 0, Mux(swap, lo_b, lo_a))),
                     r.sticky.eq(over | Mux(swap, st_b, st_a)),
                     r.zero.eq(a.z | b.z), r.pass_.eq(Mux(a.z, b, a))]
        return r

    def add_sum(self, m, x):
        """Second half of a bound sum, from :meth:`align`'s record ``x``."""
        k = self.k
        # the significand sum ``s`` and ``s + 1``, ``s + 2`` side by side (three short carry
        # chains in parallel, not the sum's chain and then the round-up's): rounded up,
        # the sum is one of them, or one of them halved (``s >= 2**(k+1)``)
        n = self._n
        s0, s1, s2 = (Signal(k + 3, name=f"bs{c}_{n}") for c in range(3))
        a = Cat(x.f, Const(1, 1))
        m.d.comb += [s0.eq(a + x.lo), s1.eq(a + x.lo + 1), s2.eq(a + x.lo + 2)]
        big = s0[k + 1]
        mr = Signal(k + 2, name=f"bmr{n}")
        m.d.comb += mr.eq(Mux(big, Mux(s0[0], s1[1:], Mux(x.sticky, s2[1:], s0[1:])),
                              Mux(x.sticky, s1, s0)))
        carry = mr[k + 1]
        both = self._new(m, "add", 0, self._bump(m, x, big, carry), Mux(carry, 0, mr[:k]))
        r = Signal(self.layout, name=f"bsum{self._n}")
        m.d.comb += r.eq(Mux(x.zero, x.pass_, both))
        return r

    def add_pow2(self, m, ea, eb):
        """``2**ea + 2**eb`` rounded up (what :meth:`align` and :meth:`add_sum` give, without
        their adders):
        ``2**(hi+1)`` if equal, else ``2**hi (1 + 2**-d)`` with ``d = |ea - eb|``, the
        fraction rounded up to ``2**-k`` beyond ``k``."""
        k = self.k
        hi = Signal(signed(self.ew), name=f"bph{self._n}")
        d = Signal(self.ew + 1, name=f"bpd{self._n}")
        m.d.comb += [hi.eq(Mux(ea > eb, ea, eb)), d.eq(Mux(ea > eb, ea - eb, eb - ea))]
        frac = Const(1, k)
        for i in range(k, 0, -1):                 # d = i: fraction 2**(k-i)
            frac = Mux(d == i, 1 << (k - i), frac)
        return self._new(m, "p2", 0, hi + (d == 0), Mux(d == 0, 0, frac))

    @property
    def product_layout(self):
        """What :meth:`mul_product` hands to :meth:`mul_round`: the significand product
        ``p``, the exponent sum ``e``, the zero bit ``z``."""
        return data.StructLayout({"p": 2 * self.k + 2, "e": signed(self.ew), "z": 1})

    def mul_product(self, m, a, b):
        """First half of a bound product ``a * b``, rounded up to ``k + 1`` significant bits:
        the significand product (shifted partial products: no
        multiplier cell) and the exponent sum."""
        k = self.k
        ma = Cat(a.f, Const(1, 1))
        pp = [Mux(b.f[i], ma << i, 0) for i in range(k)] + [ma << k]
        self._n += 1
        r = Signal(self.product_layout, name=f"bpr{self._n}")
        m.d.comb += [r.p.eq(sum(pp[1:], pp[0])), r.e.eq(a.e + b.e), r.z.eq(a.z | b.z)]
        return r

    def mul_round(self, m, x):
        """Second half of a bound product, from :meth:`mul_product`'s record ``x``."""
        k = self.k
        prod = x.p
        big = prod[2 * k + 1]
        mant = Mux(big, prod[k + 1:], prod[k:2 * k + 1])
        rup = Mux(big, prod[:k + 1] != 0, prod[:k] != 0)
        mr = Signal(k + 2, name=f"bmr{self._n}")
        m.d.comb += mr.eq(mant + rup)
        carry = mr[k + 1]
        return self._new(m, "mul", x.z, self._bump(m, x, big, carry), Mux(carry, 0, mr[:k]))

    def _bump(self, m, x, big, carry):
        """``x.e + big + carry``: ``x.e`` plus 0, 1 and 2 in chains of their own beside the
        significand's, then a choice after them, not an add."""
        e1 = Signal(signed(self.ew), name=f"be1_{self._n}")
        e2 = Signal(signed(self.ew), name=f"be2_{self._n}")
        m.d.comb += [e1.eq(x.e + 1), e2.eq(x.e + 2)]
        return Mux(big & carry, e2, Mux(big | carry, e1, x.e))

    # -- the outcome's comparisons -------------------------------------------------------
    def tight(self, x, g, q: int):
        """``|x| >= 2**q g`` (the model's ``_classify(x, g * 2**q)``: its ``ge | le``; a
        denormal pattern is zero): ``x`` is known to a relative ``2**-q``
        (:mod:`raplas_hdl.model.ordering`)."""
        f = self.fmt
        k = self.k
        ex = self._exp(x)
        man = x[:f.man_bits]
        gman = Cat(Const(0, f.man_bits - k), g.f)
        ge_ = g.e + q
        mag_ge = g.z | (ex > ge_) | ((ex == ge_) & (man >= gman))
        return Mux(self.is_zero(x), g.z, mag_ge)

    def classify(self, x, g):
        """``(ge, gt, le, lt)`` of the pattern ``x`` against the bound ``g`` (the model's
        ``_classify``; a denormal pattern is zero)."""
        f = self.fmt
        k = self.k
        xz = self.is_zero(x)
        sign = x[f.width - 1]
        ex = self._exp(x)
        man = x[:f.man_bits]
        gman = Cat(Const(0, f.man_bits - k), g.f)
        above = (ex > g.e) | ((ex == g.e) & (man > gman))
        mag_gt = g.z | above
        mag_ge = g.z | above | ((ex == g.e) & (man == gman))
        ge = Mux(xz, g.z, ~sign & mag_ge)
        le = Mux(xz, g.z, sign & mag_ge)
        gt = ~xz & ~sign & mag_gt
        lt = ~xz & sign & mag_gt
        return ge, gt, le, lt
