"""The certified mode's bounds and outcome as z3 terms: the reference of the composition
proof (:mod:`.composition`) in ``mode="certified"``.

A bound float of the model (:mod:`raplas_hdl.model.certified`) is a non-negative value of
``k + 1`` significant bits, and every operation on bounds rounds the exact result **up**.
That is SMT-LIB's FloatingPoint arithmetic with roundTowardPositive into a sort of ``k + 1``
significand bits. z3's ``fpa2bv`` adds only in sorts with at least as many significand bits
as exponent bits, so each operation rounds up in a wider sort first (:attr:`BoundReference.sort`,
which also holds every pattern's value exactly) and then to ``k + 1`` bits: rounding up
twice is rounding up once (the first result lies between the exact one and the second's).
The exponent is wide enough that no bound is subnormal or infinite.

Each leaf term is written from the model's function of the same name (``_upper``, ``_ulp``,
``_input_bound``, ``_rnd_mul``, ``_rnd_add``, ``_classify``, ``_outcome``), not from the
gateware (:mod:`raplas_hdl.rtl.certified_bound`). The bounds of products and sums
(:meth:`BoundReference.mul_b`, :meth:`~BoundReference.add_b`) are the model's formulas with
the two exact steps the gateware leaves out where an operand is exact: ``x * 0 = 0`` and
``0 + x = x``.

Two forms of the bound operations (:meth:`~BoundReference.chain_add`,
:meth:`~BoundReference.chain_mul`):

- :class:`BoundReference`: the model's own arithmetic (rounding up), so the reference can be
  folded on the golden model's operations and compared with the model (the tests);
- :class:`CutBounds`: each bound sum and product a fresh variable, a bound float in the
  gateware's encoding (``f``, ``e``, ``z``, zero canonical: :meth:`~CutBounds.canonical`),
  where the composition proof cuts the gateware's two-stage bound operators; that those
  operators round up as the model does is proved apart (:func:`bound_operator_goal`).

No Amaranth.
"""

from __future__ import annotations

import z3

from ..fp.format import FPFormat
from ..model.certified import INPUT_SLACK_EXP, VARIANTS
from ..model.ordering import tight_bits

__all__ = ["BoundReference", "CutBounds", "bound_layout", "bound_operator_goal"]


def bound_layout(fmt: FPFormat, k: int) -> tuple[int, int]:
    """``(k, ew)`` of the gateware's bound float (:class:`~raplas_hdl.rtl.certified_bound.
    BoundOps`): ``f`` in bits ``[0, k)``, the signed exponent ``e`` in ``[k, k + ew)``, ``z``
    at ``k + ew``."""
    return k, fmt.exp_bits + 4


