"""The whole intersection unit: memories, plane-sphere array, selector, pair FIFO, ray-triangle.

The host writes the memories through one write port (address map in
:mod:`raplas_hdl.model.memory_image`) and starts *runs* through the ``cmd`` stream; each run
tests a range (or a list) of spheres against the bundle in one of two banks, and its
results leave through the ``o`` stream, the last beat of the run marked ``last``. A run
with the ``keep_all`` bit culls nothing: every sphere passes the plane test. The golden
model is :func:`raplas_hdl.model.intersection.run_bundle`. The ports' payloads are the
records ``CMD``, ``RESULT`` and ``COUNTERS`` of :mod:`raplas_hdl.model.records`.

The unit is its stages, components of :mod:`raplas_hdl.rtl.unit` joined by streams
(``wiring.connect``; the FIFOs through ``w_stream``/``r_stream``), in data-flow order:

1. :class:`~raplas_hdl.rtl.unit.memories.WriteDecoder`: the host write port into the
   memories' write ports;
2. :class:`~raplas_hdl.rtl.unit.feeder.SphereFeeder`: the command / plane loader and the
   sphere feeder, ``cmd`` -> spheres (then the run's marker);
3. :class:`~raplas_hdl.rtl.plane_sphere.PlaneSphereArray`: spheres -> row and column masks
   -> a 3-deep sphere slice (a buffered FIFO: the array's FIFO reads on its registered
   ``w_rdy``, not through the selector's enable lookup into the array's credit counter, a
   path of 10.5 ns placed and routed on an ECP5 at speed 6);
4. :class:`~raplas_hdl.rtl.unit.selector.PairSelector`: the ray iterator and the enable
   lookup, masks -> jobs (one enabled ray of one sphere) -> a 4-deep job FIFO;
5. :class:`~raplas_hdl.rtl.unit.fetch.RecordFetch`: the triangle expander and the record
   fetch, jobs -> pairs -> the pair FIFO (``fifo_depth``; a
   :class:`~raplas_hdl.rtl.unit.credit_fifo.CreditFIFO`, as the feeder's sphere FIFO: the
   writer's credits make room, so a write does not wait on the FIFO's level);
6. :class:`~raplas_hdl.rtl.ray_triangle.RayTriangleUnit`: pairs -> results;
7. a 3-deep result FIFO (a register slice: the ray-triangle unit's FIFO reads into its
   registers, not through the framing into the counters' adders, a path of 10.6 ns placed
   and routed on an ECP5 at speed 6), then
   :class:`~raplas_hdl.rtl.unit.framing.ResultFraming`: results -> beats (``last``,
   ``empty``) -> a 4-deep output FIFO -> ``o``; with ``UnitConfig.reduce`` the beats go
   through :class:`~raplas_hdl.rtl.unit.reducer.Reducer` first (one answer per ray, the
   record ``ANSWER``; its ``blocked`` rays feed back to the selector: the any-hit
   early-out);
8. :class:`~raplas_hdl.rtl.unit.framing.EventCounters`: the counters.

With ``UnitConfig.mode == "certified"`` the ray-triangle units are certified
(``RayTriangleUnit(mode="certified")``) and the result records carry each pair's
``outcome`` (``RESULT_CERTIFIED``; reduced, ``ANSWER_CERTIFIED``: a run's uncertain pairs,
then its answers); the paper and conservative units are built as before.

With ``UnitConfig.lanes = K > 1``, stages 4-6 after the selector are K lanes (job FIFO,
record fetch, pair FIFO, ray-triangle unit) between a
:class:`~raplas_hdl.rtl.unit.lanes.JobDistributor` (job n to lane n mod K) and a
:class:`~raplas_hdl.rtl.unit.lanes.ResultMerger` (results back in job order): the result
stream is the K=1 stream beat for beat.

Every boundary is a stall pipeline, a credit pipeline (the sphere feeder, the record fetch)
or a FIFO; no ready signal reaches further back than the nearest FIFO's level. The stages'
streams and the drain rule (when the host may write which memory) are in
``docs/intersection-unit.md``.

Counters (32 bits, wrap around, zeroed by ``clear``): ``cycles`` (cycles while a run is
outstanding: ``busy``, from a count of runs that takes the ``cmd`` and last-beat handshakes
a cycle late and adds them back, so that the feeder's ``cmd.ready`` never reaches its
carry chain), ``spheres`` and ``plane_tests`` (counted into the feeder's sphere FIFO),
``pairs_issued`` (at the ray-triangle input), ``pairs_skipped`` (disabled rays), ``hits``,
and ``overflow``, ``underflow``, ``invalid``: the operations that raised the event, summed
over the issued pairs (the ray-triangle unit counts them per pair, up to 34, beside the ORed
``flags`` of the result stream).
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.fifo import SyncFIFOBuffered
from amaranth.lib.wiring import In, Out

from ..model.config import UnitConfig
from ..model.intersection import UNIT_BOUND_VARIANT
from ..model.records import CMD, COUNTERS, result_record
from ..model.reduction import check_reduce_format
from ..model.throughput import Timing
from .fp_add import check_adder
from .fp_mul import check_multiplier
from .plane_sphere import PlaneSphereArray
from .ram import RAM_IMPLS, SyncRAM
from .ray_triangle import RayTriangleUnit
from .records import struct_layout
from .unit.credit_fifo import CreditFIFO
from .unit.feeder import SphereFeeder
from .unit.fetch import RecordFetch
from .unit.framing import EventCounters, ResultFraming
from .unit.lanes import JobDistributor, ResultMerger
from .unit.memories import MEMORIES, WriteDecoder, bind_read, bind_write, memory_geometry
from .unit.reducer import RUN_FIFO_DEPTH, Reducer, answer_layout
from .unit.selector import PairSelector
from .unit.streams import job_layout

__all__ = ["IntersectionUnit", "build_intersection_unit", "port_layouts", "COUNTER_PORTS"]

#: Fields of the ``counters`` port, in order.
COUNTER_PORTS = COUNTERS.names
COUNTER_BITS = COUNTERS["cycles"].width
OUT_FIFO_DEPTH = 4
JOB_FIFO_DEPTH = 4
#: The result FIFO between the ray-triangle unit(s) and the framing: a registered head and
#: a registered ``w_rdy`` at one result per cycle (a 2-deep buffered FIFO takes one every
#: other cycle).
RESULT_FIFO_DEPTH = 3
#: The FIFO between the plane-sphere array and the selector: the array's FIFO reads on a
#: registered ``w_rdy``, so the selector's take (through its enable lookup) no longer reaches
#: the array's credit counter in one clock (that path held the whole unit at 95.5 MHz).
SPHERE_SLICE_DEPTH = 3
#: Width of the run numbers the reducer and the selector compare (runs between them are
#: fewer than the reducer's run FIFO plus its stages).
SEQ_BITS = 4
#: Bits per bank of the pair FIFO (:class:`CreditFIFO` ``banks``): its read enable loads the
#: output register the ray-triangle unit reads, 447 bits in one enable net took 6.6 to 8.7 ns
#: of the certified whole unit's 11.5 to 12.4 ns path (ECP5 speed 6, seeds 1 and 3).
PAIR_FIFO_BANK_BITS = 64


def port_layouts(cfg: UnitConfig) -> dict:
    """The struct layouts of the ``cmd``, ``o`` (``result``) and ``counters`` ports.

    They are the records :data:`~raplas_hdl.model.records.CMD`,
    :data:`~raplas_hdl.model.records.RESULT` (``ANSWER`` with ``cfg.reduce``; each with
    ``outcome`` in ``certified`` mode, :func:`~raplas_hdl.model.records.output_record`) and
    :data:`~raplas_hdl.model.records.COUNTERS` bound to ``cfg``."""
    return {"cmd": struct_layout(CMD, cfg),
            "result": answer_layout(cfg) if cfg.reduce else struct_layout(result_record(cfg),
                                                                          cfg),
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
    adder : {"generic", "virtex4"}
        The same for every :class:`~raplas_hdl.rtl.fp_add.FPAdd` (``virtex4``: shifts and
        significand add in two DSP48, latency 7; :mod:`raplas_hdl.rtl.fp_add_dsp48`).
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
        ``last``, ``empty`` (and ``outcome`` in ``certified`` mode: 0 miss, 1 certain hit,
        2 uncertain); with ``config.reduce`` the answers (``ANSWER``: one per ray with an
        answer, :mod:`raplas_hdl.model.reduction`; in ``certified`` mode a run's uncertain
        pairs first, ``outcome`` 2, then its answers, ``outcome`` 1).
    counters : Out(counter_layout)
        ``cycles`` and the counters of
        :data:`~raplas_hdl.model.config.COUNTER_NAMES`, 32 bits each.
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
                 adder: str = "generic", ram: str = "memory", **params):
        self._multiplier = check_multiplier(multiplier)
        self._adder = check_adder(adder)
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
        if cfg.mode == "certified" and cfg.reduce:
            check_reduce_format(cfg.fmt)
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
    def adder(self) -> str:
        return self._adder

    @property
    def latency(self):
        """None: the unit's delay depends on the scene (see the stage list)."""
        return None

    def cycle_timing(self):
        """The constants of the cycle model of this unit
        (:class:`raplas_hdl.model.throughput.Timing`): the array's and the ray-triangle
        unit's latencies and depths."""
        psa, rtu = self._subunits()
        psa._MustUse__silence = rtu._MustUse__silence = True   # built only to be inspected
        return Timing.of(self._cfg, psa.latency, psa.fifo_depth, rtu.latency, rtu.fifo_depth,
                         SPHERE_SLICE_DEPTH)

    # ------------------------------------------------------------------------------------
    def _subunits(self):
        """The plane-sphere array and the (first lane's) ray-triangle unit."""
        cfg = self._cfg
        psa = PlaneSphereArray(cfg.fmt, rows=cfg.rows, cols=cfg.cols, testers=cfg.n_testers,
                               sphere_id_bits=cfg.sphere_id_bits + 3,
                               multiplier=self._multiplier, adder=self._adder)
        return psa, self._ray_triangle_unit(1 if cfg.lanes == 1 else 2)

    def _ray_triangle_unit(self, tag_bits: int):
        """A ray-triangle unit whose ``ray_id`` carries ``tag_bits`` above the ray: the
        marker (and, in a lane, the job-last bit)."""
        cfg = self._cfg
        extra = {}
        if cfg.mode == "certified":
            extra["bound_variant"] = UNIT_BOUND_VARIANT
        return RayTriangleUnit(cfg.fmt, mode=cfg.mode, margin_scale=cfg.margin_scale,
                               **extra, ray_id_bits=cfg.ray_id_bits + tag_bits,
                               tri_id_bits=cfg.tri_id_bits,
                               multiplier=self._multiplier, adder=self._adder)

    def elaborate(self, platform):
        cfg = self._cfg
        m = Module()
        psa, rtu = self._subunits()
        m.submodules.psa = psa
        if cfg.lanes == 1:
            m.submodules.rtu = rtu
        else:
            rtu._MustUse__silence = True              # each lane builds its own
        m.submodules.writes = writes = WriteDecoder(cfg)
        m.submodules.feeder = feeder = SphereFeeder(cfg, capacity=2 * psa.latency + 8)
        m.submodules.selector = selector = PairSelector(cfg, seq_bits=SEQ_BITS)

        # the streams, in data-flow order; the back end (job FIFO, record fetch, pair FIFO,
        # ray-triangle unit) once, or in lanes between a distributor and a merger
        if cfg.reduce:
            # the reducer learns each run's bank at the command (a run is accepted when
            # both the feeder and the reducer's run FIFO can take it)
            m.submodules.reducer = reducer = Reducer(cfg, ram=self._ram, seq_bits=SEQ_BITS)
            room, idle = reducer.run_bank.ready, feeder.cmd.ready
            m.d.comb += [feeder.cmd.payload.eq(self.cmd.payload),
                         feeder.cmd.valid.eq(self.cmd.valid & room),
                         reducer.run_bank.payload.eq(self.cmd.payload.bank),
                         reducer.run_bank.valid.eq(self.cmd.valid & idle),
                         self.cmd.ready.eq(idle & room),
                         reducer.wr_en.eq(self.wr_en), reducer.wr_addr.eq(self.wr_addr),
                         reducer.wr_data.eq(self.wr_data),
                         selector.blocked.eq(reducer.blocked),
                         selector.blocked_seq.eq(reducer.seq)]
        else:
            wiring.connect(m, wiring.flipped(self.cmd), feeder.cmd)
        wiring.connect(m, feeder.o, psa.i)
        m.submodules.sphere_slice = sphere_slice = SyncFIFOBuffered(
            width=psa.o.payload.shape().size, depth=SPHERE_SLICE_DEPTH)
        wiring.connect(m, psa.o, sphere_slice.w_stream)
        wiring.connect(m, sphere_slice.r_stream, selector.i)
        if cfg.lanes == 1:
            fetches, rtus, pair_fifos = self._lane(m, "", rtu, selector.o)
            results = rtu.o
        else:
            m.submodules.distributor = dist = JobDistributor(cfg)
            m.submodules.merger = merger = ResultMerger(cfg)
            wiring.connect(m, selector.o, dist.i)
            fetches, rtus, pair_fifos = [], [], []
            for k in range(cfg.lanes):
                lane = self._lane(m, f"_{k}", self._ray_triangle_unit(2), dist.o[k],
                                  job_last=True)
                wiring.connect(m, lane[1][0].o, merger.i[k])
                for acc, part in zip((fetches, rtus, pair_fifos), lane):
                    acc.extend(part)
            results = merger.o
        m.submodules.framing = framing = ResultFraming(cfg)
        m.submodules.out_fifo = out_fifo = SyncFIFOBuffered(width=self.result_layout.size,
                                                            depth=OUT_FIFO_DEPTH)
        m.submodules.events = events = EventCounters(cfg)
        m.submodules.result_fifo = result_fifo = SyncFIFOBuffered(
            width=framing.i.payload.shape().size, depth=RESULT_FIFO_DEPTH)
        wiring.connect(m, results, result_fifo.w_stream)
        wiring.connect(m, result_fifo.r_stream, framing.i)
        if cfg.reduce:
            wiring.connect(m, framing.o, reducer.i)
            wiring.connect(m, reducer.o, out_fifo.w_stream)
        else:
            wiring.connect(m, framing.o, out_fifo.w_stream)
        wiring.connect(m, out_fifo.r_stream, wiring.flipped(self.o))
        level = pair_fifos[0].level
        for fifo in pair_fifos[1:]:
            level = Mux(fifo.level > level, fifo.level, level)
        m.d.comb += [writes.wr_en.eq(self.wr_en), writes.wr_addr.eq(self.wr_addr),
                     writes.wr_data.eq(self.wr_data),
                     feeder.plane_written.eq(writes.plane_written),
                     feeder.retired.eq(selector.i.valid & selector.i.ready),
                     psa.pw_en.eq(feeder.pw_en), psa.pw_addr.eq(feeder.pw_addr),
                     psa.pw_data.eq(feeder.pw_data),
                     self.fifo_level.eq(level),
                     self.fifo_overflow.eq(fetches[0].overflow if len(fetches) == 1 else
                                           Cat(*[f.overflow for f in fetches]).any())]

        # the memories (named as the scene backdoor of the job-stream harness expects) and
        # the stages' ports on them: one read port per lane on the fetch's memories
        readers = {"tri": fetches, "sphere": [feeder], "count": [selector],
                   "tlist": fetches, "plane": [feeder], "ray": fetches,
                   "enable": [selector], "rlist": [feeder]}
        for key, (width, depth, lane) in memory_geometry(cfg).items():
            # never a read and a write of one address in a clock: the host writes the scene
            # memories between runs and the other memories' bank no run reads
            mem = SyncRAM(width, depth, impl=self._ram, name=MEMORIES[key], collision_free=True)
            bind_write(m, mem.write_port(granularity=lane), getattr(writes, key))
            for reader in readers[key]:
                bind_read(m, mem.read_port(), getattr(reader, key))
            mem.add_to(m)

        # counters and run book-keeping: runs in flight, at most one marker per pipeline
        # slot between cmd and o
        lane_slots = cfg.fifo_depth + rtu.latency + rtu.fifo_depth + JOB_FIFO_DEPTH
        outstanding = Signal(range(psa.fifo_depth + SPHERE_SLICE_DEPTH + psa.latency
                                   + cfg.lanes * lane_slots
                                   + RESULT_FIFO_DEPTH + OUT_FIFO_DEPTH + RUN_FIFO_DEPTH
                                   + 16))
        # ``outstanding`` lags a cycle: the handshakes that change it are registered first
        # (``cmd.ready`` comes from the feeder's state, which sits far from this counter),
        # and ``busy`` adds them back, so it is the unlagged count's ``!= 0``
        started, finished = Signal(), Signal()
        m.d.sync += [started.eq(self.cmd.valid & self.cmd.ready),
                     finished.eq(self.o.valid & self.o.ready & self.o.payload.last),
                     outstanding.eq(outstanding + started - finished)]
        now = Mux(finished, Mux(started, outstanding != 0, outstanding != 1),
                  started | (outstanding != 0))
        issued = [u.i.valid & u.i.ready & ~u.i.payload.ray_id[cfg.ray_id_bits] for u in rtus]
        inc = events.inc
        m.d.comb += [self.busy.eq(now), inc.cycles.eq(self.busy),
                     inc.spheres.eq(feeder.spheres),
                     inc.plane_tests.eq(Mux(feeder.spheres, cfg.n_planes, 0)),
                     inc.pairs_issued.eq(sum(issued[1:], issued[0])),
                     inc.pairs_skipped.eq(selector.skipped),
                     events.clear.eq(self.clear), self.counters.eq(events.counters)]
        m.d.comb += [inc[name].eq(framing.events[name])
                     for name in ("hits", "overflow", "underflow", "invalid")]
        return m

    def _lane(self, m, suffix, rtu, jobs, job_last=False):
        """Job FIFO -> record fetch -> pair FIFO -> ``rtu`` from the stream ``jobs``;
        submodules named ``job_fifo``, ``fetch``, ``pair_fifo`` (and ``rtu``) + ``suffix``.
        Returns ([fetch], [rtu], [pair FIFO])."""
        cfg = self._cfg
        job_fifo = SyncFIFOBuffered(width=job_layout(cfg).size, depth=JOB_FIFO_DEPTH)
        fetch = RecordFetch(cfg, depth=cfg.fifo_depth, job_last=job_last)
        # the fetch writes on its credits: a FIFO that takes every write (no level -> write
        # enable -> level loop)
        pair_bits = fetch.o.payload.shape().size
        pair_fifo = CreditFIFO(width=pair_bits, depth=cfg.fifo_depth,
                               banks=-(-pair_bits // PAIR_FIFO_BANK_BITS))
        m.submodules["job_fifo" + suffix] = job_fifo
        m.submodules["fetch" + suffix] = fetch
        m.submodules["pair_fifo" + suffix] = pair_fifo
        if suffix:
            m.submodules["rtu" + suffix] = rtu
        wiring.connect(m, jobs, job_fifo.w_stream)
        wiring.connect(m, job_fifo.r_stream, fetch.i)
        wiring.connect(m, fetch.o, pair_fifo.w_stream)
        wiring.connect(m, pair_fifo.r_stream, rtu.i)
        m.d.comb += fetch.freed.eq(pair_fifo.r_stream.valid & pair_fifo.r_stream.ready)
        return [fetch], [rtu], [pair_fifo]

def build_intersection_unit(fmt=None, multiplier: str = "generic", adder: str = "generic",
                            **params) -> IntersectionUnit:
    """Builder for ``raplas-hdl verilog intersection-unit`` (keywords of :class:`UnitConfig`,
    and ``multiplier``, ``adder``)."""
    if fmt is not None:
        params["fmt"] = fmt
    return IntersectionUnit(UnitConfig(**params), multiplier=multiplier, adder=adder)
