"""A buffered FIFO behind a writer that holds credits: every write is taken.

:class:`CreditFIFO` is Amaranth's :class:`~amaranth.lib.fifo.SyncFIFOBuffered` cycle for
cycle (an inner FIFO of ``depth - 1`` words in a memory with a synchronous read port, then
the output register that ``r_stream`` shows), except that a write does not look at the
FIFO's level: its writers (the record fetch, the sphere feeder) start an item only while they
hold a credit for a free entry, so the entry is there when the item arrives.
``w_stream.ready`` still says whether it is (the record fetch's ``overflow`` flag watches
it), but it gates nothing.

Why: in ``SyncFIFOBuffered`` the write enable is ``w_en & w_rdy``, so the level feeds the
level through the write enable, which also enables every bit of the memory. Placed and
routed, that LUT sits among the memory's distributed RAM, far from the level register: the
certified whole unit's pair FIFO took 11.7 ns (85.2 MHz, ECP5 speed 6, seed 1), 7.4 ns of it
two routes. Here the write enable is the writer's valid register alone.

Banks: with ``banks=K`` the words are cut into ``K`` slices, each in a CreditFIFO of its own
with its own pointers, level and head flag (the same writes and reads, so the same state in
every bank; each bank's state feeds back on itself, so synthesis cannot merge the banks). The
read enable loads the output register, every bit of it: placed and routed, that one net to
the certified pair FIFO's 447 output bits took 6.6 to 8.7 ns of one route (seeds 1 and 3).
Banked, each read enable reaches one slice.
"""

from __future__ import annotations

from amaranth.hdl import Module, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..ram import incr_modulo

__all__ = ["CreditFIFO"]


class CreditFIFO(wiring.Component):
    """``depth`` words of ``width`` bits; writes are never refused (module docstring).

    Parameters
    ----------
    width : int
        Bits per word.
    depth : int
        Words held, at least 3: ``depth - 1`` in the memory and one in the output register
        (the writers' credits: ``depth`` at reset, one back a cycle after each read; with 2,
        the memory's one word cannot be written while it moves to the output register).

    Members
    -------
    w_stream : In(stream.Signature(width))
        A word is written on every cycle with ``valid`` high; ``ready`` is high while an
        entry is free (what the writer's credits promise).
    r_stream : Out(stream.Signature(width))
        The head word, from a register.
    level : Out(range(depth + 1))
        Words held.
    banks : int
        Slices the words are cut into, each a FIFO of its own (module docstring); at most
        ``width``.
    """

    def __init__(self, *, width: int, depth: int, banks: int = 1):
        if depth < 3:
            self._MustUse__silence = True          # refused: never to be elaborated
            raise ValueError(f"a CreditFIFO holds at least 3 words, not {depth}")
        if not 1 <= banks <= width:
            self._MustUse__silence = True
            raise ValueError(f"a CreditFIFO of {width} bits takes 1 to {width} banks, "
                             f"not {banks}")
        self.width, self.depth, self.banks = width, depth, banks
        super().__init__({"w_stream": In(stream.Signature(width)),
                          "r_stream": Out(stream.Signature(width)),
                          "level": Out(range(depth + 1))})

    def elaborate(self, platform):
        if self.banks > 1:
            return self._banked()
        m = Module()
        inner_depth = self.depth - 1
        inner_level = Signal(range(inner_depth + 1))
        head = self.r_stream.valid                     # the output register holds a word
        do_write = self.w_stream.valid                 # the credits made room
        do_inner_read = (inner_level != 0) & (~head | self.r_stream.ready)

        m.submodules.storage = storage = Memory(shape=self.width, depth=inner_depth, init=[])
        w_port = storage.write_port()
        r_port = storage.read_port(domain="sync")
        produce = Signal(range(inner_depth))
        consume = Signal(range(inner_depth))
        m.d.comb += [w_port.addr.eq(produce), w_port.data.eq(self.w_stream.payload),
                     w_port.en.eq(do_write),
                     r_port.addr.eq(consume), r_port.en.eq(do_inner_read),
                     self.r_stream.payload.eq(r_port.data),
                     self.w_stream.ready.eq(inner_level != inner_depth),
                     self.level.eq(inner_level + head)]
        with m.If(do_write):
            m.d.sync += produce.eq(incr_modulo(produce, inner_depth))
        with m.If(do_inner_read):
            m.d.sync += consume.eq(incr_modulo(consume, inner_depth))
        with m.If(do_write & ~do_inner_read):
            m.d.sync += inner_level.eq(inner_level + 1)
        with m.If(do_inner_read & ~do_write):
            m.d.sync += inner_level.eq(inner_level - 1)
        with m.If(do_inner_read):
            m.d.sync += head.eq(1)
        with m.Elif(self.r_stream.ready):
            m.d.sync += head.eq(0)
        return m

    def _banked(self):
        """``banks`` CreditFIFOs side by side, one slice of the word each; the flags and the
        level are bank 0's (every bank's are the same)."""
        m = Module()
        cuts = [self.width * k // self.banks for k in range(self.banks + 1)]
        banks = [CreditFIFO(width=hi - lo, depth=self.depth)
                 for lo, hi in zip(cuts, cuts[1:])]
        for k, (bank, lo, hi) in enumerate(zip(banks, cuts, cuts[1:])):
            m.submodules[f"bank{k}"] = bank
            m.d.comb += [bank.w_stream.valid.eq(self.w_stream.valid),
                         bank.w_stream.payload.eq(self.w_stream.payload[lo:hi]),
                         bank.r_stream.ready.eq(self.r_stream.ready),
                         self.r_stream.payload[lo:hi].eq(bank.r_stream.payload)]
        m.d.comb += [self.r_stream.valid.eq(banks[0].r_stream.valid),
                     self.w_stream.ready.eq(banks[0].w_stream.ready),
                     self.level.eq(banks[0].level)]
        return m
