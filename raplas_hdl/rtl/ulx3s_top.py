"""The serial board on the ULX3S: its oscillator through a PLL, its button, FTDI and LEDs.

:class:`ULX3STop` is what ``raplas-hdl bitstream --board ulx3s-85f`` places: the
:class:`~raplas_hdl.rtl.serial_board.SerialBoard` (UARTBone bridge, board top, unit) clocked
by an :class:`~raplas_hdl.rtl.ecp5_pll.ECP5PLL` from the board's 25 MHz oscillator. Each port
is one pin (:data:`raplas_hdl.pnr.board.ULX3S_BOARD_PINS` names them):

- ``clk_25mhz``: the oscillator, into the PLL;
- ``btn_fire``: the FIRE 1 button, high while pressed: reset, with the PLL unlocked
  (:class:`SerialBoard` synchronises it, and it reaches the flip-flops through an
  :class:`~raplas_hdl.rtl.ecp5_global.ECP5GlobalBuffer`, on the global network);
- ``uart_rx``, ``uart_tx``: the FTDI's serial lines (8N1, ``divisor`` clocks per bit);
- ``led_<name>`` for each of :data:`raplas_hdl.rtl.serial_board.LEDS` and ``led_locked``
  (the PLL locked), LEDs 0 to 5 of the board.
"""

from __future__ import annotations

from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..model.config import UnitConfig
from .ecp5_global import ECP5GlobalBuffer
from .ecp5_pll import ECP5PLL, PLLSettings
from .serial_board import LEDS, SerialBoard
from .uartbone import DEFAULT_TIMEOUT

__all__ = ["ULX3STop", "BOARD_LEDS"]

#: The LEDs of :class:`ULX3STop`, LED 0 first.
BOARD_LEDS = LEDS + ("locked",)


class ULX3STop(wiring.Component):
    """PLL and serial board, every port a pin of the ULX3S.

    Parameters
    ----------
    config : UnitConfig
        The unit's build.
    pll : PLLSettings
        The clock (:func:`~raplas_hdl.rtl.ecp5_pll.pll_settings` from 25 MHz).
    divisor : int
        Clocks per bit of the serial line (the PLL's output over the baud rate).
    timeout : int
        The bridge's command timeout in clocks.
    """

    def __init__(self, config: UnitConfig, pll: PLLSettings, divisor: int, *,
                 timeout: int = DEFAULT_TIMEOUT):
        self.pll = pll
        self.board = SerialBoard(config, divisor, timeout=timeout,
                                 reset_buffer=ECP5GlobalBuffer)
        ports = {"clk_25mhz": In(1), "btn_fire": In(1), "uart_rx": In(1, init=1),
                 "uart_tx": Out(1, init=1)}
        ports.update({f"led_{name}": Out(1) for name in BOARD_LEDS})
        super().__init__(ports)

    @property
    def config(self) -> UnitConfig:
        return self.board.config

    def elaborate(self, platform):
        m = Module()
        m.submodules.pll = pll = ECP5PLL(self.pll)
        m.submodules.serial_board = board = self.board
        m.d.comb += [
            pll.clk_in.eq(self.clk_25mhz),
            board.clk.eq(pll.clk_out),
            board.rst.eq(self.btn_fire | ~pll.locked),
            board.rx.eq(self.uart_rx),
            self.uart_tx.eq(board.tx),
            self.led_locked.eq(pll.locked),
        ]
        for k, name in enumerate(LEDS):
            m.d.comb += getattr(self, f"led_{name}").eq(board.leds[k])
        return m
