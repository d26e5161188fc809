"""K record-fetch / ray-triangle lanes behind one culling array: the job distributor and the
result merger (``UnitConfig.lanes``).

With ``lanes = K > 1`` the unit's back end is K copies of [job FIFO -> record fetch -> pair
FIFO -> ray-triangle unit], each fetch with its own read ports on Triangle Memory, the
triangle lists and Ray Memory. The order of the result stream does not change:

- :class:`JobDistributor` deals the selector's jobs (a run's marker job too) round-robin
  to the lanes: job ``n`` of the stream goes to lane ``n mod K``; it waits for that lane's
  FIFO, in order, never skipping ahead;
- each lane's record fetch marks the last pair of a job (a bit above the marker bit of
  ``ray_id``, :func:`~.streams.pair_layout` with two tag bits), which rides through the
  ray-triangle unit with the ID;
- :class:`ResultMerger` takes results from one lane at a time, starting at lane 0, and
  moves to the next lane after a result with that bit: so it takes job 0's results, then
  job 1's, ... -- the K=1 stream, beat for beat, into the result framing.

Both are combinational (a multiplexer and a lane pointer): the distributor's ``ready`` is
the chosen lane FIFO's ``w_rdy``, the merger's is the framing's (the output FIFO's level),
so no ``ready`` reaches further back than the nearest FIFO. The merger passes one result
per cycle, so the unit still gives at most one result beat per cycle (see
``docs/intersection-unit.md``, *Lanes*).
"""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ...model.config import UnitConfig
from .streams import job_layout, rt_result_layout

__all__ = ["JobDistributor", "ResultMerger"]


class JobDistributor(wiring.Component):
    """One job stream in, ``K`` out: job ``n`` to lane ``n mod K``, in order.

    Parameters
    ----------
    config : UnitConfig
        ``config.lanes`` is ``K``.

    Members
    -------
    i : In(stream.Signature(job_layout))
    o : Out(stream.Signature(job_layout)).array(K)
        ``o[k].valid`` only while lane ``k``'s turn; ``i.ready`` is the turn's ``o[k].ready``.
    """

    def __init__(self, config: UnitConfig):
        self._cfg = config
        sig = stream.Signature(job_layout(config))
        super().__init__({"i": In(sig), "o": Out(sig).array(config.lanes)})

    def elaborate(self, platform):
        lanes = self._cfg.lanes
        m = Module()
        turn = Signal(range(lanes))
        for k in range(lanes):
            m.d.comb += [self.o[k].payload.eq(self.i.payload),
                         self.o[k].valid.eq(self.i.valid & (turn == k))]
            with m.If(turn == k):
                m.d.comb += self.i.ready.eq(self.o[k].ready)
        with m.If(self.i.valid & self.i.ready):
            m.d.sync += turn.eq(next_turn(turn, lanes))
        return m


class ResultMerger(wiring.Component):
    """``K`` lanes' ray-triangle results in, one stream out, in job order.

    Takes results from lane ``turn`` (starting at 0) and moves to the next lane after a
    result whose job-last bit (``ray_id``'s top bit) is set. The output drops that bit: it
    is the :func:`~.streams.rt_result_layout` the result framing takes.

    Parameters
    ----------
    config : UnitConfig

    Members
    -------
    i : In(stream.Signature(rt_result_layout(config, 2))).array(K)
    o : Out(stream.Signature(rt_result_layout(config)))
    """

    def __init__(self, config: UnitConfig):
        self._cfg = config
        super().__init__({
            "i": In(stream.Signature(rt_result_layout(config, 2))).array(config.lanes),
            "o": Out(stream.Signature(rt_result_layout(config))),
        })

    def elaborate(self, platform):
        cfg = self._cfg
        lanes = cfg.lanes
        top = cfg.ray_id_bits + 1          # the job-last bit of a lane's ray_id
        m = Module()
        turn = Signal(range(lanes))
        job_last = Signal()
        for k in range(lanes):
            src = self.i[k]
            m.d.comb += src.ready.eq(self.o.ready & (turn == k))
            with m.If(turn == k):
                m.d.comb += [self.o.valid.eq(src.valid), job_last.eq(src.payload.ray_id[top])]
                m.d.comb += [self.o.payload[name].eq(src.payload[name])
                             for name, _ in self.o.payload.shape() if name != "ray_id"]
                m.d.comb += self.o.payload.ray_id.eq(src.payload.ray_id[:top])
        with m.If(self.o.valid & self.o.ready & job_last):
            m.d.sync += turn.eq(next_turn(turn, lanes))
        return m


def next_turn(turn, lanes: int):
    """``(turn + 1) mod lanes`` as an expression."""
    return Mux(turn == lanes - 1, 0, turn + 1)
