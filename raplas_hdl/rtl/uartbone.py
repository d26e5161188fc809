"""UARTBone: a Wishbone B4 classic master driven from a serial port, in LiteX's protocol.

The wire protocol and the link's own registers (``LINK_ID``, ``LINK_CRC``, ``LINK_ERRORS``,
``LINK_RX``) are :mod:`raplas_hdl.model.link_protocol`; LiteX's ``litex_server --uart`` and
its ``CommUART`` speak to it unchanged. In front of :class:`~raplas_hdl.rtl.board_top.BoardTop`
it makes the board's register map reachable from a host's serial port
(:class:`raplas_hdl.link.serial_bus.SerialBus`).

Received bytes wait in a FIFO of :data:`RX_FIFO_DEPTH` (a host may send several read
commands at once and read the answers together). One access at a time: a write's word is
complete, or a read's command is, then the bus cycle runs (``wb_cyc``/``wb_stb`` until ``wb_ack`` or ``wb_err``), then a read's word goes
back, most significant byte first. Addresses at or above ``2**addr_bits`` outside the link
block, and accesses the slave answers with ``wb_err``, count in ``LINK_ERRORS``; a read of
either answers 0. Every completed access's data word feeds ``LINK_CRC``. A command left
incomplete for ``timeout`` clocks (a byte lost on the way) is dropped, so the next command
starts clean; LiteX's bridge does the same.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.fifo import SyncFIFOBuffered
from amaranth.lib.wiring import In, Out

from ..model.link_protocol import (COMMANDS, LINK_BASE, LINK_ID, LINK_REGS, LINK_SPAN,
                                   crc_step_matrix)
from .uart import UARTRx, UARTTx, check_divisor

__all__ = ["UARTBone", "DEFAULT_TIMEOUT", "RX_FIFO_DEPTH"]

#: Bytes the receive FIFO holds: the commands a host sends together while the bridge
#: answers the first (``SerialBus.read_bursts``: 64 reads of 6 bytes), in one block RAM.
RX_FIFO_DEPTH = 512

#: Clocks without a byte after which an incomplete command is dropped (84 ms at 50 MHz:
#: longer than a USB serial adapter's latency timer).
DEFAULT_TIMEOUT = 1 << 22


def crc_next(state, word):
    """The CRC register after ``word`` (:func:`~raplas_hdl.model.link_protocol.crc_step_matrix`),
    as an Amaranth value."""
    s_rows, w_rows = crc_step_matrix()
    bits = []
    for k in range(32):
        terms = [state[i] for i in range(32) if s_rows[k] >> i & 1]
        terms += [word[j] for j in range(32) if w_rows[k] >> j & 1]
        bits.append(Cat(*terms).xor())
    return Cat(*bits)


class UARTBone(wiring.Component):
    """A Wishbone master behind a UART.

    Parameters
    ----------
    divisor : int
        Clocks per bit (:mod:`raplas_hdl.rtl.uart`).
    addr_bits : int
        Width of the slave's word address: accesses below ``2**addr_bits`` go to the bus.
    timeout : int
        Clocks without a byte after which an incomplete command is dropped.

    Members
    -------
    rx : In(1)
    tx : Out(1)
        The serial lines (idle high).
    wb_adr : Out(addr_bits)
    wb_dat_w : Out(32)
    wb_dat_r : In(32)
    wb_sel : Out(4)
        Always all ones.
    wb_we, wb_cyc, wb_stb : Out(1)
    wb_ack, wb_err : In(1)
    """

    def __init__(self, divisor: int, addr_bits: int, timeout: int = DEFAULT_TIMEOUT):
        if not isinstance(addr_bits, int) or not 1 <= addr_bits <= 30:
            raise ValueError(f"addr_bits must be an integer in 1..30, not {addr_bits!r}")
        if not isinstance(timeout, int) or timeout < 1:
            raise ValueError(f"timeout must be a positive number of clocks, not {timeout!r}")
        self.divisor, self.addr_bits, self.timeout = divisor, addr_bits, timeout
        check_divisor(divisor)
        super().__init__({
            "rx": In(1, init=1), "tx": Out(1, init=1),
            "wb_adr": Out(addr_bits), "wb_dat_w": Out(32), "wb_dat_r": In(32),
            "wb_sel": Out(4), "wb_we": Out(1), "wb_cyc": Out(1), "wb_stb": Out(1),
            "wb_ack": In(1), "wb_err": In(1),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.rx = rx = UARTRx(self.divisor)
        m.submodules.tx = tx = UARTTx(self.divisor)
        # the bytes of commands that arrive while the bridge answers an earlier one
        m.submodules.rx_fifo = rx_fifo = SyncFIFOBuffered(width=8, depth=RX_FIFO_DEPTH)
        wiring.connect(m, rx.o, rx_fifo.w_stream)
        cmd_in = rx_fifo.r_stream
        m.d.comb += [rx.rx.eq(self.rx), self.tx.eq(tx.tx), self.wb_sel.eq(0b1111)]

        write = Signal()
        fixed = Signal()
        left = Signal(8)            # words still to do in this command
        addr = Signal(32)
        data = Signal(32)
        nbyte = Signal(2)           # bytes of the address or data word taken so far
        crc = Signal(32, init=0xFFFF_FFFF)
        errors = Signal(32)
        lost = Signal(32)
        idle = Signal(range(self.timeout + 1))
        with m.If(rx.lost):
            m.d.sync += lost.eq(lost + 1)

        byte = cmd_in.payload
        got = cmd_in.valid & cmd_in.ready
        local = (addr >= LINK_BASE) & (addr < LINK_BASE + LINK_SPAN)
        on_bus = addr < (1 << self.addr_bits)
        link_rd = Signal(32)
        with m.Switch(addr):
            with m.Case(LINK_REGS["LINK_ID"]):
                m.d.comb += link_rd.eq(LINK_ID)
            with m.Case(LINK_REGS["LINK_CRC"]):
                m.d.comb += link_rd.eq(~crc)
            with m.Case(LINK_REGS["LINK_ERRORS"]):
                m.d.comb += link_rd.eq(errors)
            with m.Case(LINK_REGS["LINK_RX"]):
                m.d.comb += link_rd.eq(lost)

        def take_byte():
            """In a state that waits for a byte of a command: take it, or drop the command
            after ``timeout`` clocks without one."""
            m.d.comb += cmd_in.ready.eq(1)
            with m.If(~got):
                with m.If(idle == self.timeout):
                    m.d.sync += idle.eq(0)
                    m.next = "cmd"
                with m.Else():
                    m.d.sync += idle.eq(idle + 1)

        def shift_in(reg):
            """Take the byte into ``reg``'s low end (a word arrives most significant byte
            first)."""
            m.d.sync += [reg.eq(Cat(byte, reg[:24])), nbyte.eq(nbyte + 1), idle.eq(0)]

        def next_word():
            """After a word: the next one of the command, or the next command."""
            m.d.sync += left.eq(left - 1)
            with m.If(~fixed):
                m.d.sync += addr.eq(addr + 1)
            with m.If(left == 1):
                m.next = "cmd"
            with m.Elif(write):
                m.next = "wdata"
            with m.Else():
                m.next = "access"

        with m.FSM():
            with m.State("cmd"):
                m.d.comb += cmd_in.ready.eq(1)
                with m.If(got):
                    with m.Switch(byte):
                        for code, (w, f) in COMMANDS.items():
                            with m.Case(code):
                                m.d.sync += [write.eq(int(w)), fixed.eq(int(f)), idle.eq(0)]
                                m.next = "len"
            with m.State("len"):    # a dropped command may have left nbyte mid-word
                take_byte()
                with m.If(got):
                    m.d.sync += [left.eq(byte), nbyte.eq(0), idle.eq(0)]
                    m.next = "addr"
            with m.State("addr"):     # nbyte wraps to 0 with the fourth byte of a word
                take_byte()
                with m.If(got):
                    shift_in(addr)
                    with m.If(nbyte == 3):
                        with m.If(left == 0):
                            m.next = "cmd"
                        with m.Elif(write):
                            m.next = "wdata"
                        with m.Else():
                            m.next = "access"
            with m.State("wdata"):
                take_byte()
                with m.If(got):
                    shift_in(data)
                    with m.If(nbyte == 3):
                        m.next = "access"
            with m.State("access"):
                with m.If(local):
                    with m.If(write):
                        with m.Switch(addr):
                            with m.Case(LINK_REGS["LINK_CRC"]):
                                m.d.sync += crc.eq(0xFFFF_FFFF)
                            with m.Case(LINK_REGS["LINK_ERRORS"]):
                                m.d.sync += errors.eq(0)
                            with m.Case(LINK_REGS["LINK_RX"]):
                                m.d.sync += lost.eq(0)
                        next_word()
                    with m.Else():
                        m.d.sync += data.eq(link_rd)
                        m.next = "send"
                with m.Elif(on_bus):
                    m.d.comb += [self.wb_cyc.eq(1), self.wb_stb.eq(1), self.wb_we.eq(write),
                                 self.wb_adr.eq(addr), self.wb_dat_w.eq(data)]
                    with m.If(self.wb_ack | self.wb_err):
                        word = Mux(write, data, self.wb_dat_r)
                        with m.If(self.wb_ack):
                            m.d.sync += crc.eq(crc_next(crc, word))
                        with m.Else():
                            m.d.sync += errors.eq(errors + 1)
                        with m.If(write):
                            next_word()
                        with m.Else():
                            m.d.sync += data.eq(Mux(self.wb_ack, self.wb_dat_r, 0))
                            m.next = "send"
                with m.Else():
                    m.d.sync += errors.eq(errors + 1)
                    with m.If(write):
                        next_word()
                    with m.Else():
                        m.d.sync += data.eq(0)
                        m.next = "send"
            with m.State("send"):            # the read word, most significant byte first
                m.d.comb += [tx.i.valid.eq(1), tx.i.payload.eq(data[24:])]
                with m.If(tx.i.ready):
                    m.d.sync += [data.eq(data << 8), nbyte.eq(nbyte + 1)]
                    with m.If(nbyte == 3):
                        next_word()
        return m
