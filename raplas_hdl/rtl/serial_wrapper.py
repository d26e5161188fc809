"""A serial-in / serial-out wrapper: any unit on six pins of a board (the ULX3S bitstream).

No unit fits a board's free pins as it is (an FP adder has 79 port bits, the ray-triangle
unit 620), so ``raplas-hdl pnr UNIT --bitstream`` builds the unit behind this wrapper: every
input port of the unit is driven from a holding register loaded from a shift register fed
bit by bit from one pin, and every output port is captured into a shift register read out
bit by bit on one pin. The unit is taken by its signature (``amaranth.lib.wiring``), so any
component whose ports are plain or nested signals is wrapped the same way.

Ports (one clock domain, ``sync``, clocked by ``clk_25mhz``)::

    clk_25mhz  in   the clock (the ULX3S's 25 MHz oscillator)
    rst        in   reset, active high, asynchronous (a button): synchronised inside
    sclk       in   the host's shift clock: a rising edge shifts one bit in and one out
    sdi        in   serial data in, sampled at a rising edge of ``sclk``
    load       in   while high: the unit's inputs take the shifted-in word, the output
                    register takes the unit's outputs
    sdo        out  serial data out: bit 0 of the output register

``sclk``, ``sdi`` and ``load`` are sampled through two-flop synchronisers, so the host needs
no timing relation to the clock: it holds each level for a few clocks (at 25 MHz, a
microsecond is plenty). A transaction:

1. with ``load`` low, send the unit's input word (:attr:`SerialWrapper.in_fields`), bit 0
   first: set ``sdi``, raise ``sclk``, lower it, ``in_bits`` times;
2. raise ``load`` for at least the unit's latency plus :data:`SYNC_CYCLES` clocks: the unit's
   inputs hold the word (a pipelined unit with ``i_valid`` and ``en`` in its word computes
   the same operation every clock), and the output register follows the unit's outputs;
3. lower ``load``: the output register keeps the last outputs; read ``sdo`` (bit 0 of the
   output word, :attr:`SerialWrapper.out_fields`), then each rising edge of ``sclk`` shows
   the next bit. The bits shifted in meanwhile are the next operation's word.

The unit's inputs keep the last loaded word between transactions (all zero after
configuration). :meth:`SerialWrapper.pack` and :meth:`SerialWrapper.unpack` turn port values
into the words and back. A unit with its own clock port (``clk``) is refused: its clock
cannot come from a register.
"""

from __future__ import annotations

from amaranth.hdl import Cat, ClockDomain, Module, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer, ResetSynchronizer
from amaranth.lib.wiring import In, Out

__all__ = ["SerialWrapper", "unit_fields", "CLOCK_PORT", "RESET_PORT", "SERIAL_PORTS",
           "SYNC_CYCLES"]

#: The clock port (named as on the ULX3S's own pin file) and the reset port.
CLOCK_PORT = "clk_25mhz"
RESET_PORT = "rst"

#: The serial ports: shift clock, data in, load strobe, data out.
SERIAL_PORTS = ("sclk", "sdi", "load", "sdo")

#: Clocks from a pin's change to its effect inside (two synchroniser flops, one edge flop).
SYNC_CYCLES = 3


def unit_fields(unit: wiring.Component) -> tuple[list[tuple], list[tuple]]:
    """The unit's input and output ports as ``[(name, offset, width, value), ...]``.

    Ports in the signature's order; offsets count from bit 0 of the input (output) word.
    Nested signatures give names joined by ``__``, as in the emitted Verilog."""
    fields = {In: [], Out: []}
    offsets = {In: 0, Out: 0}
    for path, member, value in unit.signature.flatten(unit):
        value = Value.cast(value)
        flow = member.flow
        fields[flow].append(("__".join(map(str, path)), offsets[flow], len(value), value))
        offsets[flow] += len(value)
    return fields[In], fields[Out]


