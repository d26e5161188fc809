"""Stages 4 and 5: the pair selector (ray iterator and enable lookup).

For each sphere from the plane-sphere array with a hit row, a hit column and triangles: one
ray per cycle, rows ascending, columns ascending (priority encoders on the masks); one job
for a marker. A disabled ray (Ray Memory's enable bit) is dropped at the enable lookup and
its pairs are counted as skipped; the others leave as jobs. With the on-chip reduction
(``UnitConfig.reduce``) the enable lookup also drops the jobs of rays the reducer reports
blocked (an any-hit ray with an answer: the early-out), without counting them.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ...model.config import UnitConfig
from .memories import read_ports
from .streams import job_layout, mask_layout, tag_layout

__all__ = ["PairSelector", "lowest_set"]


def lowest_set(m: Module, mask, n: int, name: str):
    """(index, one-hot) of the lowest set bit of ``mask`` (``n`` bits); index 0 if none."""
    onehot = Signal(n, name=f"{name}_onehot")
    m.d.comb += onehot.eq(mask & (~mask + 1))
    bits = max(1, (n - 1).bit_length())
    index = Signal(bits, name=f"{name}_index")
    for b in range(bits):
        terms = [onehot[k] for k in range(n) if (k >> b) & 1]
        if terms:
            m.d.comb += index[b].eq(Cat(*terms).any())
    return index, onehot


class PairSelector(wiring.Component):
    """Spheres with their plane masks in, one job per enabled ray out.

    A stall pipeline of two stages: the iterator (one ray of the current sphere per cycle;
    it takes the next sphere on the cycle it offers the last ray of this one) and the enable
    lookup (a dropped ray leaves the stage in the cycle it arrives). A sphere whose tag has
    ``keep_all`` set takes all-ones masks: every ray of the bundle.

    Parameters
    ----------
    config : UnitConfig

    Members
    -------
    i : In(stream.Signature(mask_layout))
        The plane-sphere array's results (``id`` is a :func:`~.streams.tag_layout`).
    o : Out(stream.Signature(job_layout))
        Jobs: ray, sphere, bank, the sphere's triangle count, marker.
    count, enable : Out(read_signature(...))
        Read ports of the triangle counts (Sphere Memory field 4) and the enable bits.
    skipped : Out(count_bits)
        Pairs of the disabled ray dropped this cycle (0 if none).
    blocked, blocked_seq : In(rows * cols), In(seq_bits)
        Only with ``config.reduce``: the rays of run number ``blocked_seq`` whose jobs are
        dropped (:class:`~raplas_hdl.rtl.unit.reducer.Reducer`'s ``blocked`` and ``seq``);
        the selector numbers its runs as the reducer does (runs whose marker it has sent)
        and takes both a cycle late, so a change of run can never apply one run's bits to
        another.
    """

    def __init__(self, config: UnitConfig, seq_bits: int = 8):
        self._cfg = config
        self._seq_bits = int(seq_bits)
        early = {"blocked": In(config.n_rays), "blocked_seq": In(self._seq_bits)} \
            if config.reduce else {}
        super().__init__({
            **read_ports(config, "count", "enable"),
            "i": In(stream.Signature(mask_layout(config))),
            "o": Out(stream.Signature(job_layout(config))),
            "skipped": Out(config.count_bits),
            **early,
        })

    def elaborate(self, platform):
        cfg = self._cfg
        m = Module()
        rows, cols = cfg.rows, cfg.cols
        tag = data.View(tag_layout(cfg), self.i.payload.id)
        # -- ray iterator: the sphere being expanded, its remaining rows and columns
        it = Signal(data.StructLayout({"busy": 1, "rows": rows, "colmask": cols,
                                       "cols": cols, "sid": cfg.sphere_id_bits, "bank": 1,
                                       "marker": 1}))
        adv = Signal()       # the enable stage takes what the iterator offers
        ntris = self.count.data
        m.d.comb += self.count.addr.eq(tag.sphere)
        i_idx, i_hot = lowest_set(m, it.rows, rows, "row")
        j_idx, j_hot = lowest_set(m, it.cols, cols, "col")
        cols_next = Signal(cols)
        rows_next = Signal(rows)
        m.d.comb += [cols_next.eq(it.cols & ~j_hot),
                     rows_next.eq(Mux(cols_next == 0, it.rows & ~i_hot, it.rows))]
        culled = Signal()
        m.d.comb += culled.eq(~it.marker & ((it.rows == 0) | (it.cols == 0) | (ntris == 0)))
        emit = Signal()          # the iterator offers a ray job this cycle
        done = Signal()          # ... and it is its sphere's last
        m.d.comb += [emit.eq(it.busy & ~culled),
                     done.eq(it.busy & (culled | it.marker | (rows_next == 0)))]
        m.d.comb += [self.i.ready.eq(~it.busy | (done & adv)),
                     self.count.en.eq(self.i.ready)]
        row_mask = Mux(tag.keep_all, (1 << rows) - 1, self.i.payload.row_mask)
        col_mask = Mux(tag.keep_all, (1 << cols) - 1, self.i.payload.col_mask)
        with m.If(self.i.valid & self.i.ready):
            m.d.sync += [it.busy.eq(1), it.rows.eq(row_mask), it.colmask.eq(col_mask),
                         it.cols.eq(col_mask), it.sid.eq(tag.sphere), it.marker.eq(tag.marker),
                         it.bank.eq(tag.bank)]
        with m.Elif(it.busy & adv):
            with m.If(done):
                m.d.sync += it.busy.eq(0)
            with m.Else():
                m.d.sync += [it.cols.eq(Mux(cols_next == 0, it.colmask, cols_next)),
                             it.rows.eq(rows_next)]
        ray = Signal(cfg.ray_id_bits)
        m.d.comb += ray.eq(i_idx * cols + j_idx)

        # -- enable lookup
        e_v = Signal()
        job = Signal(job_layout(cfg))
        drop = Signal()
        disabled = e_v & ~job.marker & ~self.enable.data
        blocked = Signal()
        if cfg.reduce:
            seq, blk_seq = Signal(self._seq_bits), Signal(self._seq_bits)
            blk = Signal(cfg.n_rays)
            m.d.sync += [blk.eq(self.blocked), blk_seq.eq(self.blocked_seq)]
            with m.If(self.o.valid & self.o.ready & job.marker):
                m.d.sync += seq.eq(seq + 1)
            m.d.comb += blocked.eq(e_v & ~job.marker & (blk_seq == seq)
                                   & blk.bit_select(job.ray, 1))
        m.d.comb += [drop.eq(disabled | blocked),
                     adv.eq(~e_v | drop | self.o.ready),
                     self.enable.addr.eq(Mux(it.bank, ray + cfg.n_rays, ray)),
                     self.enable.en.eq(adv)]
        with m.If(adv):
            m.d.sync += [e_v.eq(emit), job.ray.eq(ray), job.sid.eq(it.sid),
                         job.bank.eq(it.bank), job.marker.eq(it.marker), job.ntris.eq(ntris)]
        m.d.comb += [self.o.payload.eq(job), self.o.valid.eq(e_v & ~drop),
                     self.skipped.eq(Mux(disabled, job.ntris, 0))]
        return m
