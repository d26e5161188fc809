"""A UART: 8N1 bytes on two pins, as byte streams (``amaranth.lib.stream``).

``divisor`` is clocks per bit: the unit's clock over the baud rate (at 50 MHz, 3 Mbaud is a
divisor of 16.7, so 17 gives 2.94 Mbaud, 2 % slow, within the 8N1 frame's tolerance). Both
ends are one clock domain, ``sync``.

- :class:`UARTRx` samples ``rx`` through a two-flop synchroniser, finds a start bit's
  falling edge, samples each bit in its middle and sends the byte on its ``o`` stream when
  the stop bit is high. A receiver cannot hold the line, so a byte that ``o`` has not taken
  when the next one is complete is lost, and so is a frame whose stop bit is low: each
  loss is one pulse of ``lost``.
- :class:`UARTTx` sends the bytes of its ``i`` stream, one frame each, back to back.
"""

from amaranth.hdl import Cat, Module, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

__all__ = ["UARTRx", "UARTTx", "MIN_DIVISOR", "check_divisor"]

#: Fewest clocks per bit: the receiver samples a bit in its middle, after a two-flop
#: synchroniser.
MIN_DIVISOR = 4


def check_divisor(divisor) -> int:
    """``divisor``, or a one-line ``ValueError`` when it is not a whole number of clocks per
    bit of at least :data:`MIN_DIVISOR`."""
    if not isinstance(divisor, int) or isinstance(divisor, bool) or divisor < MIN_DIVISOR:
        raise ValueError(f"a UART divisor is clocks per bit, an integer of at least "
                         f"{MIN_DIVISOR}, not {divisor!r}")
    return divisor


class UARTRx(wiring.Component):
    """8N1 receiver.

    Members
    -------
    rx : In(1)
        The line (idle high).
    o : Out(stream.Signature(8))
        Received bytes.
    lost : Out(1)
        One clock per byte lost (a low stop bit, or ``o`` still holding the previous byte).
    """

    rx: In(1, init=1)
    o: Out(stream.Signature(8))
    lost: Out(1)

    def __init__(self, divisor: int):
        self.divisor = check_divisor(divisor)
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        d = self.divisor
        line = Signal(init=1)
        m.submodules.sync_rx = FFSynchronizer(self.rx, line, init=1)
        count = Signal(range(d))
        bit = Signal(range(10))
        shift = Signal(8)
        m.d.sync += self.lost.eq(0)
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        with m.FSM():
            with m.State("idle"):
                with m.If(~line):
                    m.d.sync += count.eq(d // 2 - 1)
                    m.next = "start"
            with m.State("start"):          # to the middle of the start bit
                with m.If(count != 0):
                    m.d.sync += count.eq(count - 1)
                with m.Elif(line):          # a glitch, not a start bit
                    m.next = "idle"
                with m.Else():
                    m.d.sync += [count.eq(d - 1), bit.eq(0)]
                    m.next = "data"
            with m.State("data"):           # the middle of each data bit, then the stop bit
                with m.If(count != 0):
                    m.d.sync += count.eq(count - 1)
                with m.Elif(bit == 8):
                    with m.If(line & ~(self.o.valid & ~self.o.ready)):
                        m.d.sync += [self.o.payload.eq(shift), self.o.valid.eq(1)]
                    with m.Else():
                        m.d.sync += self.lost.eq(1)
                    m.next = "idle"
                with m.Else():
                    m.d.sync += [shift.eq(Cat(shift[1:], line)),     # bit 0 first
                                 count.eq(d - 1), bit.eq(bit + 1)]
        return m


class UARTTx(wiring.Component):
    """8N1 transmitter.

    Members
    -------
    i : In(stream.Signature(8))
        Bytes to send.
    tx : Out(1)
        The line (idle high).
    """

    i: In(stream.Signature(8))
    tx: Out(1, init=1)

    def __init__(self, divisor: int):
        self.divisor = check_divisor(divisor)
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        d = self.divisor
        frame = Signal(10, init=0x3FF)     # start, 8 data bits, stop: bit 0 on the line
        left = Signal(range(11))
        count = Signal(range(d))
        m.d.comb += [self.tx.eq(frame[0]), self.i.ready.eq(left == 0)]
        with m.If(left == 0):
            with m.If(self.i.valid):
                m.d.sync += [frame.eq((1 << 9) | (self.i.payload << 1)), left.eq(10),
                             count.eq(d - 1)]
        with m.Elif(count != 0):
            m.d.sync += count.eq(count - 1)
        with m.Else():
            m.d.sync += [frame.eq((frame >> 1) | (1 << 9)), left.eq(left - 1),
                         count.eq(d - 1)]
        return m
