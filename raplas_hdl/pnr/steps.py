"""Measured delay of each combinational step of a pipelined unit.

:func:`.rtl.pipeline.place_registers` cuts a datapath into stages by step weights. Here a
step's weight is measured, not guessed: :class:`StepHarness` puts one step alone between two
register banks (its inputs registered from ports, its outputs registered to ports), nextpnr
places and routes it out of context, and the step's delay is the period of the achieved Fmax
(the median over seeds), clock-to-out and setup included. The step's input shapes are those
the steps before it hand on (:func:`step_input_shapes`), so the harness sees exactly the
values the unit does.

``benchmarks/bench_pnr.py --steps`` measures the FP adder's and multiplier's steps at each
format and writes :mod:`raplas_hdl.rtl.step_delays`, the table the units read their weights
from.
"""

from __future__ import annotations

from collections.abc import Sequence

from amaranth.hdl import Module, Signal, Value
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from ..rtl.pipeline import Step

__all__ = ["StepHarness", "step_input_shapes"]


def step_input_shapes(steps: Sequence[Step], inputs: dict) -> list[dict]:
    """The shapes each step receives: ``[{name: shape}, ...]``, one dict per step.

    ``inputs`` maps the first step's input names to shapes."""
    values = {k: Signal(shape, name=k) for k, shape in inputs.items()}
    out = []
    for step in steps:
        out.append({k: Value.cast(v).shape() for k, v in values.items()})
        values = {k: Value.cast(v) for k, v in step.fn(_scratch(), values).items()}
    return out


def _scratch() -> Module:
    """A module that only collects what a step builds to learn its shapes (never used)."""
    m = Module()
    m._MustUse__silence = True
    return m


class StepHarness(wiring.Component):
    """One combinational step between an input and an output register bank.

    Parameters
    ----------
    step : Step
    shapes : dict
        The step's input shapes (from :func:`step_input_shapes`).

    Attributes
    ----------
    i : In(struct of the inputs)
    o : Out(struct of the outputs), one clock after the registered inputs
    """

    def __init__(self, step: Step, shapes: dict):
        self._step = step
        self._in = data.StructLayout(dict(shapes))
        probe = {k: Value.cast(v) for k, v in step.fn(
            _scratch(), {k: Signal(s, name=k) for k, s in shapes.items()}).items()}
        self._out = data.StructLayout({k: v.shape() for k, v in probe.items()})
        super().__init__({"i": In(self._in), "o": Out(self._out)})

    def elaborate(self, platform):
        m = Module()
        reg_in = Signal(self._in, name="in_reg")
        m.d.sync += reg_in.eq(self.i)
        m.submodules[self._step.name] = sm = Module()
        values = self._step.fn(sm, {k: reg_in[k] for k in self._in.members})
        reg_out = Signal(self._out, name="out_reg")
        m.d.sync += [reg_out[k].eq(v) for k, v in values.items()]
        m.d.comb += self.o.eq(reg_out)
        return m
