"""Pipelined floating-point multiplier, bit for bit as ``docs/fp-format.md``.

The significand product is exact (``2M+2`` bits from one ``(M+1) x (M+1)`` unsigned
multiply in :class:`SigMul`, a single DSP48 at FP24), so truncating it with guard and
sticky bits is a correct rounding; ``chop`` is ``rtz`` for the multiplier.

The five combinational steps, in order:

``unpack``
    Classify both operands, the sign of the product (xor), the special results (NaN
    operand, zero times infinity, infinity, zero) and the biased exponent sum
    ``exp(a) + exp(b) - bias``. Hands on: both significands (the raw fraction under a
    hidden 1, not flushed: when an operand is zero, denormal, infinite or NaN the product
    is not used), the sign, the exponent, the specials.
``multiply``
    The ``2M+2``-bit significand product (:class:`SigMul`).
``normalise``
    The product lies in ``[1, 4)``: if its top bit is set the significand is the top
    ``M+1`` bits and the exponent goes up by one, otherwise the next ``M+1``; the bit below
    is the guard bit, the OR of the rest the sticky bit.
``round``
    Round the significand by the format's rounding (:func:`.fp_common.round_significand`);
    in ``rne`` also test the rounded exponent's range, for ``exp`` and ``exp + 1`` beside
    the round-up's carry chain (:func:`.fp_common.round_significand_ranged`).
``pack``
    Overflow, underflow (tested here in ``rtz`` and ``chop``), specials; the bit pattern
    and the event flags (:func:`.fp_common.pack`).

Pipeline registers go behind the steps chosen by :func:`.pipeline.place_registers` from
each step's delay as placed and routed on an ECP5 (:mod:`.step_delays`, which adds to
``normalise`` the product's route out of the multiplier block). The default stage count is
the fewest whose slowest stage meets the table's target: 4 in ``rtz`` and ``chop``, 5 in
``rne``. FP24 ``rtz``, 4 stages:

1. ``unpack``: the operands classified, the exponent sum and the two significands on
   registers (the multiplier block's input registers once the ECP5 flow has moved them in,
   :mod:`raplas_hdl.pnr.dsp_registers`; a DSP48's input registers);
2. ``multiply``: the product on a register (the block's output register);
3. ``normalise`` + ``round``: the product leaves the block, is normalised (and in ``rne``,
   where ``round`` gets a stage of its own, rounded);
4. ``pack``: the result and its flags, on the output registers.

(The paper's multiplier has 3 stages, ``normalise`` to ``pack`` in one: on the LFE5U-85F that
stage, with the route out of the block, was the whole unit's critical path at 96 MHz.)

``stages`` can be anything from 1 (all five steps in one clock) to 5 (one step each).

**Multiplier target.** ``multiplier="generic"`` (the default) is the above: the multiply
is :class:`SigMul`, an inferred ``a * b``. ``multiplier="virtex4"`` replaces it with
:class:`~.dsp48.DSP48Mul`, Virtex-4 ``DSP48`` primitives with their own pipeline registers
in use, and re-plans the pipeline around it:

1. ``unpack`` feeds the DSP48's operand registers (``AREG``/``BREG``) directly; the
   fields that ride beside the product (sign, exponent, specials) and the valid bit go
   into fabric registers that stay level with the DSP48;
2. ``multiply``: the product register (``MREG``);
3. the DSP48's output register (``PREG``); at FP32 (24-bit significands, four DSP48) one
   more stage adds the limb products (:func:`.dsp48.multiplier_latency`);
4. ``normalise``, ``round``, ``pack`` with the registers that the generic plan of the same
   ``stages`` puts behind the multiply (at least the output register).

So ``latency = multiplier_latency(M+1) + (registers behind the multiply)``: 5 at FP24 with
the default ``stages=4`` in ``rtz`` (the generic unit's 4, plus ``PREG``), 6 at FP32;
:func:`fp_mul_latency` gives it without building the unit. Every DSP48 register has its
clock enable on ``en``, so a stall holds the whole unit as in the generic one.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from .dsp48 import LIMB, DSP48Mul, multiplier_latency
from .fp_common import (check_format, pack, round_significand, round_significand_ranged,
                        unpack)
from .pipeline import Step, build_pipeline, delay, group_steps, place_registers
from .step_delays import DEFAULT_STAGES, step_weights

__all__ = ["FPMul", "SigMul", "MULTIPLIERS", "MUL_STEPS", "fp_mul_latency", "mul_weights",
           "default_mul_stages"]

#: Significand-multiplier targets of :class:`FPMul`.
MULTIPLIERS = ("generic", "virtex4")

#: The combinational steps, in datapath order (their weights: :mod:`.step_delays`).
MUL_STEPS = ("unpack", "multiply", "normalise", "round", "pack")

_CARRIED = ("sign", "exp", "nan", "invalid", "inf", "zero")

#: Index of the ``multiply`` step in :data:`MUL_STEPS`.
_MULTIPLY = 1


def check_multiplier(multiplier) -> str:
    """Return ``multiplier`` if it is a known target, else raise ``ValueError``."""
    if multiplier not in MULTIPLIERS:
        raise ValueError(f"multiplier must be one of {', '.join(MULTIPLIERS)}, "
                         f"not {multiplier!r}")
    return multiplier


def mul_weights(fmt) -> list[int]:
    """The measured weight of each step of :data:`MUL_STEPS` in ``fmt``'s rounding."""
    return step_weights("fp_mul", check_format(fmt).rounding, MUL_STEPS)


