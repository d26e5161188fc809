"""Stage 6: the triangle expander and record fetch.

Jobs in, one pair per cycle out, the job's triangles in list order: [list read] ->
[Triangle Memory and Ray Memory reads] -> ``o``, a 3-stage stall pipeline.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ...model.memory_image import UnitConfig
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
    job_last : bool
        Put one more bit on top of ``ray_id``, above the marker bit: the pair is its job's
        last (the marker pair too). The lanes' result merger advances on it
        (:mod:`.lanes`); ``o`` is then ``pair_layout(config, 2)``.

    Members
    -------
    i : In(stream.Signature(job_layout))
    o : Out(stream.Signature(pair_layout))
        The ray-triangle unit's pairs (``ray_id`` with the marker bit on top).
    tlist, tri, ray : Out(read_signature(...))
        Triangle-list, Triangle Memory and Ray Memory read ports.
    overflow : Out(1)
        Sticky: a pair was offered to a full ``o`` while the pipeline moved on (never, by
        construction).
    """

    def __init__(self, config: UnitConfig, job_last: bool = False):
        self._cfg = config
        self._job_last = bool(job_last)
        super().__init__({
            **read_ports(config, "tlist", "tri", "ray"),
            "i": In(stream.Signature(job_layout(config))),
            "o": Out(stream.Signature(pair_layout(config, 2 if job_last else 1))),
            "overflow": Out(1),
        })

    def elaborate(self, platform):
        cfg = self._cfg
        m = Module()
        ray_bits = cfg.ray_id_bits
        busy = Signal()
        k = Signal(range(cfg.tris_per_sphere + 1))      # the job's next triangle
        job = Signal(job_layout(cfg))
        adv = Signal()
        tail = {"last": 1} if self._job_last else {}
        g1 = Signal(data.StructLayout({"v": 1, "ray": ray_bits, "bank": 1, "marker": 1,
                                       **tail}))
        g2 = Signal(data.StructLayout({"v": 1, "ray": ray_bits, "marker": 1,
                                       "tri": cfg.tri_id_bits, **tail}))
        last = Signal()
        pop = Signal()
        m.d.comb += [last.eq(job.marker | (k == job.ntris - 1)),
                     pop.eq(adv & (~busy | last)), self.i.ready.eq(pop)]
        with m.If(adv & busy):
            m.d.sync += k.eq(k + 1)
        with m.If(pop):
            m.d.sync += [busy.eq(self.i.valid), job.eq(self.i.payload), k.eq(0)]
        m.d.comb += [self.tlist.addr.eq(job.sid * cfg.tris_per_sphere + k),
                     self.tlist.en.eq(adv)]
        with m.If(adv):
            m.d.sync += [g1.v.eq(busy), g1.ray.eq(job.ray), g1.bank.eq(job.bank),
                         g1.marker.eq(job.marker),
                         g2.v.eq(g1.v), g2.ray.eq(g1.ray), g2.marker.eq(g1.marker),
                         g2.tri.eq(self.tlist.data)]
            if tail:
                m.d.sync += [g1.last.eq(last), g2.last.eq(g1.last)]
        m.d.comb += [self.tri.addr.eq(self.tlist.data), self.tri.en.eq(adv),
                     self.ray.addr.eq(Mux(g1.bank, g1.ray + cfg.n_rays, g1.ray)),
                     self.ray.en.eq(adv)]
        # Ray Memory and Triangle Memory words are the records RAY and TRIANGLE
        ray = data.View(struct_layout(RAY, cfg), self.ray.data)
        tri = data.View(struct_layout(TRIANGLE, cfg), self.tri.data)
        p = self.o.payload
        m.d.comb += [adv.eq(~g2.v | self.o.ready), self.o.valid.eq(g2.v),
                     p.ray_id.eq(Cat(g2.ray, g2.marker, *([g2.last] if tail else []))),
                     p.tri_id.eq(g2.tri)]
        m.d.comb += [p[f.name].eq(ray[f.name]) for f in RAY]
        m.d.comb += [p[f.name].eq(tri[f.name]) for f in TRIANGLE]
        # a pair offered to a full FIFO while the pipeline moves on would be lost
        with m.If(g2.v & ~self.o.ready & adv):
            m.d.sync += self.overflow.eq(1)
        return m
