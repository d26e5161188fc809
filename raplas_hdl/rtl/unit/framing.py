"""Stage 8, the result framing, and the unit's event counters.

One result is held back, so that the run's marker can mark the run's last result ``last``,
or, when the run issued no pair, send the ``empty`` beat instead. In ``certified`` mode the
beats carry the pair's ``outcome`` too (``hits`` counts ``outcome == 1``).
"""

from __future__ import annotations

from amaranth.hdl import Module, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ...model.config import UnitConfig
from ...model.records import EVENT_COUNT_BITS
from .streams import counter_layout, result_layout, rt_result_layout

__all__ = ["ResultFraming", "EventCounters", "EVENTS_LAYOUT"]

#: What the framing counts per result: a hit, and the pair's operations that raised each
#: event (the counters of the same names).
EVENTS_LAYOUT = data.StructLayout({"hits": 1, "overflow": EVENT_COUNT_BITS,
                                   "underflow": EVENT_COUNT_BITS,
                                   "invalid": EVENT_COUNT_BITS})


class ResultFraming(wiring.Component):
    """Ray-triangle results in, the run's result beats out (``last``, ``empty``).

    ``i.ready`` is ``o.ready``: a result is taken when a beat could leave, whether or not
    one does (the first result of a run only goes into the hold register).

    Parameters
    ----------
    config : UnitConfig

    Members
    -------
    i : In(stream.Signature(rt_result_layout))
        Results; the top bit of ``ray_id`` marks a run's marker.
    o : Out(stream.Signature(result_layout))
        Beats of the unit's result stream.
    events : Out(EVENTS_LAYOUT)
        Of the result taken the cycle before (zero for a marker or when none was taken): a
        register, since the take follows the output FIFO's level, and that level through
        the take into the counters' adders was the whole unit's critical path at speed 8
        (7.3 ns placed and routed on an ECP5).
    """

    def __init__(self, config: UnitConfig):
        self._cfg = config
        super().__init__({
            "i": In(stream.Signature(rt_result_layout(config))),
            "o": Out(stream.Signature(result_layout(config))),
            "events": Out(EVENTS_LAYOUT),
        })

    def elaborate(self, platform):
        cfg = self._cfg
        m = Module()
        ray_bits = cfg.ray_id_bits
        layout = result_layout(cfg)
        held = Signal(layout)
        held_v = Signal()
        r = self.i.payload
        beat = self.o.payload
        fresh = Signal(layout)
        m.d.comb += [fresh.ray_id.eq(r.ray_id[:ray_bits]), fresh.tri_id.eq(r.tri_id),
                     fresh.hit.eq(r.hit), fresh.t.eq(r.t), fresh.u.eq(r.u), fresh.v.eq(r.v),
                     fresh.det.eq(r.det), fresh.flags.eq(r.flags)]
        if cfg.mode == "certified":
            m.d.comb += [fresh.outcome.eq(r.outcome), fresh.tight.eq(r.tight)]
        marker = r.ray_id[ray_bits]
        events = Signal(EVENTS_LAYOUT)
        m.d.sync += self.events.eq(events)
        m.d.comb += self.i.ready.eq(self.o.ready)
        with m.If(self.i.valid):
            with m.If(marker):
                m.d.comb += self.o.valid.eq(1)
                with m.If(held_v):
                    m.d.comb += [beat.eq(held), beat.last.eq(1)]
                with m.Else():
                    m.d.comb += [beat.eq(0), beat.last.eq(1), beat.empty.eq(1)]
            with m.Else():
                m.d.comb += [self.o.valid.eq(held_v), beat.eq(held)]
        with m.If(self.i.valid & self.i.ready):
            with m.If(marker):
                m.d.sync += held_v.eq(0)
            with m.Else():
                m.d.sync += [held.eq(fresh), held_v.eq(1)]
                m.d.comb += [events.hits.eq(r.hit), events.overflow.eq(r.n_overflow),
                             events.underflow.eq(r.n_underflow),
                             events.invalid.eq(r.n_invalid)]
        return m


class EventCounters(wiring.Component):
    """The unit's counters: each adds its ``inc`` every cycle (wrapping around); ``clear``
    zeroes them all.

    Parameters
    ----------
    config : UnitConfig

    Members
    -------
    inc : In(counter_layout)
    clear : In(1)
    counters : Out(counter_layout)
    """

    def __init__(self, config: UnitConfig):
        layout = counter_layout(config)
        super().__init__({"inc": In(layout), "clear": In(1), "counters": Out(layout)})

    def elaborate(self, platform):
        m = Module()
        for name, _ in self.counters.shape():
            cnt = self.counters[name]
            with m.If(self.clear):
                m.d.sync += cnt.eq(0)
            with m.Else():
                m.d.sync += cnt.eq(cnt + self.inc[name])
        return m