def default_mul_stages(fmt) -> int:
    """The default stage count of ``FPMul(fmt)``: 4 in ``rtz`` and ``chop``, 5 in ``rne``
    (:data:`.step_delays.DEFAULT_STAGES`)."""
    return DEFAULT_STAGES["fp_mul"][check_format(fmt).rounding]


def _plan(fmt, stages, multiplier):
    """``(stages, generic registered steps, latency)`` of an :class:`FPMul`."""
    if stages is None:
        stages = default_mul_stages(fmt)
    registered = place_registers(mul_weights(fmt), stages)
    if check_multiplier(multiplier) == "generic":
        return stages, registered, stages
    width = fmt.man_bits + 1
    if width > 2 * LIMB:
        raise ValueError(f"multiplier='virtex4' handles significands of up to {2 * LIMB} "
                         f"bits, not {width} (man_bits={fmt.man_bits})")
    behind = sum(1 for i in registered if i > _MULTIPLY)
    return stages, registered, multiplier_latency(width) + behind


def fp_mul_latency(fmt, stages: int | None = None, multiplier: str = "generic") -> int:
    """Latency of ``FPMul(fmt, stages, multiplier)``, without building it.

    Raises
    ------
    ValueError
        As :class:`FPMul` does.
    """
    return _plan(check_format(fmt), stages, multiplier)[2]


class SigMul(wiring.Component):
    """The significand multiplier: ``p = a * b``, unsigned, combinational.

    The only multiplier of :class:`FPMul`, kept apart so that a target can replace it
    with a vendor primitive.

    Parameters
    ----------
    width : int
        Operand width (``M+1``).

    Attributes
    ----------
    a, b : In(width)
    p : Out(2 * width)
    """

    def __init__(self, width: int):
        if not isinstance(width, int) or isinstance(width, bool) or width < 1:
            raise ValueError(f"width must be a positive integer, not {width!r}")
        super().__init__({"a": In(width), "b": In(width), "p": Out(2 * width)})

    def elaborate(self, platform):
        m = Module()
        m.d.comb += self.p.eq(self.a * self.b)
        return m


