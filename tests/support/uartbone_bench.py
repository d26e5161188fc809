# amaranth: UnusedElaboratable=no
"""The UARTBone bridge in front of a small Wishbone slave, in the Amaranth simulator: the
bench of ``tests/rtl/test_uartbone.py`` (frames driven bit by bit) and of
``tests/link/test_serial_bus.py`` (the bridge's serial lines on a pseudo-terminal, so that
:class:`~raplas_hdl.link.serial_bus.SerialBus` opens it by name as it would a board's port).
"""

import os
import threading
import tty

from amaranth.hdl import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out
from amaranth.sim import Simulator

from raplas_hdl.rtl.uartbone import UARTBone

DIVISOR = 4
WORDS = 12          # the slave's words; addresses 12 .. 255 answer err
TIMEOUT = 200


class WishboneRam(wiring.Component):
    """``WORDS`` words behind a Wishbone B4 classic slave timed as the board top's."""

    wb_adr: In(8)
    wb_dat_w: In(32)
    wb_dat_r: Out(32)
    wb_sel: In(4)
    wb_we: In(1)
    wb_cyc: In(1)
    wb_stb: In(1)
    wb_ack: Out(1)
    wb_err: Out(1)

    def elaborate(self, platform):
        m = Module()
        mem = [Signal(32, name=f"w{k}") for k in range(WORDS)]
        req = self.wb_cyc & self.wb_stb & ~self.wb_ack & ~self.wb_err
        m.d.sync += [self.wb_ack.eq(0), self.wb_err.eq(0)]
        with m.If(req):
            with m.If(self.wb_adr < WORDS):
                m.d.sync += self.wb_ack.eq(1)
                with m.Switch(self.wb_adr):
                    for k in range(WORDS):
                        with m.Case(k):
                            m.d.sync += self.wb_dat_r.eq(mem[k])
                            with m.If(self.wb_we):
                                m.d.sync += mem[k].eq(self.wb_dat_w)
            with m.Else():
                m.d.sync += self.wb_err.eq(1)
        return m


class Bench(wiring.Component):
    """The bridge (``DIVISOR`` clocks per bit) and a :class:`WishboneRam` behind it."""

    rx: In(1, init=1)
    tx: Out(1)

    def __init__(self, timeout: int = TIMEOUT):
        self.timeout = timeout
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        m.submodules.bridge = bridge = UARTBone(DIVISOR, 8, timeout=self.timeout)
        m.submodules.ram = ram = WishboneRam()
        for name in ("wb_adr", "wb_dat_w", "wb_sel", "wb_we", "wb_cyc", "wb_stb"):
            m.d.comb += getattr(ram, name).eq(getattr(bridge, name))
        for name in ("wb_dat_r", "wb_ack", "wb_err"):
            m.d.comb += getattr(bridge, name).eq(getattr(ram, name))
        m.d.comb += [bridge.rx.eq(self.rx), self.tx.eq(bridge.tx)]
        return m




async def read_frame(ctx, tx, divisor: int = DIVISOR) -> int:
    """The next 8N1 byte on ``tx``: wait for a start bit, sample each bit in its middle."""
    while ctx.get(tx):
        await ctx.tick()
    await ctx.tick().repeat(divisor // 2)
    value = 0
    for k in range(8):
        await ctx.tick().repeat(divisor)
        value |= ctx.get(tx) << k
    await ctx.tick().repeat(divisor)
    return value


class PtyBridge:
    """A :class:`Bench` simulated in a thread, its serial lines on a pseudo-terminal: the
    bytes a host writes to :attr:`name` go onto ``rx`` frame by frame, bit by bit; the
    frames on ``tx`` are decoded and come back to the host. ``close()`` stops it.

    Faults on the way to the bridge: ``corrupt = {k: mask}`` XORs the host's ``k``-th byte
    (from 0) with ``mask``; ``drop = {k, ...}`` loses those bytes."""

    def __init__(self, timeout: int = TIMEOUT, corrupt=None, drop=()):
        corrupt, drop = dict(corrupt or {}), set(drop)
        count = [0]
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self.master, False)
        self.name = os.ttyname(self._slave)
        self._stop = threading.Event()
        self.error = None
        dut = Bench(timeout)
        sim = Simulator(dut)
        sim.add_clock(1e-6)

        async def host_to_rx(ctx):
            while not self._stop.is_set():
                try:
                    data = os.read(self.master, 64)
                except BlockingIOError:
                    data = b""
                if not data:
                    await ctx.tick().repeat(4 * DIVISOR)
                    continue
                for b in data:
                    k, count[0] = count[0], count[0] + 1
                    if k in drop:
                        continue
                    b ^= corrupt.get(k, 0)
                    for bit in [0, *((b >> k) & 1 for k in range(8)), 1]:
                        ctx.set(dut.rx, bit)
                        await ctx.tick().repeat(DIVISOR)

        async def tx_to_host(ctx):
            while True:
                os.write(self.master, bytes([await read_frame(ctx, dut.tx)]))

        sim.add_testbench(host_to_rx)
        sim.add_testbench(tx_to_host, background=True)

        def run():
            try:
                sim.run()
            except BaseException as exc:    # noqa: BLE001 - reported by close()
                self.error = exc

        self._thread = threading.Thread(target=run, daemon=True)
        self._thread.start()

    def close(self):
        self._stop.set()
        self._thread.join(timeout=30)
        os.close(self.master)
        os.close(self._slave)
        if self.error is not None:
            raise self.error
