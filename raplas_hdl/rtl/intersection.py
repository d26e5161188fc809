"""The whole intersection unit: memories, plane-sphere array, selector, pair FIFO, ray-triangle.

The host writes the memories through one write port (address map in
:mod:`raplas_hdl.model.memory_image`) and starts *runs* through the ``cmd`` stream; each run
tests a range (or a list) of spheres against the bundle in one of two banks, and its
results leave through the ``o`` stream, the last beat of the run marked ``last``. A run
with the ``keep_all`` bit culls nothing: every sphere passes the plane test. The golden
model is :func:`raplas_hdl.model.intersection.run_bundle`. The ports' payloads are the
records ``CMD``, ``RESULT`` and ``COUNTERS`` of :mod:`raplas_hdl.model.records`.

Stages, in data-flow order (every boundary is a stall pipeline or a FIFO; no ready signal
reaches further back than the nearest FIFO's level):

1. **Command / plane loader.** A run is accepted when the feeder is idle. If its bank's
   planes are not the ones in the tester array (another bank, or the host wrote the bank's
   Plane Memory since it was loaded), the feeder waits for the array and its own stages to
   drain, then copies ``rows + cols`` planes from Plane Memory into the array (one per
   cycle). *Drain rule*: this is the only time the array's planes change, so the host may
   write the other bank's planes and rays while a run is going; it must not write the
   bank of a run whose ``last`` beat it has not received, nor the scene memories during
   a run.
2. **Sphere feeder** (2-stage stall pipeline): run position -> [run list read] ->
   [Sphere Memory read] -> array input, one sphere per cycle. After the run's spheres it
   sends one *marker* sphere (an ID bit) that travels in order behind them. The array's
   sphere ID carries the sphere ID, the marker bit, the bank and the run's ``keep_all``
   bit, from the low bits up.
3. **Plane-sphere array** (:class:`~raplas_hdl.rtl.plane_sphere.PlaneSphereArray`): sphere ID,
   row mask, column mask. The array tests every sphere, ``keep_all`` or not.
4. **Ray iterator**: for each sphere with a hit row, a hit column and triangles, one ray
   per cycle, rows ascending, columns ascending (priority encoders on the masks); one ray
   job for a marker. A sphere whose ``keep_all`` bit is set takes all-ones masks instead
   of the array's: every ray of the bundle.
5. **Enable lookup** (Ray Memory's enable bits): a disabled ray is dropped here and its
   ``tris_per_sphere``-or-fewer pairs are counted as skipped in one cycle; enabled rays go
   into a 4-deep job FIFO.
6. **Triangle expander and fetch** (3-stage stall pipeline): one pair per cycle, triangles
   in list order: [list read] -> [Triangle Memory and Ray Memory reads] -> pair FIFO
   (``fifo_depth`` records). The pipeline writes the FIFO only when it has room.
7. **Ray-triangle unit** (:class:`~raplas_hdl.rtl.ray_triangle.RayTriangleUnit`), fed from the
   pair FIFO; the marker pair carries an extra ray-ID bit.
8. **Result framing**: one result is held back, so that the marker can mark the run's last
   result ``last``, or, when the run issued no pair, send the ``empty`` marker beat; a
   4-deep output FIFO feeds ``o``.

Counters (32 bits, wrap around, zeroed by ``clear``): ``cycles`` (cycles while a run is
outstanding), ``spheres`` and ``plane_tests`` (counted at the array input), ``pairs_issued``
(at the ray-triangle input), ``pairs_skipped`` (disabled rays), ``hits``, and ``overflow``,
``underflow``, ``invalid``: the operations that raised the event, summed over the issued
pairs (the ray-triangle unit counts them per pair, up to 34, beside the ORed ``flags``
of the result stream).
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.fifo import SyncFIFOBuffered
from amaranth.lib.wiring import In, Out

from ..model.memory_image import REGIONS, UnitConfig
from ..model.records import CMD, COUNTERS, RAY, RESULT, TRIANGLE
from .ram import SyncRAM
from .records import struct_layout

__all__ = ["IntersectionUnit", "build_intersection_unit", "port_layouts", "COUNTER_PORTS"]

#: Fields of the ``counters`` port, in order.
COUNTER_PORTS = COUNTERS.names
COUNTER_BITS = COUNTERS["cycles"].width
OUT_FIFO_DEPTH = 4
JOB_FIFO_DEPTH = 4


def _lowest_set(m, mask, n, name):
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


def port_layouts(cfg: UnitConfig) -> dict:
    """The struct layouts of the ``cmd``, ``o`` (``result``) and ``counters`` ports.

    They are the records :data:`~raplas_hdl.model.records.CMD`,
    :data:`~raplas_hdl.model.records.RESULT` and :data:`~raplas_hdl.model.records.COUNTERS`
    bound to ``cfg``."""
    return {"cmd": struct_layout(CMD, cfg), "result": struct_layout(RESULT, cfg),
            "counters": struct_layout(COUNTERS, cfg)}


class IntersectionUnit(wiring.Component):
    """The RAPLAS intersection unit.

    Parameters
    ----------
    config : UnitConfig, optional
        Build parameters; alternatively pass them as keywords (``rows=4, cols=4, ...``).
    multiplier : {"generic", "virtex4"}
        Significand multiplier of every :class:`~raplas_hdl.rtl.fp_mul.FPMul` in the
        plane-sphere array and the ray-triangle unit (``virtex4``: Virtex-4 ``DSP48``
        primitives, one cycle more per multiplier). An implementation choice only: the
        results, and so the golden model, do not depend on it.
    ram : {"memory", "verilog"}
        The memories as Amaranth ``Memory`` (default; Amaranth's simulator runs it) or as
        instances of a behavioural Verilog RAM without initial values
        (:mod:`raplas_hdl.rtl.ram`; append :func:`~raplas_hdl.rtl.ram.ram_verilog` to the
        emitted text). The latter converts in seconds at any depth: a mesh of 70k
        triangles takes Amaranth and Yosys some 20 minutes to convert the other way.

    Members
    -------
    wr_en, wr_addr, wr_data : In(1), In(32), In(32)
        Host write port (one 32-bit word per cycle; address map in
        :mod:`raplas_hdl.model.memory_image`).
    cmd : In(stream.Signature(cmd_layout))
        Start a run: ``first`` (sphere ID, or run-list position when ``indirect``),
        ``count`` (spheres, 0 allowed), ``bank`` (bundle bank), ``indirect``, ``keep_all``
        (cull nothing: the masks of every sphere of the run are all ones).
    o : Out(stream.Signature(result_layout))
        Results: ``ray_id``, ``tri_id``, ``hit``, ``t``, ``u``, ``v``, ``det``, ``flags``,
        ``last``, ``empty``.
    counters : Out(counter_layout)
        ``cycles`` and the counters of
        :data:`~raplas_hdl.model.memory_image.COUNTER_NAMES`, 32 bits each.
    clear : In(1)
        Zero every counter.
    busy : Out(1)
        A run is accepted and its last beat has not left ``o``.
    fifo_level : Out(range(fifo_depth + 1))
        Pair-FIFO fill level.
    fifo_overflow : Out(1)
        Sticky: a write was offered to a full pair FIFO (never, by construction; the
        testbenches assert it stays 0).

    Raises
    ------
    ValueError
        On out-of-range parameters (see :class:`UnitConfig`).
    """

    def __init__(self, config: UnitConfig | None = None, *, multiplier: str = "generic",
                 ram: str = "memory", **params):
        from .fp_mul import check_multiplier
        from .ram import RAM_IMPLS

        self._multiplier = check_multiplier(multiplier)
        if ram not in RAM_IMPLS:
            raise ValueError(f"ram must be one of {', '.join(RAM_IMPLS)}, not {ram!r}")
        self._ram = ram
        if config is None:
            config = UnitConfig(**params)
        elif params:
            raise ValueError("pass either a UnitConfig or keyword parameters, not both")
        if not isinstance(config, UnitConfig):
            raise ValueError(f"config must be a UnitConfig, not {config!r}")
        self._cfg = cfg = config
        layouts = port_layouts(cfg)
        self.cmd_layout = layouts["cmd"]
        self.result_layout = layouts["result"]
        self.counter_layout = layouts["counters"]
        super().__init__({
            "wr_en": In(1), "wr_addr": In(32), "wr_data": In(32),
            "cmd": In(stream.Signature(self.cmd_layout)),
            "o": Out(stream.Signature(self.result_layout)),
            "counters": Out(self.counter_layout),
            "clear": In(1),
            "busy": Out(1),
            "fifo_level": Out(range(cfg.fifo_depth + 1)),
            "fifo_overflow": Out(1),
        })

    @property
    def config(self) -> UnitConfig:
        return self._cfg

    @property
    def multiplier(self) -> str:
        return self._multiplier

    @property
    def latency(self):
        """None: the unit's delay depends on the scene (see the stage list)."""
        return None

    # ------------------------------------------------------------------------------------
    def _subunits(self):
        from .plane_sphere import PlaneSphereArray
        from .ray_triangle import RayTriangleUnit

        cfg = self._cfg
        psa = PlaneSphereArray(cfg.fmt, rows=cfg.rows, cols=cfg.cols, testers=cfg.n_testers,
                               sphere_id_bits=cfg.sphere_id_bits + 3,
                               multiplier=self._multiplier)
        rtu = RayTriangleUnit(cfg.fmt, mode=cfg.mode, margin_scale=cfg.margin_scale,
                              ray_id_bits=cfg.ray_id_bits + 1, tri_id_bits=cfg.tri_id_bits,
                              multiplier=self._multiplier)
        return psa, rtu

    def elaborate(self, platform):
        cfg = self._cfg
        w = cfg.fmt.width
        m = Module()
        n_planes, n_rays = cfg.n_planes, cfg.n_rays
        sid_bits, ray_bits, tri_bits = cfg.sphere_id_bits, cfg.ray_id_bits, cfg.tri_id_bits
        tps = cfg.tris_per_sphere

        m.submodules.psa, m.submodules.rtu = psa, rtu = self._subunits()

        # -- memories -----------------------------------------------------------------
        rams = []

        def memory(name, shape, depth, gran=None):
            mem = SyncRAM(shape, depth, impl=self._ram, name=name)
            rams.append(mem)
            return mem, mem.write_port(granularity=gran)

        tri_mem, tri_wp = memory("tri_mem", 12 * w, cfg.max_triangles, w)
        sph_mem, sph_wp = memory("sph_mem", 4 * w, cfg.max_spheres, w)
        cnt_mem, cnt_wp = memory("cnt_mem", cfg.count_bits, cfg.max_spheres)
        tl_mem, tl_wp = memory("tlist_mem", tri_bits, cfg.max_spheres * tps)
        pl_mem, pl_wp = memory("plane_mem", 4 * w, 2 * n_planes, w)
        ray_mem, ray_wp = memory("ray_mem", 6 * w, 2 * n_rays, w)
        en_mem, en_wp = memory("enable_mem", 1, 2 * n_rays)
        rl_mem, rl_wp = memory("rlist_mem", sid_bits, 2 * cfg.max_spheres)

        # -- host write port ----------------------------------------------------------
        region = self.wr_addr[28:32]
        bank = self.wr_addr[27]
        index = self.wr_addr[4:27]
        fld = self.wr_addr[0:4]
        word = self.wr_data

        wr = self.wr_en
        is_tri = wr & (region == REGIONS["tri"]) & (index < cfg.max_triangles) & (fld < 12)
        m.d.comb += [tri_wp.addr.eq(index), tri_wp.data.eq(Cat(*[word[:w]] * 12))]
        for k in range(12):
            m.d.comb += tri_wp.en[k].eq(is_tri & (fld == k))
        is_sph = wr & (region == REGIONS["sphere"]) & (index < cfg.max_spheres)
        m.d.comb += [sph_wp.addr.eq(index), sph_wp.data.eq(Cat(*[word[:w]] * 4)),
                     cnt_wp.addr.eq(index), cnt_wp.data.eq(word),
                     cnt_wp.en.eq(is_sph & (fld == 4))]
        for k in range(4):
            m.d.comb += sph_wp.en[k].eq(is_sph & (fld == k))
        m.d.comb += [tl_wp.addr.eq(index), tl_wp.data.eq(word),
                     tl_wp.en.eq(wr & (region == REGIONS["tlist"]) & (fld == 0)
                                 & (index < cfg.max_spheres * tps))]
        is_pl = wr & (region == REGIONS["plane"]) & (index < n_planes)
        m.d.comb += [pl_wp.addr.eq(Mux(bank, index + n_planes, index)),
                     pl_wp.data.eq(Cat(*[word[:w]] * 4))]
        for k in range(4):
            m.d.comb += pl_wp.en[k].eq(is_pl & (fld == k))
        is_ray = wr & (region == REGIONS["ray"]) & (index < n_rays)
        m.d.comb += [ray_wp.addr.eq(Mux(bank, index + n_rays, index)),
                     ray_wp.data.eq(Cat(*[word[:w]] * 6)),
                     en_wp.addr.eq(Mux(bank, index + n_rays, index)), en_wp.data.eq(word[0]),
                     en_wp.en.eq(is_ray & (fld == 6))]
        for k in range(6):
            m.d.comb += ray_wp.en[k].eq(is_ray & (fld == k))
        m.d.comb += [rl_wp.addr.eq(Mux(bank, index + cfg.max_spheres, index)),
                     rl_wp.data.eq(word),
                     rl_wp.en.eq(wr & (region == REGIONS["rlist"]) & (fld == 0)
                                 & (index < cfg.max_spheres))]
        # a plane write makes that bank's planes stale in the array
        dirty = Signal(2, init=0b11)
        plane_write = Signal(2)
        m.d.comb += plane_write.eq(Mux(is_pl, Mux(bank, 0b10, 0b01), 0))

        # -- counters -----------------------------------------------------------------
        inc = {name: Signal(COUNTER_BITS, name=f"inc_{name}") for name in COUNTER_PORTS}
        for name in COUNTER_PORTS:
            cnt = self.counters[name]
            with m.If(self.clear):
                m.d.sync += cnt.eq(0)
            with m.Else():
                m.d.sync += cnt.eq(cnt + inc[name])

        # -- 1. command / plane loader, 2. sphere feeder -----------------------------------
        run_first = Signal(sid_bits)
        run_count = Signal(cfg.run_count_bits)
        run_bank = Signal()
        run_ind = Signal()
        run_keep = Signal()
        pos = Signal(cfg.run_count_bits)
        loaded_bank = Signal()
        ld_k = Signal(range(n_planes))
        ld_v = Signal()
        ld_kd = Signal(range(n_planes))

        f1_v = Signal(name="f1_v")
        f2_v = Signal(name="f2_v")
        f1_marker = Signal(name="f1_marker")
        f2_marker = Signal(name="f2_marker")
        f1_bank = Signal(name="f1_bank")
        f2_bank = Signal(name="f2_bank")
        f1_keep = Signal(name="f1_keep")
        f2_keep = Signal(name="f2_keep")
        f1_ind = Signal()
        f1_sid = Signal(sid_bits, name="f1_sid")
        f2_sid = Signal(sid_bits, name="f2_sid")
        f_adv = Signal()
        issue = Signal()
        issue_marker = Signal()

        rl_rp = rl_mem.read_port()
        sph_rp = sph_mem.read_port()
        pl_rp = pl_mem.read_port()

        m.d.comb += f_adv.eq(~f2_v | psa.i.ready)

        new_dirty = Signal(2)
        m.d.comb += new_dirty.eq(dirty | plane_write)
        m.d.sync += dirty.eq(new_dirty)
        # spheres between the array's input and its output handshake (the array's pipeline
        # and output FIFO): the planes may change only when none is left
        in_array = Signal(range(2 * psa.latency + 8))
        m.d.sync += in_array.eq(in_array + (psa.i.valid & psa.i.ready)
                                - (psa.o.valid & psa.o.ready))
        drained = Signal()
        m.d.comb += drained.eq((in_array == 0) & ~f1_v & ~f2_v)

        m.d.sync += [ld_v.eq(0), ld_kd.eq(ld_k)]
        with m.FSM(name="feeder"):
            with m.State("START"):
                # one state change after reset, so that every simulator evaluates the
                # processes that depend on the state (Icarus does not run them at time 0)
                m.next = "IDLE"
            with m.State("IDLE"):
                m.d.comb += self.cmd.ready.eq(1)
                with m.If(self.cmd.valid):
                    p = self.cmd.payload
                    m.d.sync += [run_first.eq(p.first), run_count.eq(p.count),
                                 run_bank.eq(p.bank), run_ind.eq(p.indirect),
                                 run_keep.eq(p.keep_all), pos.eq(0)]
                    stale = (p.bank != loaded_bank) | new_dirty.bit_select(p.bank, 1)
                    with m.If(stale):
                        m.next = "DRAIN"
                    with m.Else():
                        m.next = "FEED"
            with m.State("DRAIN"):
                with m.If(drained):
                    m.d.sync += [ld_k.eq(0), loaded_bank.eq(run_bank)]
                    m.next = "LOAD"
            with m.State("LOAD"):
                m.d.comb += pl_rp.addr.eq(Mux(run_bank, ld_k + n_planes, ld_k))
                m.d.sync += [ld_k.eq(ld_k + 1), ld_v.eq(1)]
                with m.If(ld_k == 0):
                    # the bank is clean from the first read on (a write after it re-dirties)
                    m.d.sync += dirty.eq(new_dirty & Mux(run_bank, 0b01, 0b10))
                with m.If(ld_k == n_planes - 1):
                    m.next = "FEED"
            with m.State("FEED"):
                m.d.comb += issue.eq(1)
                m.d.comb += issue_marker.eq(pos == run_count)
                with m.If(f_adv):
                    m.d.sync += pos.eq(pos + 1)
                    with m.If(issue_marker):
                        m.next = "IDLE"
        m.d.comb += [psa.pw_en.eq(ld_v), psa.pw_addr.eq(ld_kd), psa.pw_data.eq(pl_rp.data)]

        # feeder stall pipeline: position -> f1 (run list read) -> f2 (sphere read)
        sid_direct = Signal(sid_bits)
        m.d.comb += [sid_direct.eq(run_first + pos),
                     rl_rp.addr.eq(Mux(run_bank, sid_direct + cfg.max_spheres, sid_direct)),
                     rl_rp.en.eq(f_adv)]
        f1_sid_eff = Signal(sid_bits)
        m.d.comb += [f1_sid_eff.eq(Mux(f1_ind, rl_rp.data, f1_sid)),
                     sph_rp.addr.eq(f1_sid_eff), sph_rp.en.eq(f_adv)]
        with m.If(f_adv):
            m.d.sync += [f1_v.eq(issue), f1_marker.eq(issue_marker), f1_bank.eq(run_bank),
                         f1_keep.eq(run_keep), f1_ind.eq(run_ind), f1_sid.eq(sid_direct),
                         f2_v.eq(f1_v), f2_marker.eq(f1_marker), f2_bank.eq(f1_bank),
                         f2_keep.eq(f1_keep), f2_sid.eq(f1_sid_eff)]
        m.d.comb += [psa.i.valid.eq(f2_v),
                     psa.i.payload.id.eq(Cat(f2_sid, f2_marker, f2_bank, f2_keep)),
                     psa.i.payload.c.eq(sph_rp.data[:3 * w]),
                     psa.i.payload.r.eq(sph_rp.data[3 * w:4 * w])]
        with m.If(f2_v & psa.i.ready & ~f2_marker):
            m.d.comb += [inc["spheres"].eq(1), inc["plane_tests"].eq(n_planes)]

        # -- 4. ray iterator ----------------------------------------------------------------
        cnt_rp = cnt_mem.read_port()
        it_busy = Signal()
        it_rows = Signal(cfg.rows)
        it_colmask = Signal(cfg.cols)
        it_cols = Signal(cfg.cols)
        it_sid = Signal(sid_bits)
        it_bank = Signal()
        it_marker = Signal()
        it_adv = Signal()
        it_ntris = cnt_rp.data
        o_id = psa.o.payload.id
        m.d.comb += cnt_rp.addr.eq(o_id[:sid_bits])

        i_idx, i_hot = _lowest_set(m, it_rows, cfg.rows, "row")
        j_idx, j_hot = _lowest_set(m, it_cols, cfg.cols, "col")
        cols_next = Signal(cfg.cols)
        rows_next = Signal(cfg.rows)
        m.d.comb += cols_next.eq(it_cols & ~j_hot)
        m.d.comb += rows_next.eq(Mux(cols_next == 0, it_rows & ~i_hot, it_rows))
        culled = Signal()
        m.d.comb += culled.eq(~it_marker & ((it_rows == 0) | (it_cols == 0) | (it_ntris == 0)))
        emit = Signal()          # the iterator offers a ray job this cycle
        it_done = Signal()       # ... and it is its sphere's last
        m.d.comb += [emit.eq(it_busy & ~culled),
                     it_done.eq(it_busy & (culled | it_marker | (rows_next == 0)))]
        accept = Signal()
        m.d.comb += [accept.eq(psa.o.valid & psa.o.ready),
                     psa.o.ready.eq(~it_busy | (it_done & it_adv)),
                     cnt_rp.en.eq(psa.o.ready)]
        # keep_all: the array's masks are replaced by all ones (every ray of the bundle)
        o_keep = o_id[sid_bits + 2]
        row_mask = Signal(cfg.rows)
        col_mask = Signal(cfg.cols)
        m.d.comb += [row_mask.eq(Mux(o_keep, (1 << cfg.rows) - 1, psa.o.payload.row_mask)),
                     col_mask.eq(Mux(o_keep, (1 << cfg.cols) - 1, psa.o.payload.col_mask))]
        with m.If(accept):
            m.d.sync += [it_busy.eq(1), it_rows.eq(row_mask), it_colmask.eq(col_mask),
                         it_cols.eq(col_mask), it_sid.eq(o_id[:sid_bits]),
                         it_marker.eq(o_id[sid_bits]), it_bank.eq(o_id[sid_bits + 1])]
        with m.Elif(it_busy & it_adv):
            with m.If(it_done):
                m.d.sync += it_busy.eq(0)
            with m.Else():
                m.d.sync += [it_cols.eq(Mux(cols_next == 0, it_colmask, cols_next)),
                             it_rows.eq(rows_next)]
        ray = Signal(ray_bits)
        m.d.comb += ray.eq(i_idx * cfg.cols + j_idx)

        # -- 5. enable lookup -> job FIFO -----------------------------------------------------
        en_rp = en_mem.read_port()
        e_v = Signal()
        e_ray = Signal(ray_bits)
        e_sid = Signal(sid_bits)
        e_bank = Signal()
        e_marker = Signal()
        e_ntris = Signal(cfg.count_bits)
        job_layout = data.StructLayout({"ray": ray_bits, "sid": sid_bits, "bank": 1,
                                        "ntris": cfg.count_bits, "marker": 1})
        m.submodules.job_fifo = job_fifo = SyncFIFOBuffered(width=job_layout.size,
                                                            depth=JOB_FIFO_DEPTH)
        e_drop = Signal()
        m.d.comb += [e_drop.eq(e_v & ~e_marker & ~en_rp.data),
                     it_adv.eq(~e_v | e_drop | job_fifo.w_rdy),
                     en_rp.addr.eq(Mux(it_bank, ray + n_rays, ray)),
                     en_rp.en.eq(it_adv)]
        with m.If(it_adv):
            m.d.sync += [e_v.eq(emit), e_ray.eq(ray), e_sid.eq(it_sid), e_bank.eq(it_bank),
                         e_marker.eq(it_marker), e_ntris.eq(it_ntris)]
        job_in = data.View(job_layout, job_fifo.w_data)
        m.d.comb += [job_in.ray.eq(e_ray), job_in.sid.eq(e_sid), job_in.bank.eq(e_bank),
                     job_in.ntris.eq(e_ntris), job_in.marker.eq(e_marker),
                     job_fifo.w_en.eq(e_v & ~e_drop)]
        with m.If(e_drop):
            m.d.comb += inc["pairs_skipped"].eq(e_ntris)

        # -- 6. triangle expander and fetch -> pair FIFO ----------------------------------
        tl_rp = tl_mem.read_port()
        tri_rp = tri_mem.read_port()
        ray_rp = ray_mem.read_port()
        t_busy = Signal()
        t_k = Signal(range(tps + 1))
        t_job = Signal(job_layout)
        g_adv = Signal()
        g1_v = Signal(name="g1_v")
        g2_v = Signal(name="g2_v")
        g1_ray = Signal(ray_bits, name="g1_ray")
        g2_ray = Signal(ray_bits, name="g2_ray")
        g1_bank = Signal()
        g1_marker = Signal(name="g1_marker")
        g2_marker = Signal(name="g2_marker")
        g2_tri = Signal(tri_bits)
        t_last = Signal()
        m.d.comb += t_last.eq(t_job.marker | (t_k == t_job.ntris - 1))
        job_out = data.View(job_layout, job_fifo.r_data)
        pop = Signal()
        m.d.comb += [pop.eq(g_adv & (~t_busy | t_last)), job_fifo.r_en.eq(pop)]
        with m.If(g_adv & t_busy):
            m.d.sync += t_k.eq(t_k + 1)
        with m.If(pop):
            m.d.sync += [t_busy.eq(job_fifo.r_rdy), t_job.eq(job_out), t_k.eq(0)]
        m.d.comb += [tl_rp.addr.eq(t_job.sid * tps + t_k), tl_rp.en.eq(g_adv)]
        with m.If(g_adv):
            m.d.sync += [g1_v.eq(t_busy), g1_ray.eq(t_job.ray), g1_bank.eq(t_job.bank),
                         g1_marker.eq(t_job.marker),
                         g2_v.eq(g1_v), g2_ray.eq(g1_ray), g2_marker.eq(g1_marker),
                         g2_tri.eq(tl_rp.data)]
        m.d.comb += [tri_rp.addr.eq(tl_rp.data), tri_rp.en.eq(g_adv),
                     ray_rp.addr.eq(Mux(g1_bank, g1_ray + n_rays, g1_ray)),
                     ray_rp.en.eq(g_adv)]
        # Ray Memory and Triangle Memory words are the records RAY and TRIANGLE
        pair_layout = data.StructLayout({"ray": ray_bits, "marker": 1, "tri": tri_bits,
                                         "ray_data": struct_layout(RAY, cfg),
                                         "tri_data": struct_layout(TRIANGLE, cfg)})
        m.submodules.pair_fifo = pair_fifo = SyncFIFOBuffered(width=pair_layout.size,
                                                             depth=cfg.fifo_depth)
        pair_in = data.View(pair_layout, pair_fifo.w_data)
        m.d.comb += [g_adv.eq(~g2_v | pair_fifo.w_rdy),
                     pair_in.ray.eq(g2_ray), pair_in.marker.eq(g2_marker),
                     pair_in.tri.eq(g2_tri), pair_in.ray_data.eq(ray_rp.data),
                     pair_in.tri_data.eq(tri_rp.data),
                     pair_fifo.w_en.eq(g2_v),
                     self.fifo_level.eq(pair_fifo.level)]
        # a record offered to a full FIFO while the fetch pipeline moves on would be lost
        with m.If(g2_v & ~pair_fifo.w_rdy & g_adv):
            m.d.sync += self.fifo_overflow.eq(1)

        # -- 7. ray-triangle unit ---------------------------------------------------------------
        pair_out = data.View(pair_layout, pair_fifo.r_data)
        rp_ = rtu.i.payload
        m.d.comb += [rtu.i.valid.eq(pair_fifo.r_rdy), pair_fifo.r_en.eq(rtu.i.ready),
                     rp_.ray_id.eq(Cat(pair_out.ray, pair_out.marker)),
                     rp_.tri_id.eq(pair_out.tri)]
        m.d.comb += [rp_[f.name].eq(pair_out.ray_data[f.name]) for f in RAY]
        m.d.comb += [rp_[f.name].eq(pair_out.tri_data[f.name]) for f in TRIANGLE]
        with m.If(rtu.i.valid & rtu.i.ready & ~pair_out.marker):
            m.d.comb += inc["pairs_issued"].eq(1)

        # -- 8. result framing -> output FIFO -------------------------------------------------
        m.submodules.out_fifo = out_fifo = SyncFIFOBuffered(width=self.result_layout.size,
                                                            depth=OUT_FIFO_DEPTH)
        held = Signal(self.result_layout)
        held_v = Signal()
        r = rtu.o.payload
        r_marker = r.ray_id[ray_bits]
        take = Signal()
        m.d.comb += [rtu.o.ready.eq(out_fifo.w_rdy), take.eq(rtu.o.valid & out_fifo.w_rdy)]
        beat = data.View(self.result_layout, out_fifo.w_data)
        fresh = Signal(self.result_layout)
        m.d.comb += [fresh.ray_id.eq(r.ray_id[:ray_bits]), fresh.tri_id.eq(r.tri_id),
                     fresh.hit.eq(r.hit), fresh.t.eq(r.t), fresh.u.eq(r.u), fresh.v.eq(r.v),
                     fresh.det.eq(r.det), fresh.flags.eq(r.flags)]
        with m.If(take):
            with m.If(r_marker):
                m.d.comb += out_fifo.w_en.eq(1)
                with m.If(held_v):
                    m.d.comb += [beat.eq(held), beat.last.eq(1)]
                with m.Else():
                    m.d.comb += [beat.eq(0), beat.last.eq(1), beat.empty.eq(1)]
                m.d.sync += held_v.eq(0)
            with m.Else():
                m.d.comb += [out_fifo.w_en.eq(held_v), beat.eq(held)]
                m.d.sync += [held.eq(fresh), held_v.eq(1)]
                m.d.comb += [inc["hits"].eq(r.hit), inc["overflow"].eq(r.n_overflow),
                             inc["underflow"].eq(r.n_underflow),
                             inc["invalid"].eq(r.n_invalid)]
        m.d.comb += [self.o.valid.eq(out_fifo.r_rdy), self.o.payload.eq(out_fifo.r_data),
                     out_fifo.r_en.eq(self.o.ready)]

        # -- run book-keeping ---------------------------------------------------------------------
        # runs in flight: at most one marker per pipeline slot between cmd and o
        outstanding = Signal(range(cfg.fifo_depth + psa.fifo_depth + psa.latency + rtu.latency
                                   + rtu.fifo_depth + JOB_FIFO_DEPTH + OUT_FIFO_DEPTH + 16))
        started = Signal()
        finished = Signal()
        m.d.comb += [started.eq(self.cmd.valid & self.cmd.ready),
                     finished.eq(self.o.valid & self.o.ready & self.o.payload.last)]
        m.d.sync += outstanding.eq(outstanding + started - finished)
        m.d.comb += [self.busy.eq(outstanding != 0), inc["cycles"].eq(self.busy)]
        for mem in rams:       # every port is taken by now
            mem.add_to(m)
        return m


def build_intersection_unit(fmt=None, multiplier: str = "generic", **params
                            ) -> IntersectionUnit:
    """Builder for ``raplas-hdl verilog intersection-unit`` (keywords of :class:`UnitConfig`,
    and ``multiplier``)."""
    if fmt is not None:
        params["fmt"] = fmt
    return IntersectionUnit(UnitConfig(**params), multiplier=multiplier)
