"""cocotb testbench of the board-level top (Verilog module ``board_top``).

Started by :func:`raplas_hdl.sim.drive.board_sim.run_board`, which passes, in environment
variables, ``BOARD_STIM`` (an ``.npz``: the scene's and the runs' memories, see
:func:`raplas_hdl.sim.drive.board_sim.encode_stimulus`), ``BOARD_META`` (JSON: the unit's
parameters, seed, bus gap density) and ``BOARD_OUT`` (where the results go).

The host side is the real driver, :class:`raplas_hdl.link.driver.BoardDriver`, run
unchanged in a cocotb *bridge* thread: its bus object turns every ``read``/``write`` into a
Wishbone classic cycle on the DUT (a :func:`cocotb.task.resume`-wrapped coroutine), so
simulation time advances only through bus cycles and the thread never runs beside the
simulator. Signals are driven and sampled on the falling clock edge (the design changes
only on rising edges). Before an access the master idles a random 0-3 cycles with
probability ``gap_density`` (seeded), so the host's pace varies.

A second test checks the bus protocol itself: ``wb_err`` on an unmapped address,
read-only registers ignoring writes, the memory window's auto-increment, and a refused
``CMD_START`` while the command slot is full (``cmd_overrun``, cleared by ``CONTROL``).
"""

from __future__ import annotations

import json
import os
import random

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.task import bridge, resume
from cocotb.triggers import FallingEdge, RisingEdge

from raplas_hdl.link.driver import BoardDriver
from raplas_hdl.model.board_map import BOARD_ID, REGISTERS, STATUS_BITS, cmd_start_word
from raplas_hdl.sim.drive.board_sim import decode_stimulus


class BusError(RuntimeError):
    """The slave answered ``wb_err``."""


class WishboneMaster:
    """Wishbone B4 classic master on the DUT's ``wb_*`` ports (one access at a time)."""

    def __init__(self, dut, seed=1, gap_density=0.0, max_wait=64):
        self.dut = dut
        self.rng = random.Random(seed)
        self.gap_density = float(gap_density)
        self.max_wait = max_wait
        self.accesses = 0

    def idle(self):
        dut = self.dut
        dut.wb_cyc.value = 0
        dut.wb_stb.value = 0
        dut.wb_we.value = 0
        dut.wb_adr.value = 0
        dut.wb_dat_w.value = 0
        dut.wb_sel.value = 0

    async def access(self, addr: int, value: int | None = None) -> int:
        """One classic cycle: a write when ``value`` is given, else a read (returns data)."""
        dut = self.dut
        if self.gap_density and self.rng.random() < self.gap_density:
            for _ in range(self.rng.randint(0, 3)):
                await FallingEdge(dut.clk)
        dut.wb_adr.value = int(addr)
        dut.wb_we.value = int(value is not None)
        dut.wb_dat_w.value = 0 if value is None else int(value)
        dut.wb_sel.value = 0xF
        dut.wb_cyc.value = 1
        dut.wb_stb.value = 1
        for _ in range(self.max_wait):
            await FallingEdge(dut.clk)
            ack, err = int(dut.wb_ack.value), int(dut.wb_err.value)
            if ack or err:
                break
        else:
            raise AssertionError(f"no wb_ack/wb_err within {self.max_wait} cycles "
                                 f"(address 0x{addr:02X})")
        assert not (ack and err), "wb_ack and wb_err together"
        data = dut.wb_dat_r.value.to_unsigned()
        self.idle()
        self.accesses += 1
        if err:
            raise BusError(f"wb_err on {'write' if value is not None else 'read'} of "
                           f"address 0x{addr:02X}")
        return data

    async def read(self, addr: int) -> int:
        return await self.access(addr)

    async def write(self, addr: int, value: int) -> None:
        await self.access(addr, value)


class BridgedBus:
    """The driver's blocking bus (``read``/``write``) over the master, from a bridge thread."""

    def __init__(self, master: WishboneMaster):
        self._read = resume(master.read)
        self._write = resume(master.write)

    def read(self, addr):
        return self._read(addr)

    def write(self, addr, value):
        self._write(addr, value)


