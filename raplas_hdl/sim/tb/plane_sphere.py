"""cocotb testbench of ``PlaneSphereArray`` (Verilog top ``plane_sphere``).

The pytest side (``tests/rtl/test_plane_sphere.py``) passes the stimulus in an ``.npz``
named by ``RAPLAS_PS_IN``:

``planes``
    Hex strings, shape (bundles, rows+cols): the plane words of each bundle.
``spheres``
    Hex strings, shape (bundles, spheres): packed sphere payloads (``id | c << I | r << I+3W``).
``idle``, ``stall``, ``seed``
    Probability of a gap before each sphere, probability that ``o.ready`` is low in a
    cycle, and the seed of both inserters.

For each bundle the TB waits for ``idle``, writes the planes (the drain rule), streams
the spheres with gaps under random back-pressure and collects every result beat. After
the last bundle it keeps ``o.ready`` high for a while and asserts that no further beat
appears and that the array is idle. Results go to ``RAPLAS_PS_OUT`` (``.npz``: hex strings
of the result payloads in arrival order, and the cycle count). The comparison with the
golden model is on the pytest side.
"""

from __future__ import annotations

import os
import random

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ReadOnly, RisingEdge

CLOCK_NS = 10


class PlaneSphereTB:
    """Clock, reset, plane writer, sphere driver with an idle inserter, and a result
    monitor with a back-pressure inserter."""

    def __init__(self, dut, idle: float, stall: float, seed: int):
        self.dut = dut
        self.idle = idle
        self.stall = stall
        self.rng = random.Random(seed)
        self.cycles = 0
        self.results = []
        self.was_idle = 0
        self._ready = 0

    async def reset(self):
        dut = self.dut
        Clock(dut.clk, CLOCK_NS, unit="ns").start()
        for name in ("pw_en", "pw_addr", "pw_data", "i__valid", "i__payload", "o__ready"):
            getattr(dut, name).value = 0
        dut.rst.value = 1
        for _ in range(3):
            await RisingEdge(dut.clk)
        dut.rst.value = 0
        await RisingEdge(dut.clk)

    async def tick(self):
        """Sample the result port under the current ``o.ready``, then clock."""
        dut = self.dut
        await ReadOnly()
        if int(dut.o__valid.value) and self._ready:
            self.results.append(int(dut.o__payload.value))
        in_ready = int(dut.i__ready.value)
        self.was_idle = int(dut.idle.value)
        await RisingEdge(dut.clk)
        self.cycles += 1
        return in_ready

    def _set_ready(self, forced=None):
        self._ready = forced if forced is not None else int(self.rng.random() >= self.stall)
        self.dut.o__ready.value = self._ready

    async def wait_idle(self, limit=10_000):
        for _ in range(limit):
            self._set_ready()
            await self.tick()
            if self.was_idle:
                return
        raise AssertionError("the array never became idle")

    async def write_planes(self, words):
        dut = self.dut
        for addr, word in enumerate(words):
            self._set_ready()
            dut.pw_en.value = 1
            dut.pw_addr.value = addr
            dut.pw_data.value = word
            await self.tick()
        dut.pw_en.value = 0

    async def stream(self, spheres, expected_total, limit):
        dut = self.dut
        idx, valid = 0, 0
        while idx < len(spheres):
            if self.cycles > limit:
                raise AssertionError(f"only {idx} of {len(spheres)} spheres taken")
            if not valid and self.rng.random() >= self.idle:
                dut.i__payload.value = spheres[idx]
                valid = 1
            dut.i__valid.value = valid
            self._set_ready()
            in_ready = await self.tick()
            if valid and in_ready:
                idx += 1
                valid = 0
        dut.i__valid.value = 0


@cocotb.test()
async def test_stream(dut):
    """Every bundle: drain, write planes, stream spheres; collect every result."""
    data = np.load(os.environ["RAPLAS_PS_IN"])
    planes = [[int(x, 16) for x in row] for row in data["planes"]]
    spheres = [[int(x, 16) for x in row] for row in data["spheres"]]
    tb = PlaneSphereTB(dut, float(data["idle"]), float(data["stall"]), int(data["seed"]))
    await tb.reset()
    total = sum(len(s) for s in spheres)
    limit = 200 * total + 10_000
    for words, bundle in zip(planes, spheres):
        await tb.wait_idle()
        await tb.write_planes(words)
        await tb.stream(bundle, total, limit)
    while len(tb.results) < total and tb.cycles <= limit:
        tb._set_ready()
        await tb.tick()
    assert len(tb.results) == total, f"{len(tb.results)} results for {total} spheres"
    for _ in range(64):          # nothing more may come out
        tb._set_ready(1)
        await tb.tick()
    assert len(tb.results) == total, f"{len(tb.results) - total} extra result beats"
    await ReadOnly()
    assert int(dut.idle.value), "the array is not idle after the last result"
    np.savez(os.environ["RAPLAS_PS_OUT"], results=np.array([f"{v:x}" for v in tb.results]),
             cycles=tb.cycles)