class FPMul(wiring.Component):
    """Fully pipelined multiplier: ``o = a * b``.

    One operation per clock; the result of the operands presented with ``i_valid`` at an
    enabled clock edge appears on ``o``/``flags`` with ``o_valid`` after ``latency``
    enabled edges. While ``en`` is 0 every register holds (a stall).

    Parameters
    ----------
    fmt : FPFormat
        Format and rounding (``rtz``, ``rne`` or ``chop``, which equals ``rtz`` here).
    stages : int
        Pipeline depth, 1 to 5 (default: 4, 5 in rne; :func:`default_mul_stages`). With
        ``multiplier="virtex4"`` it places the registers behind the multiply as in the
        generic unit (module docstring).
    multiplier : {"generic", "virtex4"}
        The significand multiply: an inferred ``a * b`` (:class:`SigMul`), or Virtex-4
        ``DSP48`` primitives with AREG/BREG/MREG/PREG (:class:`~.dsp48.DSP48Mul`).

    Attributes
    ----------
    a, b : In(W)
        Operands (bit patterns).
    i_valid : In(1)
        The operands are an operation.
    en : In(1)
        Clock enable for the whole pipeline.
    o : Out(W)
        Result bit pattern.
    flags : Out(3)
        Event flags of the result: ``FLAG_OVERFLOW``, ``FLAG_UNDERFLOW``, ``FLAG_INVALID``.
    o_valid : Out(1)
        ``o`` and ``flags`` belong to an operation.
    latency : int
        ``stages`` (generic); ``multiplier_latency(M+1)`` plus the registers behind the
        multiply (virtex4: 5 at FP24 rtz with the default ``stages=4``).

    Raises
    ------
    ValueError
        If ``fmt`` is not an :class:`FPFormat`, ``stages`` is out of range or
        ``multiplier`` is not a known target (or, for ``virtex4``, the significand is wider
        than 34 bits).
    """

    def __init__(self, fmt, stages: int | None = None, multiplier: str = "generic"):
        self._fmt = check_format(fmt)
        self._steps = tuple(Step(name, getattr(self, f"_step_{name}"), weight)
                            for name, weight in zip(MUL_STEPS, mul_weights(fmt)))
        stages, self._registered, self._latency = _plan(fmt, stages, multiplier)
        self._stages = stages
        self._multiplier = multiplier
        w = fmt.width
        super().__init__({
            "a": In(w), "b": In(w), "i_valid": In(1), "en": In(1),
            "o": Out(w), "flags": Out(3), "o_valid": Out(1),
        })

    @property
    def fmt(self):
        return self._fmt

    @property
    def stages(self) -> int:
        return self._stages

    @property
    def multiplier(self) -> str:
        return self._multiplier

    @property
    def latency(self) -> int:
        """Enabled clock edges from an input to its result (``stages`` for the generic
        multiplier; see the module docstring for ``virtex4``)."""
        return self._latency

    @property
    def stage_steps(self) -> tuple[tuple[str, ...], ...]:
        """The names of the combinational steps in each pipeline stage.

        With ``virtex4`` the DSP48's stages appear as ``("unpack",)`` (into ``AREG``/``BREG``),
        then ``("multiply",)`` for ``MREG``, ``PREG`` and, for four DSP48, the limb sum."""
        if self._multiplier == "generic":
            return group_steps(self._steps, self._registered)
        post = [i - _MULTIPLY - 1 for i in self._registered if i > _MULTIPLY]
        lat_m = multiplier_latency(self._fmt.man_bits + 1)
        return ((("unpack",),) + (("multiply",),) * (lat_m - 1)
                + group_steps(self._steps[_MULTIPLY + 1:], post))

    # -- combinational steps -----------------------------------------------------------
    def _step_unpack(self, m, v):
        fmt = self._fmt
        ua, ub = unpack(fmt, v["a"]), unpack(fmt, v["b"])
        any_nan = ua.is_nan | ub.is_nan
        zero_inf = (ua.is_zero & ub.is_inf) | (ua.is_inf & ub.is_zero)
        mb = fmt.man_bits
        return {
            "sign": ua.sign ^ ub.sign,
            "exp": ua.exp + ub.exp - fmt.bias,
            # Raw significands: a zero, denormal, infinite or NaN operand's product is never
            # used (``pack`` gives the special result), so no flush; their registers are
            # then plain, and the ECP5 flow can move them into the multiplier block.
            "sig_a": Cat(v["a"][:mb], Const(1, 1)),
            "sig_b": Cat(v["b"][:mb], Const(1, 1)),
            "nan": any_nan | zero_inf,
            "invalid": ~any_nan & zero_inf,
            "inf": ua.is_inf | ub.is_inf,
            "zero": ua.is_zero | ub.is_zero,
        }

    def _step_multiply(self, m, v):
        m.submodules.sigmul = sigmul = SigMul(self._fmt.man_bits + 1)
        m.d.comb += [sigmul.a.eq(v["sig_a"]), sigmul.b.eq(v["sig_b"])]
        return {**{k: v[k] for k in _CARRIED}, "prod": sigmul.p}

    def _step_normalise(self, m, v):
        mb = self._fmt.man_bits
        prod = v["prod"]
        top = prod[2 * mb + 1]
        norm = Mux(top, prod, prod << 1)[:2 * mb + 2]
        return {**{k: v[k] for k in _CARRIED}, "exp": v["exp"] + top,
                "sig": norm[mb + 1:], "guard": norm[mb], "sticky": norm[:mb].any()}

    def _step_round(self, m, v):
        fmt, carried = self._fmt, {k: v[k] for k in _CARRIED}
        if fmt.rounding != "rne":
            sig, exp = round_significand(fmt, v["sig"], v["exp"], v["guard"], v["sticky"])
            return {**carried, "sig": sig, "exp": exp}
        # rne: the range tests ride beside the round-up's carry chain, so ``pack``'s stage
        # is the result multiplexer alone (it held the certified ray-triangle unit, placed
        # and routed: 10.4 ns, 14 cells, from this stage's register to the output). rtz and
        # chop keep the tests in ``pack``, where no measured path has put them.
        sig, exp, overflow, underflow = round_significand_ranged(
            fmt, v["sig"], v["exp"], v["guard"], v["sticky"])
        return {**carried, "sig": sig, "exp": exp, "overflow": overflow,
                "underflow": underflow}

    def _step_pack(self, m, v):
        exp_range = (v["overflow"], v["underflow"]) if "overflow" in v else None
        bits, flags = pack(self._fmt, sign=v["sign"], exp=v["exp"], sig=v["sig"],
                           zero=v["zero"], inf=v["inf"], nan=v["nan"], invalid=v["invalid"],
                           exp_range=exp_range)
        return {"bits": bits, "flags": flags}

    def elaborate(self, platform):
        m = Module()
        if self._multiplier == "generic":
            out, valid = build_pipeline(m, self._steps, {"a": self.a, "b": self.b},
                                        self._registered, en=self.en, valid=self.i_valid)
        else:
            out, valid = self._virtex4_pipeline(m)
        m.d.comb += [self.o.eq(out["bits"]), self.flags.eq(out["flags"]),
                     self.o_valid.eq(valid)]
        return m

    def _virtex4_pipeline(self, m):
        """``unpack`` -> DSP48 (AREG/BREG, MREG, PREG) -> the steps behind the multiply."""
        en = self.en
        # unpack, combinational, straight into the DSP48's operand registers
        v, valid = build_pipeline(m, self._steps[:_MULTIPLY], {"a": self.a, "b": self.b},
                                  (), en=en, valid=self.i_valid)
        m.submodules.multiply = dsp = DSP48Mul(self._fmt.man_bits + 1)
        m.d.comb += [dsp.a.eq(v["sig_a"]), dsp.b.eq(v["sig_b"]), dsp.en.eq(en)]
        lat = dsp.latency
        carried = {k: delay(m, v[k], lat, en=en, name=f"{k}_dly") for k in _CARRIED}
        valid = delay(m, valid, lat, en=en, name="valid_dly", reset_less=False)
        post = [i - _MULTIPLY - 1 for i in self._registered if i > _MULTIPLY]
        return build_pipeline(m, self._steps[_MULTIPLY + 1:], {**carried, "prod": dsp.p},
                              post, en=en, valid=valid)
