# amaranth: UnusedElaboratable=no
"""The ULX3S board design (:class:`raplas_hdl.rtl.ulx3s_top.ULX3STop`) in the Amaranth
simulator, its PLL replaced by a stand-in (the EHXPLLL primitive has no simulation model
here): the oscillator passes through, and ``locked`` rises after a few of its cycles; the
reset's global buffer (``DCCA``, likewise) by a wire.

Checked, through the board's own ports as the board wires them: nothing answers and
``led_locked`` is dark until the PLL locks; then a UARTBone read of ``ID`` on ``uart_rx``
answers ``BOARD_ID`` on ``uart_tx``; an unmapped read lights ``led_bus_error``, which holds
until the FIRE button (``btn_fire``, high while pressed) resets the design; after the press
the board answers again.
"""

from amaranth.hdl import ClockDomain, Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out
from amaranth.sim import Simulator

import raplas_hdl.rtl.ulx3s_top as ulx3s_top
from raplas_hdl.fp import FP16
from raplas_hdl.model.board_map import BOARD_ID, REGISTERS
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.link_protocol import CMD_READ_INCR, command_bytes
from raplas_hdl.rtl.ecp5_pll import pll_settings
from tests.support.uartbone_bench import read_frame

DIVISOR = 4
CFG = UnitConfig(fmt=FP16, rows=1, cols=2, tris_per_sphere=1, max_triangles=4, max_spheres=2,
                 fifo_depth=3)
UNMAPPED = 0x1F
LOCK_CYCLES = 16
HALF = 0.5e-6


class PLLStandIn(wiring.Component):
    """:class:`raplas_hdl.rtl.ecp5_pll.ECP5PLL`'s ports: ``clk_out`` is ``clk_in``,
    ``locked`` rises after :data:`LOCK_CYCLES` of it."""

    clk_in: In(1)
    clk_out: Out(1)
    locked: Out(1)

    def __init__(self, settings):
        self.settings = settings
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        m.domains.osc = cd = ClockDomain("osc", local=True, reset_less=True)
        count = Signal(range(LOCK_CYCLES + 1))
        m.d.comb += [cd.clk.eq(self.clk_in), self.clk_out.eq(self.clk_in),
                     self.locked.eq(count == LOCK_CYCLES)]
        with m.If(count != LOCK_CYCLES):
            m.d.osc += count.eq(count + 1)
        return m


class GlobalBufferStandIn(wiring.Component):
    """:class:`raplas_hdl.rtl.ecp5_global.ECP5GlobalBuffer`'s ports: ``o`` is ``i``."""

    i: In(1)
    o: Out(1)

    def elaborate(self, platform):
        m = Module()
        m.d.comb += self.o.eq(self.i)
        return m


def simulate(monkeypatch, pll, host):
    """Run ``host(ctx, dut, received)`` against the board design with ``pll`` standing in
    for its PLL: the oscillator runs, and the bytes on ``uart_tx`` go to ``received``."""
    monkeypatch.setattr(ulx3s_top, "ECP5PLL", pll)
    monkeypatch.setattr(ulx3s_top, "ECP5GlobalBuffer", GlobalBufferStandIn)
    dut = ulx3s_top.ULX3STop(CFG, pll_settings(25.0, 62.5), DIVISOR, timeout=2000)
    sim = Simulator(dut)
    received = []

    async def oscillator(ctx):
        while True:
            ctx.set(dut.clk_25mhz, 0)
            await ctx.delay(HALF)
            ctx.set(dut.clk_25mhz, 1)
            await ctx.delay(HALF)

    async def listener(ctx):
        while True:
            received.append(await read_frame(ctx, dut.uart_tx, DIVISOR))

    async def testbench(ctx):
        await host(ctx, dut, received)

    sim.add_process(oscillator)
    sim.add_testbench(testbench)
    sim.add_testbench(listener, background=True)
    sim.run()


async def ticks(ctx, n):
    await ctx.delay(2 * HALF * n)


async def send(ctx, dut, data):
    """``data`` onto ``uart_rx``, 8N1, bit by bit."""
    for b in data:
        for bit in [0, *((b >> k) & 1 for k in range(8)), 1]:
            ctx.set(dut.uart_rx, bit)
            await ticks(ctx, DIVISOR)


def test_board_design_answers_on_its_pins_after_lock_and_resets_on_the_button(monkeypatch):
    async def host(ctx, dut, received):
        async def read(addr, wait=200 * DIVISOR):
            before = len(received)
            await send(ctx, dut, command_bytes(CMD_READ_INCR, addr, 1))
            for _ in range(wait):
                if len(received) >= before + 4:
                    break
                await ticks(ctx, 1)
            got = received[before:]
            return int.from_bytes(bytes(got[:4]), "big") if len(got) >= 4 else None

        ctx.set(dut.uart_rx, 1)
        await ticks(ctx, LOCK_CYCLES // 2)
        assert not ctx.get(dut.led_locked)
        await ticks(ctx, LOCK_CYCLES)
        assert ctx.get(dut.led_locked)
        await ticks(ctx, 16)                            # the reset synchroniser lets go
        assert await read(REGISTERS["ID"]) == BOARD_ID
        assert not ctx.get(dut.led_bus_error)
        assert await read(UNMAPPED) == 0                # a bus error reads 0 ...
        await ticks(ctx, 4)
        assert ctx.get(dut.led_bus_error)               # ... and lights its LED, held
        await ticks(ctx, 64)
        assert ctx.get(dut.led_bus_error)
        ctx.set(dut.btn_fire, 1)                        # FIRE 1 pressed: reset
        await ticks(ctx, 8)
        assert not ctx.get(dut.led_bus_error)
        ctx.set(dut.btn_fire, 0)
        await ticks(ctx, 16)
        assert not ctx.get(dut.led_bus_error)
        assert await read(REGISTERS["CFG_LATTICE"]) & 0xFFFF == CFG.rows | CFG.cols << 8

    simulate(monkeypatch, PLLStandIn, host)


def test_board_design_does_not_answer_before_lock(monkeypatch):
    """With the PLL never locking the board is held in reset: a read gets no answer."""
    class NeverLocks(PLLStandIn):
        def elaborate(self, platform):
            m = Module()
            m.d.comb += [self.clk_out.eq(self.clk_in), self.locked.eq(0)]
            return m

    async def host(ctx, dut, received):
        ctx.set(dut.uart_rx, 1)
        await ticks(ctx, 64)
        await send(ctx, dut, command_bytes(CMD_READ_INCR, REGISTERS["ID"], 1))
        await ticks(ctx, 400)
        assert received == [] and not ctx.get(dut.led_locked)
        assert not ctx.get(dut.led_rx)                  # held in reset: dark

    simulate(monkeypatch, NeverLocks, host)
