"""Stage 6: the triangle expander and record fetch.

Jobs in, one pair per cycle out, the job's triangles in list order: [list read] ->
[the triangle's index on a register] -> [Triangle Memory and Ray Memory reads] -> [the
records on a register] -> ``o``, a 4-stage pipeline that never stalls. The two registers keep
every block RAM's output off a long path: a read's clock-to-out and the wires to the next
memory's address (a Triangle Memory word is many block RAMs wide) or to the pair FIFO took
13.6 ns placed and routed on an ECP5 at speed 6.

Flow control is by credits, not by stalling: the expander starts a pair only while it holds a
credit, one per free entry of the pair FIFO behind ``o`` (``depth`` of them at reset, one back,
a cycle late, per pair the FIFO gives up: ``freed``). A pair in the pipeline then always has
room, so no register of the pipeline (some 450 flip-flops and the block RAMs' enables) waits
on the FIFO's level: a stall enable fanned out from the level was the whole unit's critical
path, 10.8 ns of which 8.9 ns routing, on the same ECP5.

The expander starts a pair and takes the next job from registers alone: whether a credit is
held and whether the next pair is its job's last are registered from their next values (the
credit count after the cycle's pair and return; ``k + 2 == ntris`` as a pair starts, the new
job's ``ntris == 1`` as it is taken), not compared from the count and ``k`` in front of the
job FIFO's read: the job -> ``k == ntris - 1`` -> pop -> job FIFO level path was one of
the certified whole unit's (seed 3), 10.8 ns at ECP5 speed 6. Cycle for cycle the same pairs.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ...model.config import UnitConfig
from ...model.records import RAY, TRIANGLE
from ..records import struct_layout
from .memories import read_ports
from .streams import job_layout, pair_layout

__all__ = ["RecordFetch"]


class RecordFetch(wiring.Component):
    """Expands each job into its pairs and fetches their ray and triangle records.

    The expander takes a job from ``i`` when it starts the job's last pair (or when it is
    idle); a marker job gives one pair with the marker bit, the ``ray_id``'s top bit.

    Parameters
    ----------
    config : UnitConfig
    depth : int
        Entries of the FIFO behind ``o``: the credits at reset.
    job_last : bool
        Put one more bit on top of ``ray_id``, above the marker bit: the pair is its job's
        last (the marker pair too). The lanes' result merger advances on it
        (:mod:`.lanes`); ``o`` is then ``pair_layout(config, 2)``.

    Members
    -------
    i : In(stream.Signature(job_layout))
    o : Out(stream.Signature(pair_layout))
        The ray-triangle unit's pairs (``ray_id`` with the marker bit on top); ``valid``
        does not wait for ``ready``: the credits keep the FIFO behind from being full.
    freed : In(1)
        The FIFO behind ``o`` gives up an entry this cycle (its read handshake).
    tlist, tri, ray : Out(read_signature(...))
        Triangle-list, Triangle Memory and Ray Memory read ports.
    overflow : Out(1)
        Sticky: a pair was offered to a full ``o`` (never, by construction: the credits).
    """

    def __init__(self, config: UnitConfig, depth: int, job_last: bool = False):
        self._cfg = config
        self._depth = int(depth)
        self._job_last = bool(job_last)
        super().__init__({
            **read_ports(config, "tlist", "tri", "ray"),
            "i": In(stream.Signature(job_layout(config))),
            "o": Out(stream.Signature(pair_layout(config, 2 if job_last else 1))),
            "freed": In(1), "overflow": Out(1),
        })

    def elaborate(self, platform):
        cfg = self._cfg
        m = Module()
        ray_bits = cfg.ray_id_bits
        busy = Signal()
        k = Signal(range(cfg.tris_per_sphere + 1))      # the job's next triangle
        job = Signal(job_layout(cfg))
        # credits: free FIFO entries not yet claimed by a started pair
        credit = Signal(range(self._depth + 1), init=self._depth)
        freed = Signal()
        issue = Signal()                                # a pair starts
        tail = {"last": 1} if self._job_last else {}
        g1 = Signal(data.StructLayout({"v": 1, "ray": ray_bits, "bank": 1, "marker": 1,
                                       **tail}))
        g2 = Signal(data.StructLayout({"v": 1, "ray": ray_bits, "bank": 1, "marker": 1,
                                       "tri": cfg.tri_id_bits, **tail}))
        g3 = Signal(data.StructLayout({"v": 1, "ray": ray_bits, "marker": 1,
                                       "tri": cfg.tri_id_bits, **tail}))
        g4 = Signal(self.o.payload.shape())
        g4_v = Signal()
        # ``issue`` and ``pop`` are formed from registers alone: ``last`` (the next pair is
        # the job's last: ``k == ntris - 1`` of the job held) and ``has_credit``
        # (``credit != 0``) are registered from their next values
        last = Signal()
        has_credit = Signal(init=self._depth != 0)
        pop = Signal()
        credit_next = Signal.like(credit)
        m.d.comb += [credit_next.eq(credit - issue + freed)]
        m.d.sync += [freed.eq(self.freed), credit.eq(credit_next),
                     has_credit.eq(credit_next != 0)]
        m.d.comb += [issue.eq(busy & has_credit),
                     pop.eq(~busy | (issue & last)), self.i.ready.eq(pop)]
        with m.If(issue):
            m.d.sync += [k.eq(k + 1), last.eq(job.marker | (k + 2 == job.ntris))]
        with m.If(pop):
            m.d.sync += [busy.eq(self.i.valid), job.eq(self.i.payload), k.eq(0),
                         last.eq(self.i.payload.marker | (self.i.payload.ntris == 1))]
        m.d.comb += [self.tlist.addr.eq(job.sid * cfg.tris_per_sphere + k),
                     self.tlist.en.eq(1)]
        m.d.sync += [g1.v.eq(issue), g1.ray.eq(job.ray), g1.bank.eq(job.bank),
                     g1.marker.eq(job.marker),
                     g2.v.eq(g1.v), g2.ray.eq(g1.ray), g2.bank.eq(g1.bank),
                     g2.marker.eq(g1.marker), g2.tri.eq(self.tlist.data),
                     g3.v.eq(g2.v), g3.ray.eq(g2.ray), g3.marker.eq(g2.marker),
                     g3.tri.eq(g2.tri)]
        if tail:
            m.d.sync += [g1.last.eq(last), g2.last.eq(g1.last), g3.last.eq(g2.last)]
        m.d.comb += [self.tri.addr.eq(g2.tri), self.tri.en.eq(1),
                     self.ray.addr.eq(Mux(g2.bank, g2.ray + cfg.n_rays, g2.ray)),
                     self.ray.en.eq(1)]
        # Ray Memory and Triangle Memory words are the records RAY and TRIANGLE
        ray = data.View(struct_layout(RAY, cfg), self.ray.data)
        tri = data.View(struct_layout(TRIANGLE, cfg), self.tri.data)
        m.d.sync += [g4_v.eq(g3.v),
                     g4.ray_id.eq(Cat(g3.ray, g3.marker, *([g3.last] if tail else []))),
                     g4.tri_id.eq(g3.tri)]
        m.d.sync += [g4[f.name].eq(ray[f.name]) for f in RAY]
        m.d.sync += [g4[f.name].eq(tri[f.name]) for f in TRIANGLE]
        m.d.comb += [self.o.valid.eq(g4_v), self.o.payload.eq(g4)]
        # a pair offered to a full FIFO would be lost
        with m.If(g4_v & ~self.o.ready):
            m.d.sync += self.overflow.eq(1)
        return m
