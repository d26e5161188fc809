"""Pipelined floating-point adder/subtractor, bit for bit as ``docs/fp-format.md``.

Datapath (``M`` = fraction bits; significands are ``M+1`` bits with the hidden one). The
aligned sum is kept as a *floor with sticky*: an integer ``S`` with two bits below the
larger operand's last place plus a sticky bit that says the exact sum is a little above
``S``. When the smaller operand loses bits in alignment, the subtraction takes one more
unit off ``S`` (the floor of the exact difference), so truncating or rounding ``S`` with
its sticky bit is a correct rounding of the exact result. Those lost bits only occur when
the exponents differ by 3 or more, and then the difference needs at most one bit of left
normalisation, so two extra bits are enough for a guard bit after normalising.

The nine combinational steps, in order:

``classify``
    Classify both operands (``sub`` flips the sign of ``b``), compare their magnitudes
    (exponent, then significand), form both exponent differences side by side (each clamped
    to the alignment's width when a register follows, so that the comparison drives one
    multiplexer before the shifter), and work out the special results (NaN operand,
    inf - inf, infinity) and the sign of an exact zero sum.
``order``
    Order the operands by the comparison so that ``x`` is the larger, and pick the exponent
    difference ``d`` = ``exp(x) - exp(y)``. Hands on: ``x``'s sign, exponent and
    significand, ``y``'s significand, ``d``, whether the operation is an effective
    subtraction, the specials.
``align``
    Shift ``y``'s significand (with two zero bits appended, in a double-width window that
    loses no bit) right by ``d``'s multiple of four (``d`` clamped to the width).
``shift``
    The rest of the shift (``d mod 4``); the bits below the significand's window are ORed
    into a sticky bit. ``chop`` instead drops everything below ``y``'s own last bit, as the
    paper's adder does, and has no sticky bit.
``add``
    ``S = X + Y'`` or ``S = X - Y' - sticky``, ``M+4`` bits.
``lzc``
    Leading-zero count of ``S`` (a multiplexer tree) and its zero test.
``normalise``
    Barrel-shift ``S`` left by the count; the significand is the top ``M+1`` bits, the next
    bit the guard bit, the rest ORed with the alignment sticky bit; the exponent is
    ``exp(x) + 1 - count``.
``round``
    Round the significand by the format's rounding (:func:`.fp_common.round_significand`).
``pack``
    Overflow, underflow, exact zero, specials; the bit pattern and the event flags
    (:func:`.fp_common.pack`).

Pipeline registers go behind the steps chosen by :func:`.pipeline.place_registers` from
each step's delay as placed and routed on an ECP5 (:mod:`.step_delays`, measured by
``benchmarks/bench_pnr.py --steps``). The default stage count is the fewest whose slowest
stage meets the table's target (the prediction that keeps a whole intersection unit at 140
MHz at speed 8): 6 in ``rtz`` (the paper's adder had 4; with 5, ``lzc`` + ``normalise`` in
one stage held the whole unit to 136 MHz at speed 8), 7 in ``rne`` (its rounding increment
costs a stage), 5 in ``chop`` (its shift is shorter). FP24 ``rtz``, 6 stages:

1. ``classify``: operands classified;
2. ``order`` + ``align``: compared and ordered, the exponent difference picked, ``y``
   shifted by the difference's multiple of 4;
3. ``shift`` + ``add``: the rest of the shift, its sticky bit, the aligned sum ``S``;
4. ``lzc``: the leading-zero count of ``S``;
5. ``normalise`` + ``round``: the normalised significand, guard and sticky bits, exponent,
   the rounded result;
6. ``pack``: the result and its flags, on the output registers.

``stages`` can be anything from 1 (all nine steps in one clock) to 9 (one step each).

**Target.** ``target="generic"`` (the default) is the above, all in the fabric.
``target="virtex4"`` builds the adder of :mod:`.fp_add_dsp48` instead: the alignment shift,
the significand add and the normalising shift in two Virtex-4 ``DSP48`` primitives, bit for
bit the same results and flags, ``latency`` 7 whatever ``stages`` (which is still checked);
formats with ``man_bits <= 16`` only. ``multiplier=`` is accepted as another name for
``target`` (the keyword the unit registry and the FP units hand their ``target`` option
to). :func:`fp_add_latency` gives the latency without building the unit.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Value
from amaranth.lib import wiring

from .fp_add_dsp48 import LATENCY, STAGE_STEPS, FPAddDSP48, check_dsp48_format
from .fp_add_front import SPECIALS, adder_ports, classify, keep, order
from .fp_common import check_format, leading_zeros, pack, round_significand
from .pipeline import Step, build_pipeline, group_steps, place_registers, wire
from .step_delays import DEFAULT_STAGES, step_weights

__all__ = ["FPAdd", "TARGETS", "ADD_STEPS", "check_adder", "fp_add_latency", "add_weights",
           "default_add_stages"]

#: Adder targets: all in the fabric, or shifts and add in Virtex-4 DSP48 (:mod:`.fp_add_dsp48`).
TARGETS = ("generic", "virtex4")

#: The combinational steps, in datapath order (their weights: :mod:`.step_delays`).
ADD_STEPS = ("classify", "order", "align", "shift", "add", "lzc", "normalise", "round",
             "pack")

def _check_target(target, multiplier):
    if multiplier is not None:
        if target != "generic" and target != multiplier:
            raise ValueError(f"target={target!r} and multiplier={multiplier!r} disagree; "
                             "give one of them")
        target = multiplier
    if target not in TARGETS:
        raise ValueError(f"target must be one of {', '.join(TARGETS)}, not {target!r}")
    return target


def check_adder(adder) -> str:
    """Return ``adder`` if it is a known adder target (:data:`TARGETS`), else raise
    ``ValueError`` (the ``adder=`` keyword of the units that hold FP adders)."""
    if adder not in TARGETS:
        raise ValueError(f"adder must be one of {', '.join(TARGETS)}, not {adder!r}")
    return adder


def add_weights(fmt) -> list[int]:
    """The measured weight of each step of :data:`ADD_STEPS` in ``fmt``'s rounding."""
    return step_weights("fp_add", check_format(fmt).rounding, ADD_STEPS)


