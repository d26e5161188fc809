"""The board design behind a serial port: the UARTBone bridge in front of the board top.

:class:`SerialBoard` is what a board carries and what the end-to-end simulation runs: the
serial lines go into :class:`~raplas_hdl.rtl.uartbone.UARTBone`, whose Wishbone master
drives :class:`~raplas_hdl.rtl.board_top.BoardTop` (the register map of
:mod:`raplas_hdl.model.board_map`; the bridge's own registers are
:mod:`raplas_hdl.model.link_protocol`'s). A host reaches it with
:class:`~raplas_hdl.link.serial_bus.SerialBus` under
:class:`~raplas_hdl.link.driver.BoardDriver`, or with LiteX's ``litex_server --uart``.

Ports: ``clk``; ``rst`` (active high, asynchronous: a button; synchronised inside, then
through ``reset_buffer`` when one is given: the FPGA's global buffer on a board); ``rx``,
``tx`` (8N1, idle high, ``divisor`` clocks per bit); ``leds`` (status, below).

LEDs (each a plain output; a board maps them to its LEDs):

- 0: heartbeat, toggling every ``2**heartbeat_bits`` clocks (the clock runs, reset is off);
- 1: a byte is arriving (the ``rx`` line low, held ``2**blink_bits`` clocks);
- 2: a byte is leaving (``tx`` low, held likewise);
- 3: a bus access is going (``wb_cyc``, held likewise);
- 4: an access was answered with a bus error since reset (sticky).
"""

from __future__ import annotations

from amaranth.hdl import ClockDomain, Module, Signal
from amaranth.lib import wiring
from amaranth.lib.cdc import ResetSynchronizer
from amaranth.lib.wiring import In, Out

from ..model.board_map import ADDR_BITS
from ..model.config import UnitConfig
from .board_top import BoardTop
from .uart import check_divisor
from .uartbone import DEFAULT_TIMEOUT, UARTBone

__all__ = ["SerialBoard", "LEDS"]

#: Status LEDs of :class:`SerialBoard`, in bit order.
LEDS = ("heartbeat", "rx", "tx", "bus", "bus_error")

_WB_TO_SLAVE = ("wb_adr", "wb_dat_w", "wb_sel", "wb_we", "wb_cyc", "wb_stb")
_WB_TO_MASTER = ("wb_dat_r", "wb_ack", "wb_err")


class SerialBoard(wiring.Component):
    """UARTBone bridge and board top, one clock.

    Parameters
    ----------
    config : UnitConfig
        The unit's build (see :class:`~raplas_hdl.rtl.board_top.BoardTop`).
    divisor : int
        Clocks per bit of the serial line (the clock over the baud rate).
    timeout : int
        Clocks without a byte after which the bridge drops an incomplete command.
    heartbeat_bits, blink_bits : int
        LED timing (module docstring); a simulation shortens nothing here.
    multiplier, adder : {"generic", "virtex4"}
        The unit's arithmetic targets.
    reset_buffer : callable or None
        Makes the component (``i`` in, ``o`` out) the synchronised reset passes through
        on its way to the design's flip-flops, e.g.
        :class:`~raplas_hdl.rtl.ecp5_global.ECP5GlobalBuffer`; None: straight.

    Members
    -------
    clk, rst, rx : In(1)
    tx : Out(1)
    leds : Out(len(LEDS))
    """

    def __init__(self, config: UnitConfig, divisor: int, *, timeout: int = DEFAULT_TIMEOUT,
                 heartbeat_bits: int = 24, blink_bits: int = 20,
                 multiplier: str = "generic", adder: str = "generic", reset_buffer=None):
        check_divisor(divisor)
        self.reset_buffer = reset_buffer
        self.board = BoardTop(config, multiplier=multiplier, adder=adder, own_domain=False)
        self.divisor, self.timeout = divisor, timeout
        self.heartbeat_bits, self.blink_bits = int(heartbeat_bits), int(blink_bits)
        super().__init__({"clk": In(1), "rst": In(1), "rx": In(1, init=1),
                          "tx": Out(1, init=1), "leds": Out(len(LEDS))})

    @property
    def config(self) -> UnitConfig:
        return self.board.config

    def elaborate(self, platform):
        m = Module()
        m.domains.sync = cd = ClockDomain("sync")
        m.d.comb += cd.clk.eq(self.clk)
        if self.reset_buffer is None:
            m.submodules.reset_sync = ResetSynchronizer(self.rst, domain="sync")
        else:       # synchronised in a domain of its own, then buffered into sync's reset
            m.domains.reset_sync = rcd = ClockDomain("reset_sync", local=True)
            m.d.comb += rcd.clk.eq(self.clk)
            m.submodules.reset_sync = ResetSynchronizer(self.rst, domain="reset_sync")
            m.submodules.reset_buffer = buf = self.reset_buffer()
            m.d.comb += [buf.i.eq(rcd.rst), cd.rst.eq(buf.o)]
        m.submodules.bridge = bridge = UARTBone(self.divisor, ADDR_BITS, timeout=self.timeout)
        m.submodules.board = board = self.board
        m.d.comb += [bridge.rx.eq(self.rx), self.tx.eq(bridge.tx)]
        for name in _WB_TO_SLAVE:
            m.d.comb += getattr(board, name).eq(getattr(bridge, name))
        for name in _WB_TO_MASTER:
            m.d.comb += getattr(bridge, name).eq(getattr(board, name))

        beat = Signal(self.heartbeat_bits + 1)
        m.d.sync += beat.eq(beat + 1)
        leds = {"heartbeat": beat[-1]}
        for name, active in (("rx", ~self.rx), ("tx", ~bridge.tx), ("bus", bridge.wb_cyc)):
            # counts up to its top bit after the activity: dark from reset until activity
            hold = Signal(self.blink_bits + 1, name=f"{name}_hold", init=1 << self.blink_bits)
            with m.If(active):
                m.d.sync += hold.eq(0)
            with m.Elif(~hold[-1]):
                m.d.sync += hold.eq(hold + 1)
            leds[name] = ~hold[-1]
        err = Signal()
        with m.If(board.wb_err):
            m.d.sync += err.eq(1)
        leds["bus_error"] = err
        for k, name in enumerate(LEDS):
            m.d.comb += self.leds[k].eq(leds[name])
        return m