class SerialWrapper(wiring.Component):
    """``unit`` behind a serial-in / serial-out interface (module docstring).

    Parameters
    ----------
    unit : amaranth.lib.wiring.Component
        The unit; clocked by the wrapper's ``sync`` domain.

    Attributes
    ----------
    clk_25mhz, rst, sclk, sdi, load : In(1)
    sdo : Out(1)
    in_fields, out_fields : list of (name, offset, width)
        The unit's input and output ports in the serial words, bit 0 first.
    in_bits, out_bits : int
        Lengths of the input and output words.

    Raises
    ------
    ValueError
        If ``unit`` has its own clock port, or no input or no output port.
    """

    def __init__(self, unit: wiring.Component):
        if not isinstance(unit, wiring.Component):
            raise ValueError(f"the unit must be an amaranth.lib.wiring.Component, not {unit!r}")
        ins, outs = unit_fields(unit)
        own = sorted({n for n, *_ in ins} & {"clk", CLOCK_PORT})
        if own:
            raise ValueError(f"the unit has its own clock port {own[0]!r}: the serial wrapper "
                             "clocks the unit and drives its ports from registers")
        if not ins or not outs:
            raise ValueError("the unit needs at least one input and one output port")
        self._unit = unit
        self._ins, self._outs = ins, outs
        super().__init__({CLOCK_PORT: In(1), RESET_PORT: In(1), "sclk": In(1), "sdi": In(1),
                          "load": In(1), "sdo": Out(1)})

    @property
    def unit(self) -> wiring.Component:
        return self._unit

    @property
    def latency(self):
        """The unit's latency (``None`` when it has none)."""
        return getattr(self._unit, "latency", None)

    @property
    def in_fields(self) -> list[tuple[str, int, int]]:
        return [f[:3] for f in self._ins]

    @property
    def out_fields(self) -> list[tuple[str, int, int]]:
        return [f[:3] for f in self._outs]

    @property
    def in_bits(self) -> int:
        return sum(f[2] for f in self._ins)

    @property
    def out_bits(self) -> int:
        return sum(f[2] for f in self._outs)

    def pack(self, values: dict) -> int:
        """The input word of ``{port: int}`` (ports left out are 0). ``ValueError`` for an
        unknown port or a value that does not fit it."""
        known = {name: (off, width) for name, off, width in self.in_fields}
        word = 0
        for name, v in values.items():
            if name not in known:
                raise ValueError(f"{name!r} is not an input port of the unit "
                                 f"({', '.join(known)})")
            off, width = known[name]
            if not 0 <= int(v) < (1 << width):
                raise ValueError(f"{name} = {v} does not fit its {width} bit(s)")
            word |= int(v) << off
        return word

    def unpack(self, word: int) -> dict:
        """``{port: int}`` of an output word."""
        return {name: (word >> off) & ((1 << width) - 1) for name, off, width in self.out_fields}

    def elaborate(self, platform):
        m = Module()
        m.domains.sync = cd = ClockDomain("sync")
        m.d.comb += cd.clk.eq(getattr(self, CLOCK_PORT))
        m.submodules.reset_sync = ResetSynchronizer(getattr(self, RESET_PORT), domain="sync")
        m.submodules.unit = self._unit

        sclk, sdi, load = Signal(name="sclk_s"), Signal(name="sdi_s"), Signal(name="load_s")
        for name, sig in (("sclk", sclk), ("sdi", sdi), ("load", load)):
            m.submodules[f"sync_{name}"] = FFSynchronizer(getattr(self, name), sig)
        sclk_last = Signal()
        m.d.sync += sclk_last.eq(sclk)
        step = Signal()
        m.d.comb += step.eq(sclk & ~sclk_last)

        shift_in = Signal(self.in_bits)
        held = Signal(self.in_bits)
        shift_out = Signal(self.out_bits)
        with m.If(step):
            m.d.sync += shift_in.eq(Cat(shift_in[1:], sdi))
        with m.If(load):
            m.d.sync += [held.eq(shift_in), shift_out.eq(Cat(*(v for *_, v in self._outs)))]
        with m.Elif(step):
            m.d.sync += shift_out.eq(shift_out[1:])
        m.d.comb += [v.eq(held[off:off + width]) for _, off, width, v in self._ins]
        m.d.comb += self.sdo.eq(shift_out[0])
        return m
