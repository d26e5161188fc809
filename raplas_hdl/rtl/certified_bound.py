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

Every function returns a combinational value; the caller places the registers.
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

    def rnd_add(self, m, a, b, s):
        """Rounding error bound of ``s = a + b`` (operand patterns as the adder sees them;
        signs do not matter)."""
        f = self.fmt
        opz = self.is_zero(a) | self.is_zero(b)
        sz = self.is_zero(s)
        if f.rounding == "chop":
            ea, eb, es = self._exp(a), self._exp(b), self._exp(s)
            top = Signal(signed(self.ew), name=f"top{self._n}")
            tab = Mux(ea > eb, ea, eb)
            m.d.comb += top.eq(Mux(~sz & (es > tab), es, tab))
            ulp = self.pow2(m, "ct", top - f.man_bits)
            zero_case = self.add_pow2(m, top - f.man_bits, 1 - f.bias)
            r = Signal(self.layout, name=f"brc{self._n}")
            m.d.comb += r.eq(Mux(sz, zero_case, ulp))
            return self._new(m, "ra", opz | r.z, r.e, r.f)
        e = Mux(sz, 1 - f.bias, self._ulp_exp(s))
        return self._new(m, "ra", opz, e, 0)

    # -- arithmetic, rounding up ---------------------------------------------------------
    def add(self, m, a, b):
        """``a + b`` rounded up to ``k + 1`` significant bits."""
        k = self.k
        swap = b.e > a.e
        hi = Signal(self.layout, name=f"bhi{self._n}")
        lo = Signal(self.layout, name=f"blo{self._n}")
        m.d.comb += [hi.eq(Mux(swap, b, a)), lo.eq(Mux(swap, a, b))]
        d = Signal(self.ew + 1, name=f"bd{self._n}")
        m.d.comb += d.eq(hi.e - lo.e)
        dd = Mux(d > k + 1, k + 1, d)
        ext = Cat(Const(0, k + 1), lo.f, Const(1, 1)) >> dd      # lo's significand, shifted
        bpart = ext[k + 1:]
        sticky = ext[:k + 1] != 0
        s = Signal(k + 2, name=f"bs{self._n}")
        m.d.comb += s.eq(Cat(hi.f, Const(1, 1)) + bpart)
        big = s[k + 1]
        mant = Mux(big, s[1:], s[:k + 1])
        rup = Mux(big, s[0] | sticky, sticky)
        mr = Signal(k + 2, name=f"bmr{self._n}")
        m.d.comb += mr.eq(mant + rup)
        carry = mr[k + 1]
        both = self._new(m, "add", 0, hi.e + big + carry, Mux(carry, 0, mr[:k]))
        r = Signal(self.layout, name=f"bsum{self._n}")
        m.d.comb += r.eq(Mux(a.z, b, Mux(b.z, a, both)))
        return r

    def add_pow2(self, m, ea, eb):
        """``2**ea + 2**eb`` rounded up (what :meth:`add` gives, without its adders):
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

    def mul(self, m, a, b):
        """``a * b`` rounded up to ``k + 1`` significant bits (the significand product as
        shifted partial products: no multiplier cell)."""
        k = self.k
        ma = Cat(a.f, Const(1, 1))
        pp = [Mux(b.f[i], ma << i, 0) for i in range(k)] + [ma << k]
        prod = Signal(2 * k + 2, name=f"bp{self._n}")
        m.d.comb += prod.eq(sum(pp[1:], pp[0]))
        big = prod[2 * k + 1]
        mant = Mux(big, prod[k + 1:], prod[k:2 * k + 1])
        rup = Mux(big, prod[:k + 1] != 0, prod[:k] != 0)
        mr = Signal(k + 2, name=f"bmr{self._n}")
        m.d.comb += mr.eq(mant + rup)
        carry = mr[k + 1]
        return self._new(m, "mul", a.z | b.z, a.e + b.e + big + carry, Mux(carry, 0, mr[:k]))

    # -- the outcome's comparisons -------------------------------------------------------
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
