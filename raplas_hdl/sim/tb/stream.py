"""cocotb tests of the batch harness: any streaming unit (the FP units, the ray-triangle and
plane-sphere units, the reducer) inside the harness of :mod:`raplas_hdl.sim.build.harness`
(so one build serves both tests). :func:`~raplas_hdl.sim.build.harness.run_batch` and
:func:`~raplas_hdl.sim.build.harness.run_percycle` pass everything through environment
variables and files:

``RAPLAS_SPEC``
    The :class:`raplas_hdl.sim.build.harness.HarnessSpec` as JSON.
``RAPLAS_TB_IN`` (per-cycle test)
    An ``.npz`` with one array per input data port, and scalars ``idle`` (probability of a
    gap in ``valid``), ``stall`` (probability that ``en``/``o_ready`` is low) and ``seed``.
``RAPLAS_TB_OUT``
    Per-cycle test: an ``.npz`` written with one array per output data port, in beat order.
    Batch test: a JSON file with the cycle count (the results come from the harness file).

Tests: ``test_batch`` (cocotb starts the clock, resets, waits for ``done``) and
``test_percycle`` (:class:`StreamTB` drives and monitors every cycle from Python). Neither
compares with a model: the pytest side does, in bulk, and asserts.
"""

from __future__ import annotations

import json
import os
import random

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, ReadOnly, RisingEdge, Timer

from raplas_hdl.sim.build.harness import HarnessSpec

CLOCK_NS = 10


class StreamTB:
    """Per-cycle driver and monitor of a pipelined unit with valid and enable/ready ports.

    Parameters
    ----------
    dut : cocotb handle
        The harness top level (its DUT-facing registers are named as the DUT's ports).
    spec : HarnessSpec
        The unit's streaming interface.
    idle : float
        Probability of an idle cycle (``valid`` low) before each vector (idle inserter).
    stall : float
        Probability that ``en`` (or ``o_ready``) is low in a cycle (back-pressure inserter).
    seed : int
        Seed of the inserters.
    """

    def __init__(self, dut, spec: HarnessSpec, idle=0.0, stall=0.0, seed=1):
        self.dut = dut
        self.spec = spec
        self.idle = float(idle)
        self.stall = float(stall)
        self.rng = random.Random(seed)
        self.clk = getattr(dut, spec.clk)
        self._clock_started = False

    def start_clock(self):
        if not self._clock_started:
            Clock(self.clk, CLOCK_NS, unit="ns").start()
            self._clock_started = True

    def _set_ready(self, value: int):
        s = self.spec
        if s.en:
            getattr(self.dut, s.en).value = value
        if s.o_ready:
            getattr(self.dut, s.o_ready).value = value

    async def reset(self, cycles: int = 3):
        """Start the clock, hold reset for ``cycles`` cycles, leave the inputs idle."""
        self.start_clock()
        s = self.spec
        getattr(self.dut, s.i_valid).value = 0
        self._set_ready(0)
        getattr(self.dut, s.rst).value = 1
        await ClockCycles(self.clk, cycles)
        await RisingEdge(self.clk)
        getattr(self.dut, s.rst).value = 0

    async def run_test(self, vectors: dict, n_out: int | None = None,
                       max_cycles: int | None = None) -> dict:
        """Drive every vector of ``vectors`` (``{input port: values}``), collect ``n_out``
        output beats (default: one per vector); returns ``{output port: list of ints}``."""
        s, dut = self.spec, self.dut
        n_in = len(vectors[s.inputs[0].name])
        n_out = n_in if n_out is None else n_out
        max_cycles = 64 * n_in + 1000 if max_cycles is None else max_cycles
        cols = {p.name: [int(v) for v in vectors[p.name]] for p in s.inputs}
        in_h = [(getattr(dut, p.name), cols[p.name]) for p in s.inputs]
        out_h = [(p.name, getattr(dut, p.name)) for p in s.outputs]
        valid_h = getattr(dut, s.i_valid)
        o_valid_h = getattr(dut, s.o_valid)
        i_ready_h = getattr(dut, s.i_ready) if s.i_ready else None
        results = {p.name: [] for p in s.outputs}
        idx, got, cycles = 0, 0, 0
        valid = 0
        while got < n_out:
            if cycles >= max_cycles:
                raise AssertionError(f"{got} of {n_out} outputs after {cycles} cycles")
            # inputs for this cycle (a raised valid stays until taken)
            if not valid and idx < n_in and self.rng.random() >= self.idle:
                for h, col in in_h:
                    h.value = col[idx]
                valid = 1
            valid_h.value = valid
            ready = 0 if self.stall and self.rng.random() < self.stall else 1
            self._set_ready(ready)
            await ReadOnly()
            in_ready = ready if s.en else (int(i_ready_h.value) if i_ready_h is not None else 1)
            out_ready = ready if (s.en or s.o_ready) else 1
            if int(o_valid_h.value) and out_ready:
                for name, h in out_h:
                    results[name].append(int(h.value))
                got += 1
            taken = valid and in_ready
            await RisingEdge(self.clk)
            cycles += 1
            if taken:
                idx += 1
                valid = 0
        self.cycles = cycles
        return results


def _spec() -> HarnessSpec:
    return HarnessSpec.from_json(os.environ["RAPLAS_SPEC"])


@cocotb.test()
async def test_percycle(dut):
    """Drive the vectors of ``RAPLAS_TB_IN`` cycle by cycle; write the outputs."""
    spec = _spec()
    data = np.load(os.environ["RAPLAS_TB_IN"])
    tb = StreamTB(dut, spec, idle=float(data["idle"]), stall=float(data["stall"]),
                  seed=int(data["seed"]))
    await tb.reset()
    vectors = {p.name: data[p.name] for p in spec.inputs}
    out = await tb.run_test(vectors)
    np.savez(os.environ["RAPLAS_TB_OUT"],
             cycles=tb.cycles,
             **{k: np.array(v, dtype=np.uint64 if max(v, default=0) < 2**64 else object)
                for k, v in out.items()})


@cocotb.test()
async def test_batch(dut):
    """Wait for the harness's ``done``; fail on its timeout.

    The harness makes its own clock and reset (no GPI call per edge) unless the run has
    ``+EXT_CLK``; then this test starts a cocotb clock and resets."""
    if os.environ.get("RAPLAS_EXT_CLK"):
        Clock(dut.clk, CLOCK_NS, unit="ns").start()
        dut.rst.value = 1
        await ClockCycles(dut.clk, 3)
        dut.rst.value = 0
    if dut.done.value != 1:
        await RisingEdge(dut.done)
    await Timer(1, unit="ns")
    cycles = int(dut.cycles.value)
    if os.environ.get("RAPLAS_TB_OUT"):
        with open(os.environ["RAPLAS_TB_OUT"], "w") as fh:
            json.dump({"cycles": cycles, "timeout": int(dut.timeout.value)}, fh)
    assert not int(dut.timeout.value), f"harness timed out after {cycles} cycles"