async def _start(dut, meta):
    master = WishboneMaster(dut, seed=meta.get("seed", 1),
                            gap_density=meta.get("gap_density", 0.0))
    master.idle()
    Clock(dut.clk, 10, unit="ns").start()
    dut.rst.value = 1
    for _ in range(3):
        await RisingEdge(dut.clk)
    await FallingEdge(dut.clk)
    dut.rst.value = 0
    for _ in range(4):          # the reset synchroniser releases after two edges
        await FallingEdge(dut.clk)
    return master


def _load(meta):
    stim = dict(np.load(os.environ["BOARD_STIM"], allow_pickle=False))
    return decode_stimulus(meta, stim)


@cocotb.test()
async def run_driver(dut):
    """The host driver loads the scene, runs every run and reads the counters."""
    with open(os.environ["BOARD_META"]) as f:
        meta = json.load(f)
    config, scene, runs = _load(meta)
    master = await _start(dut, meta)
    bus = BridgedBus(master)

    def host():
        driver = BoardDriver(bus, config)
        results = driver.run_runs(runs, scene, prefetch=bool(meta.get("prefetch", True)))
        return results, driver.reads, driver.writes

    results, reads, writes = await bridge(host)()
    beats = np.concatenate([r[0] for r in results])
    run_of_beat = np.concatenate([np.full(len(r[0]), k) for k, r in enumerate(results)])
    names = list(results[0][1])
    counters = np.array([[r[1][n] for n in names] for r in results], np.int64)
    np.savez(os.environ["BOARD_OUT"], beats=beats, run_of_beat=run_of_beat,
             counter_names=np.array(names), counters=counters, reads=np.array(reads),
             writes=np.array(writes), accesses=np.array(master.accesses),
             sim_ns=np.array(cocotb.simtime.get_sim_time("ns")))


@cocotb.test()
async def bus_protocol(dut):
    """wb_err, read-only registers, the memory window and a refused command."""
    with open(os.environ["BOARD_META"]) as f:
        meta = json.load(f)
    config, scene, runs = _load(meta)
    master = await _start(dut, {**meta, "gap_density": 0.0})
    r = REGISTERS
    assert await master.read(r["ID"]) == BOARD_ID
    await master.write(r["ID"], 0)                      # read-only: acked, ignored
    assert await master.read(r["ID"]) == BOARD_ID
    for addr in (0x0E, 0x1F, 0x29, 0xFF):               # unmapped
        for value in (None, 1):
            try:
                await master.access(addr, value)
            except BusError:
                continue
            raise AssertionError(f"no wb_err for address 0x{addr:02X}")
    await master.write(r["MEM_ADDR"], 0x1234_5670)
    assert await master.read(r["MEM_ADDR"]) == 0x1234_5670
    await master.write(r["MEM_DATA"], 0)                # an unused field: ignored by the unit
    await master.write(r["MEM_DATA"], 0)
    assert await master.read(r["MEM_ADDR"]) == 0x1234_5672
    assert await master.read(r["RES_INFO"]) == 0        # nothing to pop
    status = await master.read(r["STATUS"])
    assert status == 0, f"STATUS 0x{status:x} after reset"

    # a long run on an unloaded scene keeps the unit feeding: the second CMD_START finds
    # the slot taken by the first (the unit is busy with the run before it)
    count = config.max_spheres
    await master.write(r["CMD_FIRST"], 0)
    await master.write(r["CMD_START"], cmd_start_word(count, 0, False))
    await master.write(r["CMD_START"], cmd_start_word(0, 0, False))
    refused = False
    try:
        await master.write(r["CMD_START"], cmd_start_word(0, 0, False))
    except BusError:
        refused = True
    status = await master.read(r["STATUS"])
    assert refused, "a CMD_START into a full command slot was not refused"
    assert status >> STATUS_BITS["cmd_overrun"] & 1, f"cmd_overrun not set (0x{status:x})"
    await master.write(r["CONTROL"], 2)
    status = await master.read(r["STATUS"])
    assert not status >> STATUS_BITS["cmd_overrun"] & 1, "CONTROL did not clear cmd_overrun"
    # drain: the two accepted runs end with one last beat each
    lasts = 0
    for _ in range(200_000):
        info = await master.read(r["RES_INFO"])
        lasts += info >> 1 & 1
        if lasts == 2:
            break
    assert lasts == 2, f"{lasts} runs ended, expected 2"
    assert await master.read(r["RES_INFO"]) == 0
