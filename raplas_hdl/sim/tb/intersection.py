"""cocotb testbench of the intersection unit (Verilog module ``intersection_unit``).

Started by :func:`raplas_hdl.sim.drive.unit_driver.run_runs`, which passes, in environment
variables, ``UNIT_STIM`` (an ``.npz`` from
:func:`raplas_hdl.sim.drive.unit_driver.encode_runs`: scene writes and, per run, its memory
writes and its command), ``UNIT_META`` (JSON: the unit's
parameters, seed, ready density) and ``UNIT_OUT`` (where the results go). The ports' payloads
are packed and unpacked with the records of :mod:`raplas_hdl.model.records` (``CMD``,
``RESULT``, ``COUNTERS``) bound to the unit's parameters.

The testbench loads the scene, then for every run writes its bundle (into the other bank
while the previous run is still going: the double buffer), waits for the earlier runs of
the same bank, and starts it. Without overlap it waits for each run's last beat, reads the
counters and clears them, so counters are per run; with overlap it starts runs back to
back. A collector drives ``o.ready`` at random and records every beat. Every cycle it
asserts that the pair FIFO is within its depth and never overflowed. Signals are sampled
and driven on the falling clock edge (the design only changes on rising edges).
``UNIT_DEBUG=sig1,psa.sig2`` logs those signals every 1000 cycles.
"""

from __future__ import annotations

import json
import os
import random

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import FallingEdge, RisingEdge

from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.records import CMD, COUNTERS, output_record


def _handle(dut, path):
    for part in path.split("."):
        dut = getattr(dut, part)
    return dut


class UnitTB:
    """Clock, reset, host-port driver and result collector for ``intersection_unit``."""

    def __init__(self, dut, meta: dict, stim):
        self.dut = dut
        self.meta = meta
        self.stim = stim
        config = UnitConfig.from_params(meta["params"])
        self.cmd = CMD.bind(config)
        self.counters = COUNTERS.bind(config)
        self.last_bit = output_record(config).bind(config)["last"].offset
        self.rng = random.Random(meta.get("seed", 1))
        self.ready_density = float(meta.get("ready_density", 1.0))
        self.fifo_depth = config.fifo_depth
        self.done = 0
        self.beats: list[int] = []
        self.run_of_beat: list[int] = []
        self.max_level = 0
        self.cycles = 0
        self.max_cycles = int(meta.get("max_cycles", 2_000_000))

    async def reset(self):
        dut = self.dut
        dut.wr_en.value = 0
        dut.wr_addr.value = 0
        dut.wr_data.value = 0
        dut.cmd__valid.value = 0
        dut.cmd__payload.value = 0
        dut.o__ready.value = 0
        dut.clear.value = 0
        dut.rst.value = 1
        for _ in range(3):
            await RisingEdge(dut.clk)
        await FallingEdge(dut.clk)
        dut.rst.value = 0

    async def write(self, addrs, datas):
        dut = self.dut
        for a, d in zip(addrs.tolist(), datas.tolist()):
            dut.wr_en.value = 1
            dut.wr_addr.value = int(a)
            dut.wr_data.value = int(d)
            await FallingEdge(dut.clk)
        dut.wr_en.value = 0

    async def wait_done(self, n):
        while self.done < n:
            await FallingEdge(self.dut.clk)

    async def read_counters(self):
        dut = self.dut
        await FallingEdge(dut.clk)
        value = self.counters.unpack(dut.counters.value.to_unsigned())
        row = [int(value[n]) for n in COUNTERS.names]
        dut.clear.value = 1
        await FallingEdge(dut.clk)
        dut.clear.value = 0
        return row

    async def collector(self):
        dut = self.dut
        while True:
            await FallingEdge(dut.clk)
            self.cycles += 1
            if self.cycles % 1000 == 0 and os.environ.get("UNIT_DEBUG"):
                dut._log.info("DBG " + " ".join(f"{n}={_handle(dut, n).value}" for n in
                              os.environ["UNIT_DEBUG"].split(",")))
            if self.cycles >= self.max_cycles:
                raise AssertionError(
                    f"timed out after {self.cycles} cycles: {self.done} runs done, "
                    f"busy={dut.busy.value}, fifo_level={dut.fifo_level.value}, "
                    f"cmd.ready={dut.cmd__ready.value}, o.valid={dut.o__valid.value}")
            assert int(dut.fifo_overflow.value) == 0, "pair FIFO overflow"
            level = int(dut.fifo_level.value)
            assert level <= self.fifo_depth, f"pair FIFO level {level} above its depth"
            self.max_level = max(self.max_level, level)
            ready = int(self.rng.random() < self.ready_density)
            dut.o__ready.value = ready
            if ready and int(dut.o__valid.value):
                beat = dut.o__payload.value.to_unsigned()
                self.beats.append(beat)
                self.run_of_beat.append(self.done)
                if beat >> self.last_bit & 1:
                    self.done += 1

    async def run(self):
        dut, stim = self.dut, self.stim
        overlap = bool(int(stim["overlap"]))
        await self.write(stim["scene_addr"], stim["scene_data"])
        banks, offs = stim["run_bank"], stim["run_offsets"]
        n_runs = len(banks)
        counters = np.zeros((n_runs, len(COUNTERS.names)), np.int64)
        for k in range(n_runs):
            earlier = [j for j in range(k) if banks[j] == banks[k]]
            if earlier:
                await self.wait_done(earlier[-1] + 1)
            await self.write(stim["run_addr"][offs[k]:offs[k + 1]],
                             stim["run_data"][offs[k]:offs[k + 1]])
            if not overlap and k:
                await self.wait_done(k)
                counters[k - 1] = await self.read_counters()
            dut.cmd__payload.value = self.cmd.pack(
                {"first": stim["run_first"][k], "count": stim["run_count"][k],
                 "bank": banks[k], "indirect": stim["run_indirect"][k],
                 "keep_all": stim["run_keep_all"][k]})
            dut.cmd__valid.value = 1
            while True:   # cmd.ready depends only on registers: stable at the falling edge
                ready = int(dut.cmd__ready.value)
                await FallingEdge(dut.clk)
                if ready:
                    break
            dut.cmd__valid.value = 0
        await self.wait_done(n_runs)
        counters[n_runs - 1] = await self.read_counters()
        return counters


@cocotb.test()
async def run_stimulus(dut):
    """Load the scene, run every run, record the result stream and counters."""
    with open(os.environ["UNIT_META"]) as f:
        meta = json.load(f)
    stim = dict(np.load(os.environ["UNIT_STIM"], allow_pickle=False))
    tb = UnitTB(dut, meta, stim)
    Clock(dut.clk, 10, unit="ns").start()
    await tb.reset()
    cocotb.start_soon(tb.collector())
    counters = await tb.run()
    np.savez(os.environ["UNIT_OUT"], beats=np.array([f"{b:x}" for b in tb.beats]),
             run_of_beat=np.array(tb.run_of_beat, np.int64), counters=counters,
             max_fifo_level=np.array(tb.max_level), cycles=np.array(tb.cycles))
