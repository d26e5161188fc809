"""The credit count in front of a pipeline that never stalls, with a FIFO behind it.

The ray-triangle unit's pipeline never stalls, and every pair it accepts lands in its output
FIFO ``latency`` clocks later. So it may accept a pair only while fewer than the FIFO's
``depth`` pairs are accepted and not yet taken from the FIFO: each accepted pair holds a
credit for a word of the FIFO until it is taken. With that, the FIFO never overflows, and
its write needs no look at its level (:class:`~.ram.CreditSyncFIFO`); with the depth
``latency + 1``, one pair a clock never runs out of credits while the output is taken.

:func:`credit_count` builds the count into the caller's module (the unit's Verilog names
its registers ``held``, ``took``, ``held_le``, ``held_lt``). Its SymbiYosys check, behind a
pipeline and the FIFO, is the stream stage ``output-credits``
(:mod:`raplas_hdl.formal.streams`, ``docs/formal.md``): the FIFO is never written full,
``ready`` is exactly "fewer than ``depth`` in use", and nothing is lost, doubled or
reordered.
"""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal, Value

__all__ = ["credit_count"]


def credit_count(m: Module, *, valid: Value, ready: Signal, take: Value,
                 depth: int) -> Signal:
    """Drive ``ready`` from a count of the credits in use, and return ``accept`` (``valid &
    ready``: a pair taken in, which holds a credit from this clock edge on).

    ``take`` is 1 on a clock whose edge takes a word from the FIFO (its credit is freed).

    The credits in use are kept as ``held = in use + took``: ``took`` is the last cycle's
    take, registered, so that the output's ``ready`` (from whatever the unit feeds, maybe
    far across the chip) reaches only a flip-flop, never the counter's carry chain. The two
    comparisons ``ready`` picks from are registers too, formed for each of the count's
    three steps (+1, 0, -1; ``held <= depth + 1`` always) from ``held`` alone, so that
    ``ready`` (which enables the pair FIFO's read, every bank of it) is one LUT from
    flip-flops, and ``took`` and ``accept`` reach those registers through a multiplexer and
    no carry chain (certified, the comparison's carry chain took 2 to 3 ns of a 12.4 ns
    path; chop, ``took -> held_le`` was an 11.0 ns path; ECP5 speed 6). ``ready`` is the
    same function of the true count as it would be unregistered: every handshake happens on
    the same cycle.
    """
    held = Signal(range(depth + 2))
    took = Signal()
    accept = Signal()
    held_next = Signal(range(depth + 2))
    held_le = Signal(init=1)                        # held <= depth (held starts at 0)
    held_lt = Signal(init=1)                        # held < depth
    m.d.comb += [
        ready.eq(Mux(took, held_le, held_lt)),
        accept.eq(valid & ready),
        held_next.eq(held + accept - took),
    ]
    count_up, count_down = accept & ~took, took & ~accept
    m.d.sync += [
        took.eq(take), held.eq(held_next),
        held_le.eq(Mux(count_up, held < depth,
                       Mux(count_down, held <= depth + 1, held <= depth))),
        held_lt.eq(Mux(count_up, held < depth - 1,
                       Mux(count_down, held <= depth, held < depth))),
    ]
    return accept
