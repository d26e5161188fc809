"""FP adder/subtractor whose shifts and significand add run in two Virtex-4 ``DSP48``.

Bit for bit the generic :class:`~.fp_add.FPAdd` (``docs/fp-format.md``) in ``rtz``, ``rne``
and ``chop``, flags included, for formats whose significand fits one DSP48 operand
(``M+1 <= 17``: FP16, FP20, FP24 and the small test formats; FP32 is refused). Selected with
``FPAdd(fmt, target="virtex4")``.

Notation: ``N = M+1`` significand bits, ``x``/``y`` the larger/smaller operand's significand,
``d`` their exponent difference, ``D = min(16, M+2)`` the alignment scale.

**DSP48 #1, align and add** (``P = C +- (A*B + CARRYIN)``, ``OPMODE`` Z=C, X=Y=M): the
alignment right shift is a multiplication by a power of two. ``A = y``, ``B = 2^(D-d)``
(a one-hot from a small decoder) and ``C = x * 2^D``, so the post-adder forms the *exact*
sum or difference ``x*2^D +- y*2^(D-d)`` with every bit shifted out of ``y`` kept in the
low ``D`` bits of ``P``, no sticky logic. Two cases need more than a 17-bit one-hot:

* ``D < d <= M+2`` (only when ``M+2 > 16``: FP24, ``d`` = 17 or 18): ``y`` is pre-shifted
  right by ``M+3-D`` bits in the fabric (a 2:1 multiplexer), ``B = 2^(M+3-d) >= 2``, and
  the OR of the dropped bits goes in as ``CARRYIN``;
* ``d >= M+3`` (``y`` lies wholly below the guard bit): ``B = 0`` and ``CARRYIN`` = "y is
  not zero".

``CARRYIN`` adds (or, with ``SUBTRACT``, takes) one unit of ``P``'s last place. Without
it ``P`` is a multiple of ``2^k`` and the exact result lies strictly between ``P`` and the
next multiple of ``2^k`` in the direction of ``y``'s sign: after a pre-shift ``k`` is the
weight of ``B``'s lowest possible bit, ``k >= 1`` (hence ``B >= 2``); for ``d >= M+3`` the
dropped ``y`` is below ``2^(D-2)``, so take ``k = D-2``. With ``k >= 1`` the carry-in puts
``P`` strictly inside that interval, and the interval holds no rounding boundary:
``k <= D-2``, while the result's guard bit weighs at least ``2^(D-2)`` (these sums need at
most one place of left normalisation). So the correct rounding of ``P`` equals that of the
exact result, which is what the generic adder computes with its floor-and-sticky datapath.

``chop`` drops ``y``'s bits below its own last place before the add. For an addition that
is ``floor(P / 2^D)``; for a subtraction ``x - floor(y/2^d) = ceil(x - y/2^d)``, so ``C``
gets ``2^D - 1`` added (constant low bits) and ``P``'s low ``D`` bits are ignored.

**DSP48 #2, normalise and round** (same ``OPMODE``): the leading one of ``P`` is either
in the top three places (the *far* case: a carry, no shift, or one place lost in a
subtraction; every addition and every subtraction with ``d >= 2``) or lower (the *near*
case: a subtraction with ``d <= 1``, which is exact, the bits of ``P`` below ``2^(D-1)``
being zero). The far case is a 3:1 multiplexer in the fabric (significand, guard and
sticky bits) and goes to the DSP48 as ``C``, its ``rne`` round-up bit as ``CARRYIN``. The near
case's left shift is a multiplication: ``A`` = the ``M`` bits of ``P`` below the top three
places, ``B = 2^j`` with ``j`` from the leading-zero count. The far case sets ``B = 0``, the
near case ``C = 0``, so ``P`` is the rounded significand of either (a carry out of the
rounding shows in bit ``N``).

Stages (latency 7 for every format and rounding; ``en`` holds every register, the
DSP48's included):

1. ``unpack`` (classify, order, exponent difference, as the generic adder) and
   ``operands`` (pre-shift, one-hot decoder): ``A``/``B`` into DSP #1's ``AREG``/``BREG``;
   ``C``, ``SUBTRACT``, ``CARRYIN`` and the fields the result needs into fabric registers;
2. DSP #1's ``MREG``, and ``CREG``/``SUBTRACTREG``/``CARRYINREG``;
3. DSP #1's ``PREG``: the aligned sum ``P``;
4. ``classify``: leading-zero count of ``P``'s top ``N+2`` bits, the near-case operands
   into DSP #2's ``AREG``/``BREG``; far significand, guard, sticky and the exponent
   ``exp(x) + 1 - count`` into fabric registers;
5. ``round``: the far significand and its round-up bit into DSP #2's ``CREG`` and
   ``CARRYINREG``; DSP #2's ``MREG``;
6. DSP #2's ``PREG``: the rounded significand;
7. ``pack``: a rounding carry, then overflow, underflow, exact zero and the specials
   (:func:`.fp_common.pack`) on the output registers.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux
from amaranth.lib import wiring

from .dsp48 import LIMB, dsp48
from .fp_add_front import adder_ports, classify_and_order
from .fp_common import check_format, leading_zeros, pack
from .pipeline import Step, build_pipeline, delay, wire

__all__ = ["FPAddDSP48", "LATENCY", "check_dsp48_format", "STAGE_STEPS"]

#: Enabled clock edges from operands to result (every supported format and rounding).
LATENCY = 7

#: The steps of each pipeline stage (a DSP48 register stage has none of its own).
STAGE_STEPS = (("unpack", "operands"), ("dsp48-add",), ("dsp48-add",), ("classify",),
               ("round", "dsp48-normalise"), ("dsp48-normalise",), ("pack",))

#: Largest alignment scale: the one-hot ``2^D`` must fit a DSP48 operand (17 bits).
_SCALE = LIMB - 1

_CARRIED = ("sign_x", "zero_sign", "exp_x", "nan", "invalid", "inf")


def check_dsp48_format(fmt):
    """Return ``fmt`` if its significand fits one DSP48 operand (``M+1 <= 17``).

    Raises
    ------
    ValueError
        For a bad format or one with more than 16 fraction bits.
    """
    fmt = check_format(fmt)
    if fmt.man_bits + 1 > LIMB:
        raise ValueError(f"the DSP48 adder (target='virtex4') takes significands of at most "
                         f"{LIMB} bits (man_bits <= {LIMB - 1}, e.g. FP16, FP20, FP24), not "
                         f"{fmt.man_bits + 1} ({fmt.name})")
    return fmt


class FPAddDSP48(wiring.Component):
    """``o = a + b`` (``sub`` = 0) or ``a - b`` (1) on two DSP48; see the module docstring.

    Same ports, stall and valid behaviour as :class:`~.fp_add.FPAdd`; ``latency`` is 7.
    Build it through ``FPAdd(fmt, target="virtex4")``.

    Parameters
    ----------
    fmt : FPFormat
        Format (``man_bits <= 16``) and rounding.

    Raises
    ------
    ValueError
        If the format is bad or its significand is wider than 17 bits.
    """

    def __init__(self, fmt):
        self._fmt = check_dsp48_format(fmt)
        m = fmt.man_bits
        self._scale = min(_SCALE, m + 2)
        # pre-shift of y for D < d <= M+2, so that B >= 2 there (see the module docstring)
        self._pre = m + 3 - self._scale if m + 2 > self._scale else 0
        super().__init__(adder_ports(fmt.width))

    @property
    def fmt(self):
        return self._fmt

    @property
    def latency(self) -> int:
        return LATENCY

    # -- combinational steps -----------------------------------------------------------
    def _step_unpack(self, m, v):
        # The generic adder's classification and ordering, unchanged (one definition).
        return classify_and_order(self._fmt, m, v)

    def _step_operands(self, m, v):
        """DSP #1 operands: ``A`` (y, maybe pre-shifted), ``B`` (one-hot), ``C``, carry-in."""
        fmt, big, pre = self._fmt, self._scale, self._pre
        man = fmt.man_bits
        d = wire(m, v["diff"], "d")
        sig_y = v["sig_y"]
        # bit i of B is set when d == D - i, or (pre-shifted y) when d == D + pre - i
        onehot = []
        for i in range(big + 1):
            hit = d == big - i
            if i < pre:
                hit = hit | (d == big + pre - i)
            onehot.append(hit)
        shifted = d > big
        a = Mux(shifted, sig_y >> pre, sig_y) if pre else sig_y
        if fmt.rounding == "chop":
            cin = Const(0, 1)
        else:
            far = d > man + 2
            lost = sig_y[:pre].any() if pre else Const(0, 1)
            cin = Mux(far, sig_y[man], shifted & lost)
        return {**{k: v[k] for k in _CARRIED}, "dsp_a": a, "dsp_b": Cat(*onehot),
                "sig_x": v["sig_x"], "eff_sub": v["eff_sub"], "cin": cin}

    def _step_addend(self, m, v):
        """DSP #1's ``C = x * 2^D`` (``chop`` subtraction: ``+ 2^D - 1``), ``SUBTRACT``,
        ``CARRYIN``; one clock after its ``A``/``B``."""
        big = self._scale
        low = v["eff_sub"].replicate(big) if self._fmt.rounding == "chop" else Const(0, big)
        return {**{k: v[k] for k in _CARRIED}, "dsp_c": Cat(low, v["sig_x"]),
                "dsp_sub": v["eff_sub"], "dsp_cin": v["cin"]}

    def _step_classify(self, m, v):
        """Leading zeros of the sum; near-case DSP #2 operands; far significand and bits."""
        fmt, big = self._fmt, self._scale
        man, n = fmt.man_bits, fmt.man_bits + 1
        p = v["p"][:big + n + 1]
        if fmt.rounding == "chop":
            p = Cat(Const(0, big), p[big:])
        p = wire(m, p, "sum")
        count, zero = leading_zeros(p[big - 1:])             # N+2 bits
        count = wire(m, count, "lzc")
        far = count < 3
        # far case: the significand from the leading one (a carry, none, one place lost)
        sig = Mux(count == 0, p[big + 1:], Mux(count == 1, p[big:big + n], p[big - 1:big + n - 1]))
        out = {**{k: v[k] for k in _CARRIED if k != "exp_x"},
               "zero": zero, "exp": v["exp_x"] + 1 - count,
               "far_sig": Mux(far, sig[:n], 0),
               # near case: the M bits below the top three places, times 2^(count-2)
               "dsp_a": p[big - 1:big + man - 1],
               "dsp_b": Cat(Const(0, 1), *(count == j + 2 for j in range(1, man + 1)))}
        if fmt.rounding == "rne":
            s2 = p[:big - 2].any()
            s1 = s2 | p[big - 2]
            s0 = s1 | p[big - 1]
            out["guard"] = far & Mux(count == 0, p[big], Mux(count == 1, p[big - 1], p[big - 2]))
            out["sticky"] = Mux(count == 0, s0, Mux(count == 1, s1, s2))
        return out

    def _step_round(self, m, v):
        """DSP #2's ``C`` (the far significand) and carry-in (its ``rne`` round-up bit)."""
        keep = {k: v[k] for k in v if k not in ("far_sig", "guard", "sticky")}
        if self._fmt.rounding == "rne":
            up = v["guard"] & (v["sticky"] | v["far_sig"][0])
        else:
            up = Const(0, 1)
        return {**keep, "dsp_c": v["far_sig"], "dsp_cin": up}

    def _step_pack(self, m, v):
        fmt = self._fmt
        man, n = fmt.man_bits, fmt.man_bits + 1
        total = v["p"][:n + 1]
        carry = total[n]           # only a round-up of 1.11..1 carries out
        sig = Mux(carry, Const(1 << man, n), total[:n])
        bits, flags = pack(fmt, sign=Mux(v["zero"], v["zero_sign"], v["sign_x"]),
                           exp=v["exp"] + carry, sig=sig, zero=v["zero"], inf=v["inf"],
                           nan=v["nan"], invalid=v["invalid"])
        return {"bits": bits, "flags": flags}

    # -- pipeline ------------------------------------------------------------------------
    def _dsp_stage(self, m, name, v, valid, late_step):
        """One DSP48 stage: ``v["dsp_a"]``/``v["dsp_b"]`` into ``A``/``B`` now; the other
        fields one clock later through ``late_step``, whose ``dsp_c``/``dsp_sub``/``dsp_cin``
        go to ``C``/``SUBTRACT``/``CARRYIN``; the rest and the valid bit level with ``P``."""
        en = self.en
        late = {k: delay(m, x, 1, en=en, name=f"{name}_{k}") for k, x in v.items()
                if k not in ("dsp_a", "dsp_b")}
        valid = delay(m, valid, 1, en=en, name=f"{name}_valid", reset_less=False)
        late, valid = build_pipeline(m, [late_step], late, (), en=en, valid=valid)
        p = dsp48(m, name, v["dsp_a"], v["dsp_b"], en=en, c=late["dsp_c"],
                  subtract=late.get("dsp_sub", 0), carryin=late["dsp_cin"])
        rest = {k: delay(m, x, 2, en=en, name=f"{name}_{k}_p") for k, x in late.items()
                if not k.startswith("dsp_")}
        valid = delay(m, valid, 2, en=en, name=f"{name}_valid_p", reset_less=False)
        return {**rest, "p": p}, valid

    def elaborate(self, platform):
        m = Module()
        en = self.en
        front = [Step("unpack", self._step_unpack), Step("operands", self._step_operands)]
        v, valid = build_pipeline(m, front, {"a": self.a, "b": self.b, "sub": self.sub}, (),
                                  en=en, valid=self.i_valid)
        v, valid = self._dsp_stage(m, "dsp_add", v, valid, Step("addend", self._step_addend))
        v, valid = build_pipeline(m, [Step("classify", self._step_classify)], v, (),
                                  en=en, valid=valid)
        v, valid = self._dsp_stage(m, "dsp_norm", v, valid, Step("round", self._step_round))
        out, valid = build_pipeline(m, [Step("pack", self._step_pack)], v, (0,),
                                    en=en, valid=valid)
        m.d.comb += [self.o.eq(out["bits"]), self.flags.eq(out["flags"]),
                     self.o_valid.eq(valid)]
        return m