class BoundReference:
    """The model's bound arithmetic for the patterns of ``fmt`` (``W``-bit z3 terms).

    Parameters
    ----------
    fmt : FPFormat
        The datapath's format and rounding.
    variant : str
        The bound variant (``"exp"``, the gateware's).
    """

    def __init__(self, fmt: FPFormat, variant: str = "exp"):
        j, k = VARIANTS[variant]
        if j != 0:
            raise ValueError(f"the bound reference is written for j = 0 (the exp variant), "
                             f"not variant {variant!r}")
        self.fmt, self.k = fmt, k
        self.ew = bound_layout(fmt, k)[1]
        #: exponent bits: float64's, and room for the exact product of any two values
        #: of the gateware's encoding (``ew``-bit exponents)
        self.eb = max(11, self.ew + 2)
        #: the sort of every value here: a bound, a product of two, a pattern's value
        self.sort = z3.FPSort(self.eb, max(fmt.man_bits + 1, 2 * k + 2, self.eb))
        #: a bound float's own precision, ``k + 1`` bits
        self.narrow = z3.FPSort(self.eb, k + 1)
        self.iw = self.eb + 4            # signed exponent arithmetic
        self.zero = z3.FPVal(0.0, self.sort)

    # -- exponents and powers of two ----------------------------------------------------
    def _num(self, v):
        return z3.BitVecVal(v, self.iw)

    def _field(self, x):
        f = self.fmt
        return z3.Extract(f.man_bits + f.exp_bits - 1, f.man_bits, x)

    def is_zero(self, x):
        """A zero or denormal pattern (a denormal is zero)."""
        return self._field(x) == 0

    def exp(self, x):
        """Unbiased exponent of the pattern's field (signed, :attr:`iw` bits)."""
        return z3.ZeroExt(self.iw - self.fmt.exp_bits, self._field(x)) - self._num(self.fmt.bias)

    def _biased(self, e):
        return z3.Extract(self.eb - 1, 0, e + self._num(2 ** (self.eb - 1) - 1))

    def pow2(self, e):
        """``2**e`` of a signed exponent term ``e`` (:attr:`iw` bits, in range)."""
        return z3.fpFP(z3.BitVecVal(0, 1), self._biased(e),
                       z3.BitVecVal(0, self.sort.sbits() - 1))

    def eta(self):
        """``2**emin``, the flushed value."""
        return self.pow2(self._num(1 - self.fmt.bias))

    # -- rounding up -----------------------------------------------------------------------
    def _up(self, x):
        """``x`` (a non-negative value of :attr:`sort`) rounded up to ``k + 1`` bits."""
        return z3.fpToFP(z3.RNE(), z3.fpToFP(z3.RTP(), x, self.narrow), self.sort)  # exact

    def badd(self, a, b):
        """``a + b`` rounded up to ``k + 1`` bits."""
        return self._up(z3.fpAdd(z3.RTP(), a, b))

    def bmul(self, a, b):
        """``a * b`` rounded up to ``k + 1`` bits (exact in :attr:`sort` before)."""
        return self._up(z3.fpMul(z3.RTP(), a, b))

    # -- the chain's form of a bound (here the value itself) ----------------------------
    def lift(self, x):
        """A leaf bound (a value of :attr:`sort`) in the chain's form."""
        return x

    def lower(self, x):
        """A bound of the chain as a value of :attr:`sort`."""
        return x

    def chain_add(self, a, b):
        return self.badd(a, b)

    def chain_mul(self, a, b):
        return self.bmul(a, b)

    # -- the model's leaf terms ---------------------------------------------------------
    def upper(self, x):
        """``U(x) = 2**(ex + 1)``, 0 for a zero pattern."""
        return z3.If(self.is_zero(x), self.zero, self.pow2(self.exp(x) + 1))

    def ulp(self, x):
        """ulp of a pattern that is not zero (rne: half of it)."""
        half = 1 if self.fmt.rounding == "rne" else 0
        return self.pow2(self.exp(x) - self._num(self.fmt.man_bits + half))

    def input_bound(self, x, slack: bool):
        """Bound of an encoded input: ulp (rne: ulp/2), eta for a zero pattern; with
        ``slack`` times ``1 + 2**-INPUT_SLACK_EXP`` rounded up."""
        b = z3.If(self.is_zero(x), self.eta(), self.ulp(x))
        if slack:
            tiny = z3.fpMul(z3.RNE(), b, self.pow2(self._num(-INPUT_SLACK_EXP)))   # exact
            b = self.badd(b, tiny)
        return self.lift(b)

    def rnd_mul(self, p):
        """Rounding error bound of a product ``p``."""
        return z3.If(self.is_zero(p), self.eta(), self.ulp(p))

    def _smax(self, a, b):
        return z3.If(a > b, a, b)                # signed: z3's > on bit vectors is

    def rnd_add(self, a, b, s):
        """Rounding error bound of ``s = a + b`` (operands as the adder sees them; a sign
        changes neither their zero test nor their exponent)."""
        m = self._num(self.fmt.man_bits)
        if self.fmt.rounding == "chop":          # ulp of the largest
            top = self._smax(self.exp(a), self.exp(b))
            nonzero = self.pow2(self._smax(top, self.exp(s)) - m)
            zero_sum = self.badd(self.pow2(top - m), self.eta())
        else:
            nonzero, zero_sum = self.ulp(s), self.eta()
        return z3.If(z3.Or(self.is_zero(a), self.is_zero(b)), self.zero,
                     z3.If(self.is_zero(s), zero_sum, nonzero))

    # -- bounds of the operations (the gateware's order of the model's terms) ---------------
    def mul_b(self, a, ba, b, bb, p):
        """Bound of ``p = mul(a, b)``: ``U(a) B_b + (U(b) + B_b) B_a + rnd``; ``bb`` None
        (``b`` exact): ``U(b) B_a + rnd``."""
        if bb is None:
            acc = self.chain_mul(self.lift(self.upper(b)), ba)
        else:
            t1 = self.chain_mul(self.lift(self.upper(a)), bb)
            t2 = self.chain_mul(self.chain_add(self.lift(self.upper(b)), bb), ba)
            acc = self.chain_add(t1, t2)
        return self.chain_add(acc, self.lift(self.rnd_mul(p)))

    def add_b(self, a, ba, b, bb, s):
        """Bound of ``s = add(a, b)``: ``B_a + B_b + rnd``; ``bb`` None (``b`` exact):
        ``B_a + rnd``."""
        acc = ba if bb is None else self.chain_add(ba, bb)
        return self.chain_add(acc, self.lift(self.rnd_add(a, b, s)))

    # -- comparisons and the outcome ----------------------------------------------------
    def value(self, x):
        """The value of a pattern, exactly (a denormal is zero)."""
        f = self.fmt
        pad = self.sort.sbits() - 1 - f.man_bits
        man = z3.Extract(f.man_bits - 1, 0, x)
        if pad:
            man = z3.Concat(man, z3.BitVecVal(0, pad))
        finite = z3.fpFP(z3.Extract(f.width - 1, f.width - 1, x), self._biased(self.exp(x)),
                         man)
        return z3.If(self.is_zero(x), self.zero, finite)

    def classify(self, x, g, scale_exp: int = 0):
        """``(ge, gt, le, lt)``: the value of ``x`` against the bound value ``g`` times
        ``2**scale_exp`` and its negation (the model's ``_classify``)."""
        v = self.value(x)
        big = g
        if scale_exp:
            big = z3.fpMul(z3.RNE(), big, self.pow2(self._num(scale_exp)))     # exact
        return (z3.fpGEQ(v, big), z3.fpGT(v, big), z3.fpLEQ(v, z3.fpNeg(big)),
                z3.fpLT(v, z3.fpNeg(big)))

    def outcome(self, vals: dict, bounds: dict, overflow):
        """``(outcome, tight)`` of the results ``vals`` (``det, t, u, v, w``: patterns),
        their bounds (the chain's form) and ``overflow`` (a Bool: an operation raised it):
        2 (uncertain) for a special result or an overflow, else the model's ``_outcome``
        (1 hit, 0 miss, 2); ``tight``: a hit whose ``t'`` and ``det`` are each at least
        ``2**q`` times their bounds (``q`` = :func:`~raplas_hdl.model.ordering.tight_bits`)."""
        f = self.fmt
        emf = f.exp_max_field
        special = z3.Or(*(self._field(x) == emf for x in vals.values()))
        g = {k: self.lower(b) for k, b in bounds.items()}
        cl = {k: self.classify(vals[k], g[k]) for k in vals}
        ge, gt, le, lt = ({k: c[i] for k, c in cl.items()} for i in range(4))
        names = ("u", "v", "w", "t")
        chit = z3.Or(z3.And(gt["det"], *(ge[k] for k in names)),
                     z3.And(lt["det"], *(le[k] for k in names)))
        cmiss = z3.And(z3.Or(le["det"], *(lt[k] for k in names)),
                       z3.Or(ge["det"], *(gt[k] for k in names)))
        two, one, nil = (z3.BitVecVal(v, 2) for v in (2, 1, 0))
        outcome = z3.If(z3.Or(special, overflow), two,
                        z3.If(chit, one, z3.If(cmiss, nil, two)))
        q = tight_bits(f)

        def tight(k):
            c = self.classify(vals[k], g[k], q)
            return z3.Or(c[0], c[2])

        return outcome, z3.And(outcome == one, tight("t"), tight("det"))


