"""Pipeline helpers shared by the RTL units.

A pipelined unit is written as a sequence of named combinational *steps*. Each step is a
function ``fn(m, v) -> dict`` that takes the values handed to it (a ``dict`` of Amaranth
values) and returns exactly the values it hands to the next step. Where the pipeline
registers go is decided separately, by :func:`place_registers`, from the number of stages
the unit was asked for and a rough weight (combinational depth) per step; then
:func:`build_pipeline` chains the steps and puts a register bank behind the chosen ones.
The last step is always registered, so a unit with ``stages`` stages has a latency of
``stages`` clock cycles and no combinational path from its inputs to its outputs.

Netlist layout: each step is a submodule named after the step. Its outputs go onto one
wire of the same name, a :class:`~amaranth.lib.data.StructLayout` of the output names
(so waveforms show the fields); behind a registered step sits a register of the same
layout, ``s1``, ``s2``, ... with its valid bit ``s1_valid``, ... The per-step submodules
and single wires matter for Amaranth's simulator, which compiles expressions as trees
(a value read by a later step would otherwise be recomputed there) and re-evaluates a
whole module whenever one of its inputs changes.

Every register holds its value while the clock enable ``en`` is 0 (a stall). The
``valid`` bit travels beside the data through the same stages; it is the only register
that is reset, so data registers cost no reset logic.

:func:`delay` and :class:`Delay` are shift registers with the same enable, for units that
need to hold an operand back until a parallel pipeline catches up. With ``srl`` a long
reset-less delay becomes Virtex-4 ``SRL16E`` primitives (one LUT site per bit per 16 stages)
in front of flip-flops, with the same behaviour under the clock enable. :func:`wire` names a
combinational value that several expressions read.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from amaranth.hdl import (Cat, ClockSignal, Const, Instance, Module, Shape, ShapeCastable,
                          Signal, Value)
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

__all__ = ["Step", "place_registers", "group_steps", "build_pipeline", "wire", "delay",
           "Delay", "srl_split", "check_srl", "SRL_STAGES"]

#: Stages of one ``SRL16E`` (its address is the number of stages minus 1).
SRL_STAGES = 16


@dataclass(frozen=True)
class Step:
    """One combinational step of a pipelined datapath.

    Parameters
    ----------
    name : str
        Short name: the name of the step's submodule and of its output wire.
    fn : callable
        ``fn(m, v) -> dict``: ``m`` is the step's own :class:`~amaranth.hdl.Module` (a
        submodule of the unit, named after the step) for the step's submodules and wires,
        ``v`` the ``dict`` handed over by the previous step.
    weight : int
        Rough combinational depth, used only to decide where registers go.
    """

    name: str
    fn: Callable[[Module, dict], dict]
    weight: int = 1


def _check_stages(stages, n_steps, name):
    if not isinstance(stages, int) or isinstance(stages, bool):
        raise ValueError(f"{name} must be an integer, not {stages!r}")
    if not 1 <= stages <= n_steps:
        raise ValueError(f"{name} must be between 1 and {n_steps} (the number of "
                         f"combinational steps), not {stages}")


def place_registers(weights: Sequence[int], stages: int, *, name: str = "stages"
                    ) -> tuple[int, ...]:
    """Choose after which steps the pipeline registers go.

    The steps are cut into ``stages`` contiguous groups so that the heaviest group is as
    light as possible; among those cuts, the one with the smallest sum of squared group
    weights (the most even), and among those the one with the earliest cuts.

    Parameters
    ----------
    weights : sequence of int
        Weight of each step, in datapath order.
    stages : int
        Number of register banks, 1 to ``len(weights)``.
    name : str
        Parameter name used in the error message.

    Returns
    -------
    tuple of int
        Indices of the steps followed by a register, ascending; the last step is always
        one of them.

    Raises
    ------
    ValueError
        If ``stages`` is not an integer between 1 and the number of steps.
    """
    n = len(weights)
    _check_stages(stages, n, name)
    prefix = [0]
    for w in weights:
        prefix.append(prefix[-1] + w)

    def group(i, j):  # weight of steps i..j-1
        return prefix[j] - prefix[i]

    inf = float("inf")
    # Pass 1: the smallest possible heaviest group (classic linear partition).
    best_max = [[inf] * (n + 1) for _ in range(stages + 1)]
    best_max[0][0] = 0
    for k in range(1, stages + 1):
        for j in range(k, n + 1):
            best_max[k][j] = min(max(best_max[k - 1][i], group(i, j)) for i in range(k - 1, j))
    limit = best_max[stages][n]
    # Pass 2: under that limit, the most even cut; ties go to the earliest cut.
    cost = [[inf] * (n + 1) for _ in range(stages + 1)]
    back = [[None] * (n + 1) for _ in range(stages + 1)]
    cost[0][0] = 0
    for k in range(1, stages + 1):
        for j in range(k, n + 1):
            for i in range(k - 1, j):
                g = group(i, j)
                if g <= limit and cost[k - 1][i] + g * g < cost[k][j]:
                    cost[k][j] = cost[k - 1][i] + g * g
                    back[k][j] = i
    ends, j = [], n
    for k in range(stages, 0, -1):
        ends.append(j - 1)
        j = back[k][j]
    return tuple(sorted(ends))


def wire(m: Module, value, name: str) -> Value:
    """Put a combinational value on a named signal and return the signal.

    Use it inside a step for a value that several expressions read: Amaranth's simulator
    compiles expressions as trees, so a shared subexpression is otherwise evaluated once
    per reader.
    """
    value = Value.cast(value)
    sig = Signal(value.shape(), name=name)
    m.d.comb += sig.eq(value)
    return sig


def group_steps(steps: Sequence[Step], registered: Iterable[int]) -> tuple[tuple[str, ...], ...]:
    """Names of the steps in each pipeline stage, for documentation and tests.

    Parameters
    ----------
    steps : sequence of Step
    registered : iterable of int
        As returned by :func:`place_registers`.
    """
    groups, start = [], 0
    for end in sorted(registered):
        groups.append(tuple(s.name for s in steps[start:end + 1]))
        start = end + 1
    return tuple(groups)


def build_pipeline(m: Module, steps: Sequence[Step], inputs: dict, registered: Iterable[int],
                   *, en: Value, valid: Value, domain: str = "sync") -> tuple[dict, Value]:
    """Chain combinational steps and register the outputs of the chosen ones.

    Parameters
    ----------
    m : Module
        Module that receives the steps as submodules.
    steps : sequence of Step
        The datapath, in order.
    inputs : dict
        Values handed to the first step.
    registered : iterable of int
        Indices of the steps whose outputs are registered (see :func:`place_registers`).
    en : Value
        Clock enable: every register (data and valid) holds while it is 0.
    valid : Value
        Valid bit of the inputs; it travels beside the data.
    domain : str
        Clock domain of the registers.

    Returns
    -------
    (dict, Value)
        The last step's outputs (registered if the last step is in ``registered``) and the
        valid bit that belongs to them.
    """
    registered = set(registered)
    values = dict(inputs)
    stage = 0
    for index, step in enumerate(steps):
        # One submodule, one output wire and at most one register per step: see the
        # module docstring for why.
        m.submodules[step.name] = sm = Module()
        values = {key: Value.cast(val) for key, val in step.fn(sm, values).items()}
        layout = data.StructLayout({key: val.shape() for key, val in values.items()})
        bank = Signal(layout, name=step.name)
        sm.d.comb += Value.cast(bank).eq(Cat(*values.values()))
        if index in registered:
            stage += 1
            reg = Signal(layout, name=f"s{stage}", reset_less=True)
            valid_reg = Signal(name=f"s{stage}_valid")
            with sm.If(en):
                sm.d[domain] += [reg.eq(bank), valid_reg.eq(valid)]
            bank, valid = reg, valid_reg
        values = {key: bank[key] for key in values}
    return values, valid


def _check_cycles(cycles):
    if not isinstance(cycles, int) or isinstance(cycles, bool) or cycles < 0:
        raise ValueError(f"cycles must be a non-negative integer, not {cycles!r}")


def check_srl(srl) -> int:
    """``srl`` if it is an integer from 0 to 16 (see :func:`srl_split`), else ``ValueError``."""
    if not isinstance(srl, int) or isinstance(srl, bool) or not 0 <= srl <= SRL_STAGES:
        raise ValueError(f"srl must be an integer from 0 to {SRL_STAGES}, not {srl!r}")
    return srl


def srl_split(cycles: int, srl: int) -> tuple[tuple[int, ...], int]:
    """How :func:`delay` builds a reset-less delay of ``cycles`` stages with ``srl``.

    The last stage is always a flip-flop (an ``SRL16E``'s clock-to-out is slower than a
    flip-flop's, so its output is registered before any logic reads it). The ``cycles - 1``
    stages in front of it go into ``SRL16E`` pieces of 16 stages, and the remainder into
    one more piece when it has at least ``srl`` stages; what is left stays flip-flops.

    Parameters
    ----------
    cycles : int
        Stages of the delay.
    srl : int
        Fewest stages worth an ``SRL16E`` (1 to 16; 0: flip-flops only).

    Returns
    -------
    (tuple of int, int)
        The stages of each ``SRL16E`` piece, in order from the input, and the number of
        flip-flop stages behind them (their sum is ``cycles``).

    Raises
    ------
    ValueError
        If ``cycles`` is not a non-negative integer or ``srl`` not an integer from 0 to 16.
    """
    _check_cycles(cycles)
    check_srl(srl)
    if not srl or cycles < 2:
        return (), cycles
    full, rest = divmod(cycles - 1, SRL_STAGES)
    pieces = (SRL_STAGES,) * full + ((rest,) if rest and rest >= srl else ())
    return pieces, cycles - sum(pieces)


def _srl16(m: Module, value: Value, stages: int, en, domain: str, name: str) -> Value:
    """``value`` through ``stages`` (1 to 16) stages of ``SRL16E``, one per bit."""
    addr = stages - 1
    bits = []
    for b in range(len(value)):
        q = Signal(name=f"{name}_q{b}")
        m.submodules[f"{name}_b{b}"] = Instance(
            "SRL16E", p_INIT=Const(0, 16), i_CLK=ClockSignal(domain),
            i_CE=Const(1, 1) if en is None else en, i_D=value[b],
            **{f"i_A{k}": Const((addr >> k) & 1, 1) for k in range(4)}, o_Q=q)
        bits.append(q)
    out = Signal(value.shape(), name=name)
    m.d.comb += out.eq(Cat(*bits))
    return out


def delay(m: Module, value, cycles: int, *, en=None, domain: str = "sync",
          name: str = "delay", reset_less: bool = True, srl: int = 0) -> Value:
    """Delay a value by ``cycles`` enabled clock edges.

    Parameters
    ----------
    m : Module
        Module that receives the registers.
    value : Value
        Value to delay.
    cycles : int
        Number of register stages; 0 returns ``value`` unchanged.
    en : Value or None
        Clock enable (``None``: always enabled). All stages hold while it is 0.
    domain : str
        Clock domain.
    name : str
        Prefix of the register names (``name_1``, ``name_2``, ...; ``SRL16E`` pieces:
        ``name_srl1``, ...).
    reset_less : bool
        Data registers need no reset; pass ``False`` for control bits such as a valid.
    srl : int
        0 (the default): flip-flops only. 1 to 16: a reset-less delay puts its stages into
        Virtex-4 ``SRL16E`` primitives (``CE`` = ``en``, so a stall holds them exactly as
        it holds flip-flops; power-up contents 0 like the flip-flops'), each piece of at
        least ``srl`` stages, as :func:`srl_split` says; the last stage stays a
        flip-flop. A delay with a reset is never put into ``SRL16E``.

    Returns
    -------
    Value
        The delayed value (the last register).

    Raises
    ------
    ValueError
        If ``cycles`` is not a non-negative integer, or ``srl`` not an integer from 0 to 16.
    """
    _check_cycles(cycles)
    check_srl(srl)
    value = Value.cast(value)
    pieces, ff = srl_split(cycles, srl if reset_less else 0)
    for k, stages in enumerate(pieces):
        value = _srl16(m, value, stages, en, domain, f"{name}_srl{k + 1}")
    for i in range(cycles - ff, cycles):
        reg = Signal(value.shape(), name=f"{name}_{i + 1}", reset_less=reset_less)
        if en is None:
            m.d[domain] += reg.eq(value)
        else:
            with m.If(en):
                m.d[domain] += reg.eq(value)
        value = reg
    return value


class Delay(wiring.Component):
    """Shift register with clock enable, as a component.

    Parameters
    ----------
    shape : int or shape-castable
        Shape of the delayed value.
    cycles : int
        Delay in enabled clock edges (0 is a wire).
    srl : int
        As in :func:`delay`: 0 for flip-flops only, 1 to 16 to put the stages into
        ``SRL16E`` primitives (Virtex-4; simulate with
        :func:`raplas_hdl.rtl.dsp48.dsp48_sim_model`).

    Attributes
    ----------
    i : In(shape)
        Input value.
    en : In(1)
        Clock enable; every stage holds while it is 0.
    o : Out(shape)
        ``i`` as it was ``cycles`` enabled edges ago.
    latency : int
        Equal to ``cycles``.

    Raises
    ------
    ValueError
        If ``cycles`` is not a non-negative integer, ``shape`` is not a shape or ``srl``
        not an integer from 0 to 16.
    """

    def __init__(self, shape, cycles: int, *, srl: int = 0):
        _check_cycles(cycles)
        check_srl(srl)
        if not isinstance(shape, (int, Shape, ShapeCastable)) or isinstance(shape, bool):
            raise ValueError(f"shape must be a width or a shape, not {shape!r}")
        self._shape = shape
        self._cycles = cycles
        self._srl = srl
        super().__init__({"i": In(shape), "en": In(1), "o": Out(shape)})

    @property
    def latency(self) -> int:
        return self._cycles

    def elaborate(self, platform):
        m = Module()
        m.d.comb += self.o.eq(delay(m, self.i, self._cycles, en=self.en, name="stage",
                                      srl=self._srl))
        return m
