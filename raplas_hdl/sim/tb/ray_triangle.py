"""cocotb testbench of the ray-triangle unit (stream in ``i``, stream out ``o``).

The pytest side (``tests/rtl/test_ray_triangle_cocotb.py``) writes the packed input payloads, one
hexadecimal line per pair, and names the files in environment variables:

``RAPLAS_RT_IN``     input payloads (hex lines), in order;
``RAPLAS_RT_OUT``    where the TB writes the output payloads it received, in order;
``RAPLAS_RT_IDLE``   probability of a gap (``i.valid`` low) in a cycle;
``RAPLAS_RT_STALL``  probability that ``o.ready`` is low in a cycle (back-pressure);
``RAPLAS_RT_SEED``   seed of both inserters.
``RAPLAS_RT_LATENCY_OUT`` (optional) where ``test_latency`` writes the latency it measured.

:class:`RayTriangleTB` drives and monitors every cycle: it sets its inputs at the falling
edge, samples the handshakes in the read-only phase before the rising edge, and counts a
transfer when ``valid`` and ``ready`` were both high there. The driver keeps Amaranth's
stream rule: once ``i.valid`` is raised, it and the payload stay until the transfer (gaps
come only between pairs). The TB compares nothing with
a model; it checks only that the unit never offers more results than it took pairs, and
the pytest side compares every bit in bulk.

``test_latency`` then sends the first pair alone into the empty unit with ``o.ready`` high
and counts the clock edges from the one that accepts it to the one that takes its result
(the unit's ``latency``).
"""

from __future__ import annotations

import os
import random

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, FallingEdge, ReadOnly, RisingEdge

CLOCK_NS = 10


def write_payloads(path, values) -> None:
    """Write integers as hexadecimal lines."""
    with open(path, "w") as fh:
        fh.writelines(f"{int(v):x}\n" for v in values)


def read_payloads(path) -> list[int]:
    """Read hexadecimal lines back as integers."""
    with open(path) as fh:
        return [int(line, 16) for line in fh if line.strip()]


class RayTriangleTB:
    """Per-cycle driver (with an idle inserter) and monitor (with a back-pressure inserter).

    Parameters
    ----------
    dut : cocotb handle
        The ``RayTriangleUnit`` top level (ports ``clk``, ``rst``, ``i__*``, ``o__*``).
    idle, stall : float
        Probabilities of a gap in ``i.valid`` and of ``o.ready`` low, per cycle.
    seed : int
    """

    def __init__(self, dut, idle=0.0, stall=0.0, seed=1):
        self.dut = dut
        self.idle = float(idle)
        self.stall = float(stall)
        self.rng = random.Random(seed)

    async def reset(self, cycles=3):
        dut = self.dut
        Clock(dut.clk, CLOCK_NS, unit="ns").start()
        dut.rst.value = 1
        dut.i__valid.value = 0
        dut.i__payload.value = 0
        dut.o__ready.value = 0
        await ClockCycles(dut.clk, cycles)
        await FallingEdge(dut.clk)
        dut.rst.value = 0

    async def run(self, payloads, max_cycles=None):
        """Send every payload, collect the results; returns ``(results, cycles)``."""
        dut = self.dut
        n = len(payloads)
        limit = max_cycles or 64 * n + 1000
        sent, got, cycles = 0, [], 0
        offer = False
        while len(got) < n:
            if cycles >= limit:
                raise AssertionError(f"timeout: {len(got)} of {n} results after {cycles} cycles")
            # stream rule: an offered pair stays (valid and payload) until it is taken;
            # the idle inserter draws a gap only between pairs
            if not offer and sent < n and self.rng.random() >= self.idle:
                offer = True
                dut.i__payload.value = payloads[sent]
            dut.i__valid.value = int(offer)
            take = self.rng.random() >= self.stall
            dut.o__ready.value = int(take)
            await ReadOnly()
            if offer and int(dut.i__ready.value):
                sent += 1
                offer = False
            if take and int(dut.o__valid.value):
                got.append(int(dut.o__payload.value))
                if len(got) > sent:
                    raise AssertionError("a result came out before its pair went in")
            await RisingEdge(dut.clk)
            await FallingEdge(dut.clk)
            cycles += 1
        dut.i__valid.value = 0
        # a few more cycles: nothing else may come out
        dut.o__ready.value = 1
        for _ in range(8):
            await ReadOnly()
            if int(dut.o__valid.value):
                raise AssertionError("the unit produced more results than it took pairs")
            await RisingEdge(dut.clk)
            await FallingEdge(dut.clk)
        return got, cycles


@cocotb.test()
async def test_stream(dut):
    """Every pair in, every result out, with gaps and back-pressure."""
    payloads = read_payloads(os.environ["RAPLAS_RT_IN"])
    tb = RayTriangleTB(dut, idle=float(os.environ.get("RAPLAS_RT_IDLE", "0")),
                       stall=float(os.environ.get("RAPLAS_RT_STALL", "0")),
                       seed=int(os.environ.get("RAPLAS_RT_SEED", "1")))
    await tb.reset()
    got, cycles = await tb.run(payloads)
    write_payloads(os.environ["RAPLAS_RT_OUT"], got)
    dut._log.info("%d pairs in %d cycles", len(got), cycles)


@cocotb.test()
async def test_latency(dut):
    """Edges from accepting one pair (empty unit, ``o.ready`` high) to taking its result."""
    payloads = read_payloads(os.environ["RAPLAS_RT_IN"])
    tb = RayTriangleTB(dut)
    await tb.reset()
    dut.o__ready.value = 1
    dut.i__valid.value = 1
    dut.i__payload.value = payloads[0]
    await ReadOnly()
    assert int(dut.i__ready.value), "an empty unit must take a pair"
    await RisingEdge(dut.clk)             # the accepting edge
    await FallingEdge(dut.clk)
    dut.i__valid.value = 0
    edges = 0
    while True:
        await ReadOnly()
        if int(dut.o__valid.value):
            break                         # taken at the next edge
        if edges > 1000:
            raise AssertionError("no result within 1000 cycles")
        await RisingEdge(dut.clk)
        await FallingEdge(dut.clk)
        edges += 1
    latency = edges + 1
    dut._log.info("latency %d cycles", latency)
    if os.environ.get("RAPLAS_RT_LATENCY_OUT"):
        with open(os.environ["RAPLAS_RT_LATENCY_OUT"], "w") as fh:
            fh.write(f"{latency}\n")