def default_add_stages(fmt) -> int:
    """The default stage count of ``FPAdd(fmt)``: 6 in ``rtz``, 7 in ``rne``, 5 in ``chop``
    (:data:`.step_delays.DEFAULT_STAGES`)."""
    return DEFAULT_STAGES["fp_add"][check_format(fmt).rounding]


def fp_add_latency(fmt, stages: int | None = None, target: str = "generic") -> int:
    """Latency of ``FPAdd(fmt, stages, target)``, without building it: ``stages`` (default
    :func:`default_add_stages`) for the generic adder, :data:`.fp_add_dsp48.LATENCY` (7) for
    ``virtex4``.

    Raises
    ------
    ValueError
        As :class:`FPAdd` does.
    """
    if stages is None:
        stages = default_add_stages(fmt)
    place_registers(add_weights(fmt), stages)
    if _check_target(target, None) == "virtex4":
        check_dsp48_format(fmt)
        return LATENCY
    check_format(fmt)
    return stages


class FPAdd(wiring.Component):
    """Fully pipelined adder/subtractor: ``o = a + b`` (``sub`` = 0) or ``a - b`` (1).

    One operation per clock; the result of the operands presented with ``i_valid`` at an
    enabled clock edge appears on ``o``/``flags`` with ``o_valid`` after ``latency``
    enabled edges. While ``en`` is 0 every register holds (a stall), inputs are not taken
    and outputs do not change.

    Parameters
    ----------
    fmt : FPFormat
        Format and rounding (``rtz``, ``rne`` or ``chop``).
    stages : int
        Pipeline depth, 1 to 9 (default: 5, 6 in rne; :func:`default_add_stages`). The
        ``virtex4`` adder's depth is set by its DSP48 registers (latency 7); ``stages`` is
        checked but not used.
    target : {"generic", "virtex4"}
        ``virtex4``: shifts and significand add in two DSP48 (:mod:`.fp_add_dsp48`).
    multiplier : {"generic", "virtex4"}, optional
        Another name for ``target``.

    Attributes
    ----------
    a, b : In(W)
        Operands (bit patterns).
    sub : In(1)
        1 selects ``a - b``.
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

    Raises
    ------
    ValueError
        If ``fmt`` is not an :class:`FPFormat`, ``stages`` is out of range, ``target`` is
        unknown, or (``virtex4``) the significand is wider than 17 bits.
    """

    def __init__(self, fmt, stages: int | None = None, target: str = "generic", *,
                 multiplier: str | None = None):
        self._fmt = check_format(fmt)
        self._target = _check_target(target, multiplier)
        if stages is None:
            stages = default_add_stages(fmt)
        self._latency = fp_add_latency(fmt, stages, self._target)
        self._steps = tuple(Step(name, getattr(self, f"_step_{name}"), weight)
                            for name, weight in zip(ADD_STEPS, add_weights(fmt)))
        self._registered = place_registers([s.weight for s in self._steps], stages)
        self._stages = stages
        super().__init__(adder_ports(fmt.width))

    @property
    def fmt(self):
        return self._fmt

    @property
    def stages(self) -> int:
        return self._stages

    @property
    def target(self) -> str:
        return self._target

    @property
    def latency(self) -> int:
        """Enabled clock edges from an input to its result (``stages``; 7 for ``virtex4``)."""
        return self._latency

    @property
    def stage_steps(self) -> tuple[tuple[str, ...], ...]:
        """The names of the combinational steps in each pipeline stage."""
        if self._target == "virtex4":
            return STAGE_STEPS
        return group_steps(self._steps, self._registered)

    # -- combinational steps -----------------------------------------------------------
    def _clamp(self, diff):
        """An exponent difference clamped to the alignment's width (a larger shift shifts
        everything out)."""
        width = self._fmt.man_bits + 3
        return Mux(diff > width, width, diff)

    @property
    def _clamp_early(self) -> bool:
        """Clamp both differences in ``classify`` (a register follows it), else the one
        ``order`` picks, in ``align``."""
        return ADD_STEPS.index("classify") in self._registered

    def _step_classify(self, m, v):
        # with a register behind this step, both exponent differences are clamped here,
        # beside the magnitude comparison, so that ``order`` picks the shift amount with one
        # multiplexer and ``align``'s shifter waits on nothing after it (swap -> difference
        # multiplexer -> clamp -> shifter was the slowest path of a placed adder). Where
        # ``order`` shares this step's stage (``chop``'s 5 stages) the clamp stays in
        # ``align``: here it lengthened the stage (FP24 chop, 129.7 -> 119.8 MHz, speed 6)
        v = classify(self._fmt, m, v)
        if not self._clamp_early:
            return v
        return {**v, **{name: self._clamp(v[name]) for name in ("diff_ab", "diff_ba")}}

    def _step_order(self, m, v):
        return order(m, v)

    def _step_align(self, m, v):
        # the shift by the difference's multiple of 4 (the difference clamped to the width,
        # which shifts everything out); every bit stays in the double-width window, so
        # ``shift`` below loses nothing that its sticky bit should see
        width = self._fmt.man_bits + 3
        clamped = wire(m, v["diff"] if self._clamp_early else self._clamp(v["diff"]),
                       "clamped")
        wide = Cat(Const(0, width), Const(0, 2), v["sig_y"]) >> Cat(Const(0, 2), clamped[2:])
        return {**keep(v, "sign_x", "zero_sign", "eff_sub", "exp_x", "sig_x", *SPECIALS),
                "wide": wide[:2 * width], "fine": clamped[:2]}

    def _step_shift(self, m, v):
        width = self._fmt.man_bits + 3
        wide = v["wide"] >> v["fine"]
        shifted, sticky = wide[width:2 * width], wide[:width] != 0
        if self._fmt.rounding == "chop":
            shifted, sticky = Cat(Const(0, 2), shifted[2:]), Const(0, 1)
        return {**keep(v, "sign_x", "zero_sign", "eff_sub", "exp_x", "sig_x", *SPECIALS),
                "sig_y": shifted, "sticky": sticky}

    def _step_add(self, m, v):
        width = self._fmt.man_bits + 4
        x = Cat(Const(0, 2), v["sig_x"])
        # one carry chain for both: X - Y' - sticky = X + ~Y' + (1 - sticky) mod 2**width
        sub = v["eff_sub"]
        y = Value.cast(v["sig_y"])
        y = Cat(y ^ sub.replicate(len(y)), sub.replicate(width - len(y)))
        total = x + y + (sub & ~v["sticky"])
        return {**keep(v, "sign_x", "zero_sign", "exp_x", "sticky", *SPECIALS),
                "sum": total[:width]}

    def _step_lzc(self, m, v):
        count, zero = leading_zeros(v["sum"])
        return {**keep(v, "sign_x", "zero_sign", "exp_x", "sticky", "sum", *SPECIALS),
                "lzc": count, "zero": zero}

    def _step_normalise(self, m, v):
        width = self._fmt.man_bits + 4
        norm = (v["sum"] << v["lzc"])[:width]
        return {**keep(v, "sign_x", "zero_sign", "zero", *SPECIALS),
                "sig": norm[3:], "guard": norm[2],
                "sticky": norm[:2].any() | v["sticky"],
                "exp": v["exp_x"] + 1 - v["lzc"]}

    def _step_round(self, m, v):
        sig, exp = round_significand(self._fmt, v["sig"], v["exp"], v["guard"], v["sticky"])
        return {**keep(v, "sign_x", "zero_sign", "zero", *SPECIALS),
                "sig": sig, "exp": exp}

    def _step_pack(self, m, v):
        bits, flags = pack(self._fmt, sign=Mux(v["zero"], v["zero_sign"], v["sign_x"]),
                           exp=v["exp"], sig=v["sig"], zero=v["zero"], inf=v["inf"],
                           nan=v["nan"], invalid=v["invalid"])
        return {"bits": bits, "flags": flags}

    def elaborate(self, platform):
        m = Module()
        if self._target == "virtex4":
            m.submodules.dsp48 = unit = FPAddDSP48(self._fmt)
            m.d.comb += [getattr(unit, k).eq(getattr(self, k))
                         for k in ("a", "b", "sub", "i_valid", "en")]
            m.d.comb += [getattr(self, k).eq(getattr(unit, k)) for k in ("o", "flags", "o_valid")]
            return m
        out, valid = build_pipeline(
            m, self._steps, {"a": self.a, "b": self.b, "sub": self.sub},
            self._registered, en=self.en, valid=self.i_valid)
        m.d.comb += [self.o.eq(out["bits"]), self.flags.eq(out["flags"]),
                     self.o_valid.eq(valid)]
        return m