class CutBounds(BoundReference):
    """:class:`BoundReference` with each bound sum and product a fresh variable (``bop<i>``)
    in the gateware's encoding, listed in :attr:`applied` as ``(kind, a, b, result)`` in
    the order the formula applies them: the composition proof cuts the unit's bound
    operations there, matched one to one in that order (the unit builds them in the same
    order), instead of leaving a solver to pair up applications of a function.

    The leaves (``U``, the rounding terms, the input bounds) are still the model's, encoded
    (:meth:`encode`); the outcome reads each bound's value (:meth:`decode`)."""

    def __init__(self, fmt: FPFormat, variant: str = "exp"):
        super().__init__(fmt, variant)
        self.width = self.k + self.ew + 1
        self.applied = []

    def canonical(self, x):
        """The encoded bound ``x`` with ``e`` and ``f`` cleared when ``z`` is set."""
        return z3.If(z3.Extract(self.width - 1, self.width - 1, x) == 1,
                     z3.BitVecVal(1 << (self.width - 1), self.width), x)

    def encode(self, v):
        """A bound value (of :attr:`sort`, zero or ``k + 1`` significant bits) in the
        gateware's encoding, zero canonical, the exponent's low ``ew`` bits."""
        k, ew = self.k, self.ew
        bits = z3.fpToIEEEBV(v)
        sb = self.sort.sbits() - 1
        f = z3.Extract(sb - 1, sb - k, bits)
        biased = z3.Extract(sb + self.eb - 1, sb, bits)
        e = z3.Extract(ew - 1, 0, biased - z3.BitVecVal(2 ** (self.eb - 1) - 1, self.eb))
        return z3.If(z3.fpIsZero(v), z3.BitVecVal(1 << (self.width - 1), self.width),
                     z3.Concat(z3.BitVecVal(0, 1), e, f))

    def decode(self, x):
        """The value of an encoded bound (``z`` set: zero)."""
        k, ew = self.k, self.ew
        z = z3.Extract(k + ew, k + ew, x)
        e = z3.SignExt(self.iw - ew, z3.Extract(k + ew - 1, k, x))
        f = z3.Extract(k - 1, 0, x)
        pad = self.sort.sbits() - 1 - k
        sig = z3.Concat(f, z3.BitVecVal(0, pad)) if pad else f
        return z3.If(z == 1, self.zero, z3.fpFP(z3.BitVecVal(0, 1), self._biased(e), sig))

    def lift(self, x):
        return self.encode(x)

    def lower(self, x):
        return self.decode(x)

    def _apply(self, kind, a, b):
        v = z3.BitVec(f"bop{len(self.applied)}", self.width)
        self.applied.append((kind, a, b, v))
        return v

    def chain_add(self, a, b):
        return self._apply("add", a, b)

    def chain_mul(self, a, b):
        return self._apply("mul", a, b)


def bound_operator_goal(fmt: FPFormat, kind: str, out, a, b, variant: str = "exp"):
    """The negation of "the gateware's bound operator rounds up as the model does":
    satisfiable exactly when, for some operands ``a``, ``b`` (encoded bound terms), the
    operator's result ``out`` is not, once canonical, the encoding of the model's rounded-up
    sum or product of their values (:meth:`CutBounds.encode`, which keeps the
    exponent's low ``ew`` bits, as the gateware's exponent arithmetic does). Unsatisfiable
    makes the result a function of the operands' canonical forms, the premise of the cut
    (:class:`CutBounds`), and the model's operation wherever the exponent stays in
    the encoding's range (every bound of a pair does: :mod:`raplas_hdl.rtl.certified_bound`)."""
    ref = CutBounds(fmt, variant)
    op = ref.badd if kind == "add" else ref.bmul
    return ref.canonical(out) != ref.encode(op(ref.decode(a), ref.decode(b)))
