"""Stream stages of the intersection unit checked with SymbiYosys: nothing lost, doubled,
reordered or dropped under any pattern of ``valid``, ``ready`` and reset.

Each stage is emitted by Amaranth exactly as the unit instantiates it (small parameters) and
wrapped in a formal harness (``read_verilog -formal``) whose inputs are free in every cycle:
``valid``, ``ready``, ``rst`` and the payloads. The harness assumes what the stage's
neighbours guarantee (an input stream keeps ``valid`` and its payload until taken: the
stream rule) and asserts:

- **the stream rule** on every output: a beat offered and not taken is offered again, with
  the same payload, in the next cycle (unless ``rst``);
- **conservation and order**, by sequence numbers: the environment numbers the beats it
  sends (some payload bits are the count of beats accepted so far, as the stages treat
  their payload as opaque data, except the merger's job-last bit, which stays free), and
  every beat that leaves must carry the count of beats that left before it: so no beat is
  lost, doubled or reordered, for runs as long as the counters (wider than the stage's
  capacity);
- **what is held**: beats in = beats out + beats held (the FIFO's ``level``, 0 for the
  combinational lanes), and the stage's own ready/valid read from it;
- for the FIFO, a bounded latency: a word held and not offered is offered in the next
  cycle (with the one-cycle read of the block RAM, at most two edges after its write);
- for the FIFO written on credits (:class:`~raplas_hdl.rtl.unit.credit_fifo.CreditFIFO`,
  which takes every write), an environment that holds the writers' credits (``depth`` at
  reset, one spent per write, one back a cycle after each read) and no other assumption on
  its writes; the harness asserts that every write then finds a free entry (``w_rdy``), the
  premise of taking it unchecked, besides all of the above;
- for the ray-triangle unit's output (``output-credits``: its credit count,
  :func:`~raplas_hdl.rtl.credit_count.credit_count`, in front of a pipeline that never
  stalls, and :class:`~raplas_hdl.rtl.ram.CreditSyncFIFO`, which takes every write, behind
  it), with ``valid`` and ``ready`` free: the FIFO is never written full; ``ready`` is
  exactly "fewer than the FIFO's depth accepted and not yet taken" (so the count's
  registered take and comparisons lose no cycle); accepted = taken + in the pipeline + in
  the FIFO; the pairs leave in order, each once, under the stream rule;
- for the job distributor, that beat ``n`` leaves on lane ``n mod K``; for the result
  merger, that it takes lane ``k``'s beats only between job-last beats ``k - 1`` and ``k``
  (mod K);
- for the result framing (:class:`~raplas_hdl.rtl.unit.framing.ResultFraming`), whose
  input's marker bit is free (markers arrive at any time, their other bits free too; a
  result's number is in the low bits of its ``t``): results in = non-empty beats out + the
  hold register's valid (0 or 1), which is set exactly when a result came since the last
  marker, and then holds that result's beat; a beat leaves with each input taken, except a
  run's first result (it only fills the hold register); a non-empty beat carries its
  result's fields, in order, once each, with ``last`` set exactly when the next input is a
  marker; an ``empty`` beat (``last`` set, every other field 0) leaves exactly for a marker
  with no result since the previous marker or reset;
- for the pair selector (:class:`~raplas_hdl.rtl.unit.selector.PairSelector`), whose two
  read ports the harness answers as the memories do (the word addressed at the last ``en``)
  from contents that are free but fixed for the check (the spheres' triangle counts and
  both banks' enable bits: the host writes them between runs): sphere after sphere as
  taken, each ray of its masks (every ray with ``keep_all``; none if it has no triangle),
  rows ascending then columns, leaves as a job (that ray, the sphere, its bank and triangle
  count) if the ray is enabled, or else as ``skipped`` = its triangle count for one cycle;
  a marker gives one marker job; one ray a cycle, and a ray due waits at most one cycle
  with ``o.ready`` high. With the reduction's early-out (``pair-selector-reduce``),
  ``blocked`` and ``blocked_seq`` are free in every cycle (any report the reducer could
  make, and more) and the harness numbers the runs by the marker jobs taken: an enabled ray
  whose bit was set in the report of the cycle before, for the run with that number, is
  dropped without a job and without ``skipped`` (a disabled one is skipped as before),
  every other ray as without the early-out; a job is offered exactly for a marker or an
  enabled ray not so blocked; and the stream rule on ``o`` holds except that a job offered
  under ``!o.ready`` is withdrawn when its ray is reported blocked (harmless behind the job
  FIFO, which writes on ``valid`` and ``ready``);
- for the record fetch (:class:`~raplas_hdl.rtl.unit.fetch.RecordFetch` as a lane builds
  it, the job-last bit above the marker), whose three read ports the harness answers from
  free, fixed contents (the triangle lists, the Ray Memory's two banks, the Triangle
  Memory), and whose ``o`` writes into a FIFO the harness keeps as a level (the reader takes
  a word when there is one; each read comes back on ``freed``): no pair is written without
  a free entry (``o.ready``, and ``overflow`` stays 0); the jobs taken, numbered by the
  harness (every field of a job is an address or a count, none opaque), leave job after
  job as their pairs, ``ntris`` of them (one for a marker, the jobs assumed to be markers
  or to have 1 to ``tris_per_sphere`` triangles), each with the job's ray and marker bit,
  job-last on the last, the ``k``-th triangle of the sphere's list, and the Ray Memory's
  word at the ray in the job's bank and the Triangle Memory's at that triangle; credits
  held + pairs in flight + words in the FIFO + reads on their way back = ``depth``; a job
  taken while the FIFO behind is empty writes a pair within 4 cycles;
- for the sphere feeder (:class:`~raplas_hdl.rtl.unit.feeder.SphereFeeder`, with its
  sphere FIFO), whose read ports the harness answers from free, fixed contents (the run
  lists, the Sphere Memory, the Plane Memory's two banks), and behind whose ``o`` it keeps
  the array as a count (items taken from ``o``, less those ``retired``, which it assumes
  only when there is one), with ``plane_written`` free, and runs assumed inside the
  memories (``first + count <= max_spheres``): the runs taken leave run after run, each as
  its ``count`` spheres (position ``first + pos``, or the run list's entry there in the
  run's bank when ``indirect``) with the Sphere Memory's word and the run's tag bits, then
  its marker; every item leaves while the array holds all the planes of its run's bank;
  planes are written only while no item is on its way to or through the array, in order,
  the Plane Memory's words of the last run's bank; credits held + items in the pipeline +
  in the sphere FIFO + reads on their way back = the FIFO's depth. Checked to a stated
  depth (``bmc``): an induction over the sphere FIFO's words needs the invariant the FIFOs'
  checks cannot state either;
- for the reducer (:class:`~raplas_hdl.rtl.unit.reducer.Reducer`, the whole pipeline, e3m2,
  2 x 2 rays), the send stage's order and framing: ``i``, ``run_bank`` (both under the
  stream rule), ``o.ready`` and the host's writes free, the harness numbers the runs by the
  ``last`` beats taken and keeps, per run, the rays with a hit beat (``hit``, not
  ``empty``); an answer leaves only for a run whose ``last`` beat came in (at most 7 in
  flight); within a run the rays leave ascending (each once), each with a hit beat in that
  run; ``last`` exactly when no answer is left (the ``valid`` bits, probed: every ray left
  above the one sent, with a hit beat), or one ``empty`` beat with ``last`` for a run
  without answers; and the stream rule on ``o``. Checked to a stated depth (``bmc``): the
  products and the answer RAM are state no invariant of the harness names. In certified
  mode (``reducer-certified``) the environment also numbers its beats in ``u`` (carried,
  never compared) with ``hit`` = ``outcome == 1``: the pairs passed on in stage ``r``
  (``emit``, probed) = those out + the output and skid registers' (none lost or doubled),
  and each leaves in stream order, a beat of the run being reduced with its ray and a
  non-zero outcome, never ``last`` and never after an answer of its run.

The stages and what each checks are :data:`STAGES`; :func:`check_stage` runs one
(k-induction, ``mode prove``; a stage whose induction does not close at the depth given is
``unknown``, never passed; the FIFOs, the sphere feeder and the reducer are checked to a
stated depth instead, since an induction over a FIFO's memory words (the reducer's: its
RAMs and pipeline registers) needs an invariant the harness cannot state). Cover statements
show the checks are not vacuous: each stage must reach a full FIFO (the output on credits:
also a pair accepted on a credit given back after all were in use) / a lane change / an
``empty`` beat, a ``last`` beat and a beat held under ``!ready`` / a skipped ray, a marker
job, a job held under ``!ready``, every ray of a sphere (with the early-out, also a blocked
ray dropped, and a job of a ray blocked in another run's report) / a job's two pairs, a
marker's pair, the write that spends the last credit, a pair on a credit given back / a
sphere from a run list, the marker of a run of two spheres, an item held under ``!ready``,
a second plane load after an item went through the array / a run's second answer leaving
``last``, an ``empty`` beat, an answer held under ``!ready`` / a transfer while a reset is
free.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, replace
from pathlib import Path

from ..fp import FP16, FPFormat
from .netlist import WORK_DIR
from .sby import run_job

__all__ = ["STAGES", "Stage", "check_stage", "stage_verilog"]

#: The SymbiYosys job: ``{mode}`` prove or cover, ``{depth}``, ``{timeout}``.
_SBY = """[options]
mode {mode}
depth {depth}
timeout {timeout}

[engines]
smtbmc z3

[script]
read_verilog stage.v
read_verilog -formal check.v
prep -top stream_check -flatten
{probes}
[files]
stage.v
check.v
"""

SEQ = 4         # bits of the sequence numbers of the lanes' checks
FIFO_SEQ = 3    # the FIFO's words: sequence numbers mod 8, more than the 4 words it holds
FETCH_FORMAT = FPFormat(3, 2)   # the record fetch's words: 6-bit fields
CREDIT_PIPE = 3     # the output-credits check's pipeline; its FIFO is 2 deeper, as the unit's


@dataclass(frozen=True)
class Stage:
    """One stream stage and its check.

    Attributes
    ----------
    name : str
    what : str
        One line: the component and its parameters.
    depth : int
        k of the k-induction, or the cycles of the bounded check.
    mode : str
        ``prove`` (k-induction) or ``bmc`` (bounded: the property holds for ``depth``
        cycles from reset, where the induction cannot close without an invariant over the
        memory's words).
    probes : tuple
        ``(wire, internal name)``: an internal register of the stage tied to a wire of the
        harness after flattening (``connect -set``), so the harness can state the
        invariant that links it to its own counters (which k-induction needs).
    cover : int or None
        Cycles of the cover run; ``depth + 4`` if None.
    """

    name: str
    what: str
    depth: int
    mode: str = "prove"
    probes: tuple = ()
    cover: int | None = None


STAGES = {s.name: s for s in (
    Stage("bram-fifo", "rtl.ram.BlockRAMFIFO(width=3, depth=4): the ray-triangle unit's "
          "output FIFO in block RAM", 12, "bmc"),
    Stage("sync-fifo-buffered", "amaranth.lib.fifo.SyncFIFOBuffered(width=3, depth=4): the "
          "unit's job and result FIFOs", 12, "bmc"),
    Stage("credit-fifo", "rtl.unit.credit_fifo.CreditFIFO(width=3, depth=4) behind a writer "
          "with credits: the unit's pair and sphere FIFOs", 12, "bmc"),
    Stage("credit-fifo-banked", "rtl.unit.credit_fifo.CreditFIFO(width=3, depth=4, banks=3) "
          "behind a writer with credits: the pair FIFO in banks, one bit each", 12, "bmc"),
    Stage("output-credits", f"rtl.credit_count.credit_count in front of a {CREDIT_PIPE}-cycle "
          f"pipeline that never stalls and rtl.ram.CreditSyncFIFO(width=3, "
          f"depth={CREDIT_PIPE + 2}) behind it: the ray-triangle unit's output on credits",
          12, "bmc", cover=14),
    Stage("job-distributor", "rtl.unit.lanes.JobDistributor, 3 lanes", 8,
          probes=(("turn_probe", "dut.turn"),)),
    Stage("result-merger", "rtl.unit.lanes.ResultMerger, 3 lanes", 8,
          probes=(("turn_probe", "dut.turn"),)),
    Stage("result-framing", "rtl.unit.framing.ResultFraming, FP16, 2 rays, generic mode: "
          "stage 8, one result held back for the run's last", 8,
          probes=(("held_v_probe", "dut.held_v"), ("held_probe", "dut.held"))),
    Stage("pair-selector", "rtl.unit.selector.PairSelector, 2 x 2 rays, 2 spheres, no "
          "reduction: stages 4 and 5, one job per enabled ray", 8,
          probes=(("e_v_probe", "dut.e_v"), ("it_probe", "dut.it"))),
    Stage("pair-selector-reduce", "rtl.unit.selector.PairSelector, 2 x 2 rays, 2 spheres, "
          f"reduce, {SEQ}-bit run numbers: stages 4 and 5 with the reducer's early-out", 8,
          probes=(("e_v_probe", "dut.e_v"), ("it_probe", "dut.it"),
                  ("seq_probe", "dut.$signal"))),      # its run number (unnamed)
    Stage("record-fetch", "rtl.unit.fetch.RecordFetch(depth=4, job_last=True), e3m2, 2 rays, "
          "2 spheres of 2 triangles: stage 6 as a lane builds it, on credits", 8, cover=14,
          probes=tuple((f"{r}_probe", f"dut.{r}")
                       for r in ("busy", "job", "k", "credit", "g1", "g2", "g3", "last",
                                 "has_credit"))),
    Stage("sphere-feeder", "rtl.unit.feeder.SphereFeeder, e3m2, 2 spheres, 2 planes: stages 1 "
          "and 2, plane loads and spheres on credits into its sphere FIFO", 18, "bmc", cover=18,
          probes=(*((f"{r}_probe", f"dut.{r}") for r in ("credit", "freed", "f1", "fs", "f2",
                                                          "f3")),
                  ("fifo_level_probe", "dut.fifo.inner_level"))),
    Stage("reducer-send", "rtl.unit.reducer.Reducer, e3m2, 2 x 2 rays, 4-bit run numbers: "
          "the send stage's order and framing, behind the whole pipeline", 20, "bmc",
          cover=20, probes=(("valid_probe", "dut.valid"),)),
    Stage("reducer-certified", "rtl.unit.reducer.Reducer, certified, e3m2, 2 x 2 rays, "
          "4-bit run numbers: passed-on pairs through the output and skid registers, before "
          "their run's answers", 16, "bmc", cover=16,
          probes=(("valid_probe", "dut.valid"), ("emit_probe", "dut.emit"),
                  ("en_probe", "dut.en"), ("sk_probe", "dut.sk_v"))),
)}


def _config(lanes: int, rows: int = 1, fmt=FP16):
    # lazy: model.config loads numba, only to build the unit's stages
    from ..model.config import UnitConfig

    return UnitConfig(fmt=fmt, rows=rows, cols=2, tris_per_sphere=2, max_triangles=4,
                      max_spheres=2, lanes=lanes)


def stage_verilog(name: str) -> tuple[str, dict]:
    """The stage's Verilog (module ``stage``) and its widths."""
    # lazy (here and below): Amaranth and the RTL load only when a stage is emitted
    from amaranth.back import verilog

    if name in ("bram-fifo", "sync-fifo-buffered"):
        from amaranth.lib.fifo import SyncFIFOBuffered

        from ..rtl.ram import BlockRAMFIFO

        cls = BlockRAMFIFO if name == "bram-fifo" else SyncFIFOBuffered
        f = cls(width=FIFO_SEQ, depth=4)
        ports = [f.w_data, f.w_en, f.w_rdy, f.r_data, f.r_en, f.r_rdy, f.level]
        return (verilog.convert(f, name="stage", ports=ports, emit_src=False),
                {"width": FIFO_SEQ, "depth": 4})
    if name in ("credit-fifo", "credit-fifo-banked"):
        from ..rtl.unit.credit_fifo import CreditFIFO

        f = CreditFIFO(width=FIFO_SEQ, depth=4,
                       banks=FIFO_SEQ if name == "credit-fifo-banked" else 1)
        return (verilog.convert(f, name="stage", emit_src=False),
                {"width": FIFO_SEQ, "depth": 4, "credits": True})
    if name == "output-credits":
        return _credits_verilog()
    if name == "result-framing":
        return _framing_verilog()
    if name in ("pair-selector", "pair-selector-reduce"):
        return _selector_verilog(name == "pair-selector-reduce")
    if name == "record-fetch":
        return _fetch_verilog()
    if name == "sphere-feeder":
        return _feeder_verilog()
    if name == "reducer-send":
        return _reducer_verilog()
    if name == "reducer-certified":
        return _reducer_verilog("certified")
    from ..rtl.unit.lanes import JobDistributor, ResultMerger

    cfg = _config(3)
    comp = (JobDistributor if name == "job-distributor" else ResultMerger)(cfg)
    if name == "job-distributor":
        width = comp.i.payload.shape().size
    else:
        width = comp.o.payload.shape().size
    info = {"lanes": 3, "width": width, "top": cfg.ray_id_bits + 1,
            "ray_lsb": _ray_lsb(comp) if name == "result-merger" else 0}
    return verilog.convert(comp, name="stage", emit_src=False), info


def _credits_verilog() -> tuple[str, dict]:
    """The ray-triangle unit's output as it builds it: :func:`~raplas_hdl.rtl.credit_count.
    credit_count` in front, a pipeline of :data:`CREDIT_PIPE` registers that never stalls
    (the valid bits reset, the data not), the FIFO behind written on the last valid bit."""
    from amaranth.back import verilog
    from amaranth.hdl import Cat, Elaboratable, Module, Signal

    from ..rtl.credit_count import credit_count
    from ..rtl.ram import CreditSyncFIFO

    depth = CREDIT_PIPE + 2

    class Output(Elaboratable):
        def __init__(self):
            for name in ("i_valid", "i_ready", "o_valid", "o_ready", "w_en", "w_rdy"):
                setattr(self, name, Signal(name=name))
            self.i_data = Signal(FIFO_SEQ, name="i_data")
            self.o_data = Signal(FIFO_SEQ, name="o_data")
            self.level = Signal(range(depth + 1), name="level")
            self.line = Signal(CREDIT_PIPE, name="line")

        def elaborate(self, platform):
            m = Module()
            fifo = m.submodules.fifo = CreditSyncFIFO(width=FIFO_SEQ, depth=depth)
            accept = credit_count(m, valid=self.i_valid, ready=self.i_ready,
                                  take=fifo.r_rdy & self.o_ready, depth=depth)
            valid, data = accept, self.i_data
            bits = []
            for k in range(CREDIT_PIPE):
                v, d = Signal(name=f"v{k}"), Signal(FIFO_SEQ, name=f"d{k}", reset_less=True)
                m.d.sync += [v.eq(valid), d.eq(data)]
                valid, data = v, d
                bits.append(v)
            m.d.comb += [fifo.w_en.eq(valid), fifo.w_data.eq(data), self.w_en.eq(valid),
                         self.w_rdy.eq(fifo.w_rdy), self.level.eq(fifo.level),
                         self.line.eq(Cat(*bits)), self.o_valid.eq(fifo.r_rdy),
                         fifo.r_en.eq(self.o_ready), self.o_data.eq(fifo.r_data)]
            return m

    top = Output()
    ports = [top.i_valid, top.i_ready, top.i_data, top.o_valid, top.o_ready, top.o_data,
             top.w_en, top.w_rdy, top.level, top.line]
    return (verilog.convert(top, name="stage", ports=ports, emit_src=False),
            {"width": FIFO_SEQ, "depth": depth, "pipe": CREDIT_PIPE})


def _credits_check(info: dict) -> str:
    w, depth, pipe = info["width"], info["depth"], info["pipe"]
    lw = depth.bit_length()
    in_flight = " + ".join(f"line[{k}]" for k in range(pipe))
    return f"""module stream_check(input clk, input rst, input i_valid, input o_ready);
  reg init = 1;
  reg [{w - 1}:0] n_in = 0, n_out = 0;
  wire [{w - 1}:0] i_data = n_in;
  wire i_ready, o_valid, w_en, w_rdy;
  wire [{w - 1}:0] o_data;
  wire [{lw - 1}:0] level;
  wire [{pipe - 1}:0] line;
  stage dut(.clk(clk), .rst(rst), .i_valid(i_valid), .i_ready(i_ready), .i_data(i_data),
            .o_valid(o_valid), .o_ready(o_ready), .o_data(o_data), .w_en(w_en),
            .w_rdy(w_rdy), .level(level), .line(line));
  reg offered = 0, full = 0;
  reg [{w - 1}:0] offered_data = 0;
  wire [{w - 1}:0] used = n_in - n_out;       // accepted and not yet taken
  always @(posedge clk) begin
    init <= 0;
    if (rst) begin n_in <= 0; n_out <= 0; end
    else begin
      if (i_valid && i_ready) n_in <= n_in + 1;
      if (o_valid && o_ready) n_out <= n_out + 1;
    end
    offered <= !rst && o_valid && !o_ready;
    offered_data <= o_data;
    full <= !rst && !i_ready;
  end
  always @* begin
    if (init) assume(rst);
    if (!init && !rst) begin
      if (w_en) assert(w_rdy);                   // the credits made room: never written full
      assert(i_ready == (used < {depth}));       // ready exactly while a credit is free
      assert(used == level + {in_flight});  // in = out + in flight + held
      assert(used <= {depth});
      if (o_valid) assert(o_data == n_out);      // in order, none lost or doubled
      if (offered) assert(o_valid && o_data == offered_data);   // the stream rule
      cover(full && i_ready);                    // out of credits, then one given back
      cover(level == {depth});
      cover(n_out == {depth + 2});
    end
  end
endmodule
"""


def _framing_verilog() -> tuple[str, dict]:
    from amaranth.back import verilog

    from ..rtl.unit.framing import ResultFraming

    cfg = _config(1)
    comp = ResultFraming(cfg)
    i_layout, o_layout = comp.i.payload.shape(), comp.o.payload.shape()
    # (offset in o, offset in i, width) of each field a result beat copies from its result;
    # ray_id loses its marker bit on the way
    copied = tuple((o_layout[n].offset, i_layout[n].offset, f.width)
                   for n, f in o_layout if n not in ("last", "empty"))
    info = {"iw": i_layout.size, "ow": o_layout.size, "copied": copied,
            "marker": i_layout["ray_id"].offset + cfg.ray_id_bits,
            "t_in": i_layout["t"].offset, "t_out": o_layout["t"].offset,
            "last": o_layout["last"].offset, "empty": o_layout["empty"].offset}
    return verilog.convert(comp, name="stage", emit_src=False), info


def _selector_verilog(reduce: bool = False) -> tuple[str, dict]:
    from amaranth.back import verilog

    from ..rtl.unit.selector import PairSelector
    from ..rtl.unit.streams import tag_layout

    cfg = replace(_config(1, rows=2), reduce=reduce)
    comp = PairSelector(cfg, seq_bits=SEQ)
    i_layout, o_layout, tag = comp.i.payload.shape(), comp.o.payload.shape(), tag_layout(cfg)
    tag_at = i_layout["id"].offset
    info = {"rows": cfg.rows, "cols": cfg.cols, "spheres": cfg.max_spheres,
            "iw": i_layout.size, "ow": o_layout.size, "count": cfg.count_bits,
            "sphere_bits": cfg.sphere_id_bits,
            "i": {**{n: tag_at + tag[n].offset for n in ("sphere", "marker", "bank", "keep_all")},
                  "row_mask": i_layout["row_mask"].offset,
                  "col_mask": i_layout["col_mask"].offset},
            "o": {n: (o_layout[n].offset, o_layout[n].width) for n, _ in o_layout},
            "reduce": reduce}
    return verilog.convert(comp, name="stage", emit_src=False), info


def _fetch_verilog() -> tuple[str, dict]:
    from amaranth.back import verilog

    from ..model.records import RAY, TRIANGLE
    from ..rtl.records import struct_layout
    from ..rtl.unit.fetch import RecordFetch

    # the fetch copies the records' words whole: a narrow format makes them cheaper to check
    cfg = _config(1, fmt=FETCH_FORMAT)
    comp = RecordFetch(cfg, depth=4, job_last=True)
    job, pair = comp.i.payload.shape(), comp.o.payload.shape()
    ray, tri = struct_layout(RAY, cfg), struct_layout(TRIANGLE, cfg)
    info = {"depth": 4, "tps": cfg.tris_per_sphere, "rays": cfg.n_rays,
            "spheres": cfg.max_spheres, "tris": cfg.max_triangles,
            "iw": job.size, "ow": pair.size, "rw": ray.size, "tw": tri.size,
            "tb": cfg.tri_id_bits, "rb": cfg.ray_id_bits,
            "job": {n: (f.offset, f.width) for n, f in job},
            "ray_id": pair["ray_id"].offset, "tri_id": pair["tri_id"].offset,
            # (offset in the pair, offset in the memory word, width) of each record field
            "ray": tuple((pair[n].offset, f.offset, f.width) for n, f in ray),
            "tri": tuple((pair[n].offset, f.offset, f.width) for n, f in tri),
            "abits": {n: getattr(comp, n).addr.shape().width for n in ("tlist", "ray", "tri")}}
    text = verilog.convert(comp, name="stage", emit_src=False)
    info["regs"] = _reg_widths(text, ("k", "credit", "g1", "g2", "g3"))
    return text, info


def _feeder_verilog() -> tuple[str, dict]:
    from amaranth.back import verilog

    from ..model.records import PLANE
    from ..rtl.records import struct_layout
    from ..rtl.unit.feeder import SPHERE_FIFO_DEPTH, SphereFeeder
    from ..rtl.unit.streams import tag_layout

    # one ray: two planes to load, so that a second load comes within the cycles checked
    cfg = replace(_config(1, fmt=FETCH_FORMAT), cols=1)
    comp = SphereFeeder(cfg, capacity=4)
    cmd, sph, tag = comp.cmd.payload.shape(), comp.o.payload.shape(), tag_layout(cfg)
    info = {"depth": SPHERE_FIFO_DEPTH, "spheres": cfg.max_spheres, "planes": cfg.n_planes,
            "sb": cfg.sphere_id_bits, "iw": cmd.size, "ow": sph.size,
            "sw": comp.sphere.data.shape().width, "pw": struct_layout(PLANE, cfg).size,
            "cmd": {n: (f.offset, f.width) for n, f in cmd},
            "tag": {n: sph["id"].offset + f.offset for n, f in tag},
            # the sphere's words as the feeder copies them from the Sphere Memory's word
            "c": (sph["c"].offset, sph["c"].width), "r": (sph["r"].offset, sph["r"].width),
            "abits": {n: getattr(comp, n).addr.shape().width
                      for n in ("rlist", "sphere", "plane")},
            "pw_addr": comp.pw_addr.shape().width}
    text = verilog.convert(comp, name="stage", emit_src=False)
    info["regs"] = _reg_widths(text, ("credit", "f1", "fs", "f2", "f3"))
    return text, info


def _reducer_verilog(mode: str = "paper") -> tuple[str, dict]:
    from amaranth.back import verilog

    from ..rtl.unit.reducer import Reducer

    # the send stage's order and framing do not depend on the format: the narrowest keeps
    # the products (which decide only which rays have answers) cheap
    cfg = replace(_config(1, rows=2, fmt=FETCH_FORMAT), reduce=True, mode=mode)
    comp = Reducer(cfg, seq_bits=SEQ)
    i_layout, o_layout = comp.i.payload.shape(), comp.o.payload.shape()
    certified = mode == "certified"
    info = {"rays": cfg.n_rays, "rb": cfg.ray_id_bits, "iw": i_layout.size,
            "ow": o_layout.size, "uw": cfg.fmt.width,
            "i": {n: i_layout[n].offset for n in ("ray_id", "hit", "last", "empty")
                  + (("u", "outcome") if certified else ())},
            "o": {n: o_layout[n].offset for n in ("ray_id", "last", "empty")
                  + (("u", "outcome") if certified else ())}}
    return verilog.convert(comp, name="stage", emit_src=False), info


def _reg_widths(text: str, names) -> dict:
    """The widths of registers ``names`` as declared in the emitted Verilog."""
    out = {}
    for name in names:
        found = re.search(rf"^  reg (?:\[(\d+):0\] )?{name} = ", text, re.M)
        out[name] = int(found.group(1)) + 1 if found and found.group(1) else 1
    return out


def _ray_lsb(merger) -> int:
    """Bit offset of ``ray_id`` in the merger's input payload."""
    layout = merger.i[0].payload.shape()
    return layout["ray_id"].offset


def _fifo_check(w: int, depth: int, credits: bool = False) -> str:
    if credits:        # CreditFIFO's stream ports; the writer holds credits
        dut = ("stage dut(.clk(clk), .rst(rst), .w_stream__payload(w_data), "
               ".w_stream__valid(w_en), .w_stream__ready(w_rdy),\n"
               "            .r_stream__payload(r_data), .r_stream__ready(r_en), "
               ".r_stream__valid(r_rdy), .level(level));")
        env = f"""  reg [2:0] credit = {depth};
  reg freed = 0;
  always @(posedge clk) begin
    if (rst) begin credit <= {depth}; freed <= 0; end
    else begin credit <= credit - w_en + freed; freed <= r_en && r_rdy; end
  end
"""
        rules = """    if (!init && !rst) assume(!w_en || credit != 0);   // a write spends a credit
"""
        premise = """      if (w_en) assert(w_rdy);                // the credits made room
"""
    else:
        dut = ("stage dut(.clk(clk), .rst(rst), .w_data(w_data), .w_en(w_en), "
               ".w_rdy(w_rdy),\n"
               "            .r_data(r_data), .r_en(r_en), .r_rdy(r_rdy), .level(level));")
        env = rules = premise = ""
    return f"""module stream_check(input clk, input rst, input w_en, input r_en);
  reg init = 1;
  reg [{w - 1}:0] n_in = 0, n_out = 0;
  wire [{w - 1}:0] w_data = n_in;
  wire w_rdy, r_rdy;
  wire [{w - 1}:0] r_data;
  wire [2:0] level;
  {dut}
{env}
  reg offered = 0, waiting = 0;
  reg [{w - 1}:0] offered_data = 0;
  always @(posedge clk) begin
    init <= 0;
    if (rst) begin n_in <= 0; n_out <= 0; end
    else begin
      if (w_en && w_rdy) n_in <= n_in + 1;
      if (r_en && r_rdy) n_out <= n_out + 1;
    end
    offered <= !rst && r_rdy && !r_en;
    offered_data <= r_data;
    waiting <= !rst && level != 0 && !r_rdy;
  end
  always @* begin
    if (init) assume(rst);
{rules}    if (!init && !rst) begin
{premise}      assert(level == n_in - n_out);          // beats in = beats out + beats held
      assert(level <= {depth});
      if (r_rdy) assert(r_data == n_out);      // in order, none lost or doubled
      if (r_rdy) assert(level != 0);
      if (!w_rdy) assert(level >= {depth - 1});
      if (offered) assert(r_rdy && r_data == offered_data);   // the stream rule
      if (waiting) assert(r_rdy);              // a held word is offered a cycle later
      cover(level == {depth});
      cover(n_out == {depth + 2});
    end
  end
endmodule
"""


def _distributor_check(info: dict) -> str:
    k, w = info["lanes"], info["width"]
    outs = "".join(f"  wire o{j}_valid; wire [{w - 1}:0] o{j}_payload;\n" for j in range(k))
    conns = "".join(f", .o__{j}__valid(o{j}_valid), .o__{j}__payload(o{j}_payload), "
                    f".o__{j}__ready(o{j}_ready)" for j in range(k))
    ready_in = "".join(f", input o{j}_ready" for j in range(k))
    asserts = []
    for j in range(k):
        asserts.append(f"""      if (o{j}_valid && o{j}_ready) begin
        assert(o{j}_payload[{SEQ - 1}:0] == n_out[{SEQ - 1}:0]);   // in order, once
        assert(lane == {j});                                  // beat n on lane n mod K
      end
      if (off{j}) assert(o{j}_valid && o{j}_payload == off{j}_data);
      cover(o{j}_valid && o{j}_ready && n_out == {k + j});""")
    regs = "".join(f"  reg off{j} = 0; reg [{w - 1}:0] off{j}_data = 0;\n" for j in range(k))
    upd = "".join(f"    off{j} <= !rst && o{j}_valid && !o{j}_ready;\n"
                  f"    off{j}_data <= o{j}_payload;\n" for j in range(k))
    taken = " + ".join(f"(o{j}_valid && o{j}_ready)" for j in range(k))
    return f"""module stream_check(input clk, input rst, input i_valid,
                    input [{w - 1 - SEQ}:0] i_free{ready_in});
  reg init = 1;
  reg [{SEQ - 1}:0] n_in = 0, n_out = 0;
  reg [1:0] lane = 0;
  wire [1:0] turn_probe;                       // the distributor's turn (connect -set)
  reg held = 0;
  reg [{w - 1}:0] held_payload = 0;
  wire [{w - 1}:0] i_payload = {{i_free, n_in}};
  wire i_ready;
{outs}{regs}  stage dut(.clk(clk), .rst(rst), .i__valid(i_valid), .i__payload(i_payload),
            .i__ready(i_ready){conns});
  wire [1:0] taken = {taken};
  always @(posedge clk) begin
    init <= 0;
    if (rst) begin n_in <= 0; n_out <= 0; lane <= 0; end
    else begin
      if (i_valid && i_ready) n_in <= n_in + 1;
      n_out <= n_out + taken;
      if (taken != 0) lane <= (lane == {k - 1}) ? 0 : lane + 1;
    end
    held <= !rst && i_valid && !i_ready;
    held_payload <= i_payload;
{upd}  end
  always @* begin
    if (init) assume(rst);
    if (!init && held) assume(i_valid && i_payload == held_payload);   // the stream rule
    if (!init && !rst) begin
      assert(n_in == n_out);                   // nothing held: beats in = beats out
      assert(turn_probe == lane);              // its turn is the beat count mod K
      assert(taken == (i_valid && i_ready));   // one out per one in, never two
{chr(10).join(asserts)}
    end
  end
endmodule
"""


def _merger_check(info: dict) -> str:
    k, w, top, lsb = info["lanes"], info["width"], info["top"], info["ray_lsb"]
    iw = w + 1                                   # the input payload has the job-last bit
    last = lsb + top                             # its position (the sequence on top)
    ins = "".join(f", input i{j}_valid, input [{iw - 1 - SEQ}:0] i{j}_free" for j in range(k))
    wires = "".join(f"  wire i{j}_ready; wire [{iw - 1}:0] i{j}_payload = "
                    f"{{n_in{j}, i{j}_free}};\n" for j in range(k))
    conns = "".join(f", .i__{j}__valid(i{j}_valid), .i__{j}__payload(i{j}_payload), "
                    f".i__{j}__ready(i{j}_ready)" for j in range(k))
    regs = "".join(f"  reg [{SEQ - 1}:0] n_in{j} = 0; reg held{j} = 0; "
                   f"reg [{iw - 1}:0] held{j}_payload = 0;\n" for j in range(k))
    upd = "".join(f"""    if (rst) n_in{j} <= 0;
    else if (i{j}_valid && i{j}_ready) n_in{j} <= n_in{j} + 1;
    held{j} <= !rst && i{j}_valid && !i{j}_ready;
    held{j}_payload <= i{j}_payload;
""" for j in range(k))
    assumes = "".join(f"    if (!init && held{j}) assume(i{j}_valid && "
                      f"i{j}_payload == held{j}_payload);\n" for j in range(k))
    low = (lambda j: f"        assert(o_payload[{last - 1}:0] == i{j}_payload[{last - 1}:0]);\n"
           if last > 0 else "")
    per_lane = []
    for j in range(k):
        per_lane.append(f"""      if (i{j}_valid && i{j}_ready) begin
        assert(turn == {j} && o_valid && o_ready);         // only the turn's lane, as o
        assert(o_payload[{w - 1}:{w - SEQ}] == n_in{j});       // its beats in order, once
        assert(o_payload[{w - 1}:{last}] == i{j}_payload[{iw - 1}:{last + 1}]);
{low(j)}      end""")
    sel = " : ".join(f"(turn == {j}) ? i{j}_payload[{last}]" for j in range(k)) + " : 1'b0"
    taken_in = " + ".join(f"(i{j}_valid && i{j}_ready)" for j in range(k))
    return f"""module stream_check(input clk, input rst, input o_ready{ins});
  reg init = 1;
  reg [1:0] turn = 0;
  wire [1:0] turn_probe;                       // the merger's turn (connect -set)
  reg [{SEQ - 1}:0] n_out = 0, n_all = 0;
  reg off = 0;
  reg [{w - 1}:0] off_data = 0;
{regs}{wires}  wire o_valid;
  wire [{w - 1}:0] o_payload;
  stage dut(.clk(clk), .rst(rst), .o__valid(o_valid), .o__payload(o_payload),
            .o__ready(o_ready){conns});
  wire job_last = {sel};
  wire [1:0] taken_in = {taken_in};
  always @(posedge clk) begin
    init <= 0;
{upd}    if (rst) begin turn <= 0; n_out <= 0; n_all <= 0; end
    else begin
      if (o_valid && o_ready) n_out <= n_out + 1;
      n_all <= n_all + taken_in;
      if (o_valid && o_ready && job_last) turn <= (turn == {k - 1}) ? 0 : turn + 1;
    end
    off <= !rst && o_valid && !o_ready;
    off_data <= o_payload;
  end
  always @* begin
    if (init) assume(rst);
{assumes}    if (!init && !rst) begin
      assert(n_all == n_out);                  // beats in = beats out, none held
      assert(turn_probe == turn);
      assert(taken_in == (o_valid && o_ready));
{chr(10).join(per_lane)}
      if (off) assert(o_valid && o_payload == off_data);    // the stream rule
      cover(turn == {k - 1} && o_valid && o_ready && job_last);
    end
  end
endmodule
"""


def _stream_env(iw: int, ow: int, withdrawn: str = "") -> tuple[str, str]:
    """The harness text of a stage with one input stream ``i`` and one output ``o``: the
    registers (a beat offered on ``i`` and not taken; one offered on ``o`` and not taken),
    and the text that ends the harness's clocked block and opens its checks, with the
    stream rule assumed on ``i`` and asserted on ``o`` (where ``withdrawn``, an expression
    of the harness, is true, the beat may instead be withdrawn, its payload kept)."""
    rule = ("o_valid && o_payload == off_data" if not withdrawn else
            f"(o_valid || {withdrawn}) && o_payload == off_data")
    regs = f"""  reg i_held = 0, off = 0;
  reg [{iw - 1}:0] i_held_payload = 0;
  reg [{ow - 1}:0] off_data = 0;
"""
    checks = f"""    i_held <= !rst && i_valid && !i_ready;
    i_held_payload <= i_payload;
    off <= !rst && o_valid && !o_ready;
    off_data <= o_payload;
  end
  always @* begin
    if (init) assume(rst);
    if (!init && i_held) assume(i_valid && i_payload == i_held_payload);   // the stream rule
    if (!init && !rst) begin
      if (off) assert({rule});    // the stream rule
"""
    return regs, checks


def _framing_check(info: dict) -> str:
    iw, ow, mk = info["iw"], info["ow"], info["marker"]
    ts, to, last, empty = info["t_in"], info["t_out"], info["last"], info["empty"]
    seq_in, seq_out = f"[{ts + SEQ - 1}:{ts}]", f"[{to + SEQ - 1}:{to}]"
    # the beat the last result taken makes, last and empty clear: what the hold register keeps
    beat = "".join(f"  assign want[{o + w - 1}:{o}] = res_payload[{i + w - 1}:{i}];\n"
                   for o, i, w in info["copied"])
    ends = f"{ow}'h{(1 << last) | (1 << empty):x}"       # last and empty set
    regs, checks = _stream_env(iw, ow)
    return f"""module stream_check(input clk, input rst, input i_valid, input o_ready,
                    input [{iw - 1}:0] i_free);
  reg init = 1;
  // results taken, non-empty beats out; a result since the last marker (or reset)
  reg [{SEQ - 1}:0] n_res = 0, n_out = 0;
  wire [{SEQ - 1}:0] n_prev = n_res - 1;
  reg pending = 0;
  reg [{iw - 1}:0] res_payload = 0;          // the last result taken
  wire held_v_probe;                         // the hold register's valid (connect -set)
  wire [{ow - 1}:0] held_probe;              // and its beat
  wire marker = i_free[{mk}];
  // a result carries its number in t's low bits; a marker's payload is all free
  wire [{iw - 1}:0] i_payload = {{i_free[{iw - 1}:{ts + SEQ}],
      marker ? i_free{seq_in} : n_res, i_free[{ts - 1}:0]}};
  wire i_ready, o_valid;
  wire [{ow - 1}:0] o_payload, want;
{beat}  assign want[{last}] = 0;
  assign want[{empty}] = 0;
  stage dut(.clk(clk), .rst(rst), .i__valid(i_valid), .i__payload(i_payload),
            .i__ready(i_ready), .o__valid(o_valid), .o__payload(o_payload),
            .o__ready(o_ready));
  wire i_take = i_valid && i_ready, o_take = o_valid && o_ready;
  wire o_last = o_payload[{last}], o_empty = o_payload[{empty}];
{regs}  always @(posedge clk) begin
    init <= 0;
    if (rst) begin n_res <= 0; n_out <= 0; pending <= 0; end
    else begin
      if (i_take && !marker) begin n_res <= n_res + 1; res_payload <= i_payload; end
      if (i_take) pending <= !marker;
      if (o_take && !o_empty) n_out <= n_out + 1;
    end
{checks}      assert(n_res == n_out + held_v_probe);   // results in = non-empty beats out + held
      assert(held_v_probe == pending);         // held: the run's latest result
      if (pending) assert(held_probe == want && res_payload{seq_in} == n_prev);
      assert(i_ready == o_ready);
      // a beat leaves with each take, but for a run's first result
      assert(o_take == (i_take && (pending || marker)));
      if (o_take) begin
        assert(o_last == marker);              // last: the next one in is a marker
        assert(o_empty == (marker && !pending));   // empty: a run without a result
        if (o_empty) assert(o_payload == {ends});    // and every other field 0
        if (!o_empty) assert(o_payload{seq_out} == n_out);   // in order, once each
        if (!o_empty) assert((o_payload & ~{ends}) == want);   // its result's fields
      end
      cover(o_take && o_empty);
      cover(o_take && o_last && !o_empty && n_out == 2);    // the third result, last
      cover(off && o_take && !o_empty);        // a beat held under !o.ready, then taken
    end
  end
endmodule
"""


def _selector_check(info: dict) -> str:
    rows, cols, cb, sb = info["rows"], info["cols"], info["count"], info["sphere_bits"]
    n, iw, ow, at, o = rows * cols, info["iw"], info["ow"], info["i"], info["o"]
    pb = n.bit_length()                          # positions 0 .. n
    rw = rows + cols + sb + 2 + cb               # a sphere's record
    all_rows, all_cols = f"{rows}'h{(1 << rows) - 1:x}", f"{cols}'h{(1 << cols) - 1:x}"
    job = {name: f"o_payload[{off + w - 1}:{off}]" for name, (off, w) in o.items()}
    # the iterator's register as selector.py lays it out, low bits first (probed)
    it_at = {}
    for name, w in (("busy", 1), ("rows", rows), ("colmask", cols), ("cols", cols),
                    ("sid", sb), ("bank", 1), ("marker", 1)):
        it_at[name] = (sum(v[1] for v in it_at.values()), w)
    it_w = sum(w for _, w in it_at.values())
    it_wires = "".join(f"  wire [{w - 1}:0] it_{name} = it_probe[{off + w - 1}:{off}];\n"
                       for name, (off, w) in it_at.items())

    def record(r):         # the fields of record register r, as wires r_rows, r_cols, ...
        offs, out = 0, []
        for name, w in (("rows", rows), ("cols", cols), ("sid", sb), ("bank", 1),
                        ("marker", 1), ("ntris", cb)):
            out.append(f"  wire [{w - 1}:0] {r}_{name} = {r}[{offs + w - 1}:{offs}];\n")
            offs += w
        out.append(f"  wire [{cb - 1}:0] {r}_count = counts >> ({r}_sid * {cb});\n")
        return "".join(out)

    def search(name, r, start):
        """The next ray of record r at or after position start (rows ascending, then
        columns): {name}_found, _q; _more: a ray of r's masks follows it; _rows, _cols: the
        masks of the rows and columns from its own on."""
        lines = [f"  reg {name}_found, {name}_more;\n  reg [{pb - 1}:0] {name}_q;\n"
                 f"  reg [{rows - 1}:0] {name}_rows;\n  reg [{cols - 1}:0] {name}_cols;\n"
                 f"  always @* begin\n    {name}_found = 0; {name}_more = 0; {name}_q = 0;\n"
                 f"    {name}_rows = 0; {name}_cols = 0;\n"]
        for k in reversed(range(n)):
            i, j = divmod(k, cols)
            lines.append(
                f"    if ({start} <= {k} && {r}_rows[{i}] && {r}_cols[{j}]) begin "
                f"{name}_more = {name}_found; {name}_found = 1; {name}_q = {k};\n"
                f"      {name}_rows = {rows}'h{((1 << rows) - 1) & ~((1 << i) - 1):x}; "
                f"{name}_cols = {cols}'h{((1 << cols) - 1) & ~((1 << j) - 1):x}; end\n")
        return "".join(lines) + "  end\n"

    def holds(r, at):      # the iterator holds record r from search at's ray on
        return (f"it_busy && it_sid == {r}_sid && it_bank == {r}_bank && it_marker == "
                f"{r}_marker && count_data == {r}_ntris\n"
                f"          && ({r}_marker || ({at}_found && it_colmask == {r}_cols\n"
                f"              && it_rows == ({r}_rows & {at}_rows) "
                f"&& it_cols == ({r}_cols & {at}_cols)))")

    def sane(r):           # a record in the queue: a marker, or a sphere with a ray
        return (f"({r}_marker || ({r}_rows != 0 && {r}_cols != 0 && {r}_ntris != 0 "
                f"&& {r}_ntris == {r}_count))")

    records = record("q0") + record("q1")
    # with the early-out, a job offered under !o.ready is withdrawn when its ray is reported
    # blocked (harmless behind the job FIFO, which writes on valid and ready)
    regs, checks = _stream_env(iw, ow, "dropped" if info["reduce"] else "")
    if info["reduce"]:     # the reducer's report: any rays, any run number, in every cycle
        ports = f", input [{n - 1}:0] blocked, input [{SEQ - 1}:0] blocked_seq"
        early = f"""  // the report as the selector takes it, a cycle late; runs whose marker left
  reg [{n - 1}:0] blk = 0;
  reg [{SEQ - 1}:0] blk_seq = 0, seq = 0;
  wire [{SEQ - 1}:0] seq_probe;                  // the selector's run number (connect -set)
  wire h_blocked = blk_seq == seq && blk[h_q];
"""
        tie = ", .blocked(blocked), .blocked_seq(blocked_seq)"
        count = """    blk <= rst ? 0 : blocked;
    blk_seq <= rst ? 0 : blocked_seq;
    if (rst) seq <= 0;
    else if (o_take && q0_marker) seq <= seq + 1;
"""
        more = """      assert(seq_probe == seq);
      cover(dropped);
      // a job of a ray reported blocked in another run's report
      cover(o_take && !q0_marker && blk[h_q] && blk_seq != seq);
"""
    else:
        ports = tie = count = more = ""
        early = "  wire h_blocked = 0;\n"
    searches = (search("h", "q0", "p") + f"  wire [{pb - 1}:0] after = h_q + 1;\n"
                + search("nx", "q0", "after") + search("q1s", "q1", "0"))
    return f"""module stream_check(input clk, input rst, input i_valid,
                    input [{iw - 1}:0] i_payload, input o_ready{ports});
  reg init = 1;
  // the memories' words the selector reads: any, fixed for the check
  (* anyconst *) reg [{cb * info["spheres"] - 1}:0] counts;    // triangles per sphere
  (* anyconst *) reg [{2 * n - 1}:0] enables;    // the rays' enables, two banks
  wire count_en, enable_en;
  wire [{sb - 1}:0] count_addr;
  wire [{(2 * n - 1).bit_length() - 1}:0] enable_addr;
  reg [{cb - 1}:0] count_data;
  reg enable_data;
  always @(posedge clk) begin               // read ports: the word addressed at the last en
    if (count_en) count_data <= counts >> (count_addr * {cb});
    if (enable_en) enable_data <= enables >> enable_addr;
  end
  wire i_ready, o_valid;
  wire [{ow - 1}:0] o_payload;
  wire [{cb - 1}:0] skipped;
  stage dut(.clk(clk), .rst(rst), .i__valid(i_valid), .i__payload(i_payload),
            .i__ready(i_ready), .o__valid(o_valid), .o__payload(o_payload),
            .o__ready(o_ready), .skipped(skipped),
            .count__addr(count_addr), .count__en(count_en), .count__data(count_data),
            .enable__addr(enable_addr), .enable__en(enable_en), .enable__data(enable_data)
            {tie});
  wire e_v_probe;                            // the enable lookup's valid (connect -set)
  wire [{it_w - 1}:0] it_probe;                  // the iterator's register
{it_wires}  wire it_live = it_busy && (it_marker || (it_rows != 0 && it_cols != 0
                                          && count_data != 0));
  // a sphere taken: its record {{ntris, marker, bank, sphere, cols, rows}}
  wire i_keep = i_payload[{at["keep_all"]}], i_marker = i_payload[{at["marker"]}];
  wire i_bank = i_payload[{at["bank"]}];
  wire [{sb - 1}:0] i_sphere = i_payload[{at["sphere"] + sb - 1}:{at["sphere"]}];
  wire [{rows - 1}:0] i_rows = i_keep ? {all_rows}
      : i_payload[{at["row_mask"] + rows - 1}:{at["row_mask"]}];
  wire [{cols - 1}:0] i_cols = i_keep ? {all_cols}
      : i_payload[{at["col_mask"] + cols - 1}:{at["col_mask"]}];
  wire [{cb - 1}:0] i_ntris = counts >> (i_sphere * {cb});
  wire [{rw - 1}:0] rec = {{i_ntris, i_marker, i_bank, i_sphere, i_cols, i_rows}};
  wire i_take = i_valid && i_ready;
  // the spheres whose jobs and skips are still to come, in order (q0 the head; p: its
  // next position); a sphere without a ray (none in its masks, or no triangle) has none
  reg [{rw - 1}:0] q0 = 0, q1 = 0, q2 = 0;
  reg [1:0] qn = 0;
  reg [{pb - 1}:0] p = 0;
  wire push = i_take && (i_marker || (i_rows != 0 && i_cols != 0 && i_ntris != 0));
{records}  // the head's next ray; the one after it; q1's first
{searches}  wire h_enabled = enables >> (q0_bank * {n} + h_q);
  wire job_enabled = enables >> ({job["bank"]} * {n} + {job["ray"]});
  wire o_take = o_valid && o_ready, skip = skipped != 0;
{early}  // an enabled ray blocked in its run: dropped, not skipped
  wire dropped = e_v_probe && !q0_marker && h_enabled && h_blocked;
  wire served = o_take || skip || dropped;   // the head's next ray (or marker) done
  wire pop = served && (q0_marker || !h_more);
  wire [1:0] base = qn - pop;
  reg [{rw - 1}:0] n0, n1, n2;
  always @* begin
    n0 = pop ? q1 : q0; n1 = pop ? q2 : q1; n2 = q2;
    if (push && base == 0) n0 = rec;
    if (push && base == 1) n1 = rec;
    if (push && base == 2) n2 = rec;
  end
{regs}  reg [1:0] starve = 0;                      // cycles of o.ready a queued ray waited
  always @(posedge clk) begin
    init <= 0;
    q0 <= n0; q1 <= n1; q2 <= n2;
    if (rst) begin qn <= 0; p <= 0; starve <= 0; end
    else begin
      qn <= base + push;
      if (served) p <= pop ? 0 : after;
      if (served || qn == 0) starve <= 0;
      else if (o_ready) starve <= starve + 1;
    end
{count}{checks}      assert(!(o_take && skip));             // one ray a cycle
      if (served) assert(qn != 0);           // nothing that was not sent
      if (o_take) begin                      // the head's next job, once
        assert({job["marker"]} == q0_marker && {job["sid"]} == q0_sid);
        assert({job["bank"]} == q0_bank);
        if (!q0_marker) assert(h_found && h_enabled && !h_blocked && {job["ray"]} == h_q
                               && {job["ntris"]} == q0_ntris);
      end
      // ... or its next ray skipped, disabled
      if (skip) assert(!q0_marker && h_found && !h_enabled && skipped == q0_ntris);
      // a job is offered for a marker, or an enabled ray not blocked in its run
      assert(o_valid == (e_v_probe && (q0_marker || (h_enabled && !h_blocked))));
      assert(starve <= 1);                   // a ray waits at most 1 cycle of o.ready
      // what the selector holds is what is still to come (for the induction)
      assert(qn <= 2 && p <= {n} && (qn != 0 || p == 0));
      if (qn >= 1) assert({sane("q0")} && (q0_marker || h_found));
      if (qn >= 2) assert({sane("q1")});
      if (e_v_probe) begin                   // the enable lookup holds the head's next
        assert(qn >= 1 && {job["marker"]} == q0_marker && {job["sid"]} == q0_sid
               && {job["bank"]} == q0_bank
               && (q0_marker || ({job["ray"]} == h_q && {job["ntris"]} == q0_ntris)));
        assert(enable_data == job_enabled);
        if (!q0_marker && h_more) assert(qn == 1 && {holds("q0", "nx")});
        else if (qn == 2) assert({holds("q1", "q1s")});
        else assert(!it_live);
      end else begin
        assert(qn <= 1 && starve == 0);
        if (qn == 1) assert({holds("q0", "h")});
        else assert(!it_live);
      end
      cover(skip);
      cover(o_take && q0_marker);
      cover(off && o_take);                  // a job held under !o.ready, then taken
      // the last of a sphere's rays, all of them in its masks
      cover(pop && !q0_marker && q0_rows == {all_rows} && q0_cols == {all_cols});
{more}    end
  end
endmodule
"""


def _word(vec: str, index: str, width: int, count: int) -> str:
    """Word ``index`` of the ``count`` words of ``width`` bits in ``vec``, as a chain of
    multiplexers (cheaper for the solver than a shift by ``index * width``)."""
    out = f"{vec}[{count * width - 1}:{(count - 1) * width}]"
    for j in reversed(range(count - 1)):
        out = f"({index} == {j}) ? {vec}[{(j + 1) * width - 1}:{j * width}] : {out}"
    return f"({out})"


def _memories(stage: str, mems) -> str:
    """The harness text of the read ports of ``stage``, answered as the memories do (the
    word addressed at the last ``en``) from contents that are free but fixed for the check:
    ``mems`` holds ``(port, contents, word bits, words, address bits, what)``."""
    decl = "".join(f"  (* anyconst *) reg [{w * n - 1}:0] {mem};    // {what}\n"
                   for _, mem, w, n, _, what in mems)
    wires = "".join(f"  wire {port}_en;\n  wire [{ab - 1}:0] {port}_addr;\n"
                    f"  reg [{w - 1}:0] {port}_data;\n" for port, _, w, _, ab, _ in mems)
    reads = "".join(f"    if ({port}_en) {port}_data <= {_word(mem, f'{port}_addr', w, n)};\n"
                    for port, mem, w, n, _, _ in mems)
    return (f"  // the memories the {stage} reads: any contents, fixed for the check\n{decl}"
            f"{wires}  always @(posedge clk) begin       // the word addressed at the last en\n"
            f"{reads}  end\n")


def _fetch_check(info: dict) -> str:
    d, tps, nr, tb, rb = info["depth"], info["tps"], info["rays"], info["tb"], info["rb"]
    iw, ow, rw, tw, ab, regs_w = (info["iw"], info["ow"], info["rw"], info["tw"],
                                  info["abits"], info["regs"])
    kb, cw, nb = regs_w["k"], regs_w["credit"], 3       # nb: job numbers mod 8
    cb = info["job"]["ntris"][1]

    def job(name, n):      # job number n, as wires {name}_ray, _sid, ...
        out = [f"  wire [{iw - 1}:0] {name} = slots >> ({n} * {iw});\n"]
        for f, (off, w) in info["job"].items():
            out.append(f"  wire [{w - 1}:0] {name}_{f} = {name}[{off + w - 1}:{off}];\n")
        return "".join(out)

    # the pairs in flight, oldest first: the chain of positions from the next pair out
    stages = ("o_valid", "g3_probe[0]", "g2_probe[0]", "g1_probe[0]")
    chain = [f"  wire [{nb - 1}:0] p0_n = n_done;\n  wire [{kb - 1}:0] p0_k = kout;\n"]
    for i, v in enumerate(stages):
        chain.append(job(f"p{i}_j", f"p{i}_n") + f"""\
  wire p{i}_last = p{i}_j_marker || p{i}_k == p{i}_j_ntris - 1;
  wire [{nb - 1}:0] p{i + 1}_n = ({v} && p{i}_last) ? p{i}_n + 1 : p{i}_n;
  wire [{kb - 1}:0] p{i + 1}_k = {v} ? (p{i}_last ? 0 : p{i}_k + 1) : p{i}_k;
""")
    want = [f"  assign want[{info['ray_id'] + rb + 1}:{info['ray_id']}] = "
            f"{{p0_last, p0_j_marker, p0_j_ray}};\n",
            f"  assign want[{info['tri_id'] + tb - 1}:{info['tri_id']}] = h_tri;\n"]
    want += [f"  assign want[{o + w - 1}:{o}] = h_rayw[{m + w - 1}:{m}];\n"
             for o, m, w in info["ray"]]
    want += [f"  assign want[{o + w - 1}:{o}] = h_triw[{m + w - 1}:{m}];\n"
             for o, m, w in info["tri"]]
    regs, checks = _stream_env(iw, ow)
    nt, mk = info["job"]["ntris"][0], info["job"]["marker"][0]
    i_ntris = f"i_payload[{nt + cb - 1}:{nt}]"
    sane = "".join(   # every job queued is as assumed when taken
        f"      if ({nb}'d{j} - n_done < queued) assert(slots[{j * iw + mk}] || "
        f"(slots[{j * iw + nt + cb - 1}:{j * iw + nt}] >= 1 && "
        f"slots[{j * iw + nt + cb - 1}:{j * iw + nt}] <= {tps}));\n" for j in range(8))
    probes = "".join(f"  wire [{regs_w[r] - 1}:0] {r}_probe;\n" for r in ("k", "credit", "g1",
                                                                           "g2", "g3"))
    mems = (("tlist", "tlist", tb, info["spheres"] * tps, ab["tlist"],
             f"sphere s's k-th triangle at s * {tps} + k"),
            ("ray", "rays", rw, 2 * nr, ab["ray"], "Ray Memory, two banks"),
            ("tri", "tris", tw, info["tris"], ab["tri"], "Triangle Memory"))
    return f"""module stream_check(input clk, input rst, input i_valid,
                    input [{iw - 1}:0] i_payload, input r_take);
  reg init = 1;
{_memories("fetch", mems)}\
  // the pair FIFO behind o, as its writer's credits see it: lvl words; the reader takes one
  // when there is one (r_take), and each read gives the fetch an entry back (freed)
  reg [2:0] lvl = 0;
  reg fr = 0;                                // a read last cycle: the credit on its way
  wire o_ready = lvl != {d};
  wire i_ready, o_valid, overflow;
  wire [{ow - 1}:0] o_payload, want;
  stage dut(.clk(clk), .rst(rst), .i__valid(i_valid), .i__payload(i_payload),
            .i__ready(i_ready), .o__valid(o_valid), .o__payload(o_payload),
            .o__ready(o_ready), .freed(r_take), .overflow(overflow),
            .tlist__addr(tlist_addr), .tlist__en(tlist_en), .tlist__data(tlist_data),
            .ray__addr(ray_addr), .ray__en(ray_en), .ray__data(ray_data),
            .tri__addr(tri_addr), .tri__en(tri_en), .tri__data(tri_data));
  // the fetch's registers (connect -set): the job it expands, its next pair, its credits,
  // and the pipeline (bit 0 of g1 .. g3: valid; g4's is o.valid)
  wire busy_probe, last_probe, has_credit_probe;
  wire [{iw - 1}:0] job_probe;
{probes}  // jobs taken (job n kept at n mod 8); jobs whose pairs all left; pairs of job n_done out
  reg [{nb - 1}:0] n_in = 0, n_done = 0;
  reg [{kb - 1}:0] kout = 0;
  reg [{8 * iw - 1}:0] slots = 0;
  wire [{nb - 1}:0] queued = n_in - n_done;
{"".join(chain)}  // the next pair out, pair kout of job n_done: its ray, its kout-th triangle,
  // their words
  wire [{tb - 1}:0] h_tri = {_word("tlist", f"p0_j_sid * {tps} + p0_k", tb, info["spheres"] * tps)};
  wire [{rw - 1}:0] h_rayw = {_word("rays", f"p0_j_bank * {nr} + p0_j_ray", rw, 2 * nr)};
  wire [{tw - 1}:0] h_triw = {_word("tris", "h_tri", tw, info["tris"])};
{"".join(want)}  // where the fetch is: the next pair it starts
  wire [{nb - 1}:0] ip_n = busy_probe ? n_in - 1 : n_in;
  wire [{kb - 1}:0] ip_k = busy_probe ? k_probe : 0;
{job("cur", "ip_n")}  wire [{cw - 1}:0] in_flight = {" + ".join(stages)};
  reg [2:0] m_out = 0;                       // pairs written (mod 8)
  reg [2:0] starve = 0;                      // cycles a job waited, FIFO behind empty
{regs}  always @(posedge clk) begin
    init <= 0;
    fr <= !rst && r_take;
    if (rst) begin n_in <= 0; n_done <= 0; kout <= 0; lvl <= 0; m_out <= 0; starve <= 0; end
    else begin
      if (i_valid && i_ready) begin
        slots[n_in * {iw} +: {iw}] <= i_payload;
        n_in <= n_in + 1;
      end
      n_done <= p1_n;
      kout <= p1_k;
      lvl <= lvl + o_valid - r_take;
      m_out <= m_out + o_valid;
      starve <= (queued != 0 && lvl == 0 && !o_valid) ? starve + 1 : 0;
    end
{checks}      // a job is a marker, or has 1 .. {tps} triangles (the selector sends none without;
      // the host's counts are at most tris_per_sphere)
      if (i_valid && !i_payload[{mk}]) assume({i_ntris} >= 1 && {i_ntris} <= {tps});
      assume(!r_take || lvl != 0);           // the reader takes a word that is there
      if (o_valid) begin
        assert(o_ready);                     // never written without a free entry
        assert(queued != 0);                 // nothing that was not taken
        assert(o_payload == want);           // the next pair, in order, its words fetched
      end
      assert(!overflow);
      assert(starve <= 4);                   // a job's first pair within 4 cycles of room
      // the credits: every entry is free for the fetch, claimed by a pair in flight, full,
      // or on its way back
      assert(credit_probe + in_flight + lvl + fr == {d} && lvl <= {d});
      // the registered tests: a credit is held; the job's next pair is its last
      assert(has_credit_probe == (credit_probe != 0));
      if (busy_probe) assert(last_probe == (cur_marker || ip_k == cur_ntris - 1));
      // the job the fetch holds is the last taken, at its next pair; the pairs in flight are
      // those from the next out to it
      assert(queued <= 5);
{sane}      if (busy_probe) assert(queued != 0 && job_probe == cur
                             && (cur_marker ? ip_k == 0 : ip_k < cur_ntris));
      if (queued != 0) assert(p0_j_marker ? kout == 0 : kout < p0_j_ntris);
      else assert(kout == 0);
      assert(p4_n == ip_n && p4_k == ip_k);
      cover(o_valid && p0_last && !p0_j_marker && kout == 1);   // a job's two pairs
      cover(o_valid && p0_j_marker);         // a marker's pair
      cover(o_valid && lvl == {d - 1});          // the write that spends the last credit
      cover(o_valid && m_out == {d});            // a pair on a credit given back
    end
  end
endmodule
"""


def _feeder_check(info: dict) -> str:
    d, ns, n, sb, iw, ow = (info["depth"], info["spheres"], info["planes"], info["sb"],
                            info["iw"], info["ow"])
    sw, pw, ab, rg, tag = info["sw"], info["pw"], info["abits"], info["regs"], info["tag"]
    c_at, c_w = info["c"]
    r_at, r_w = info["r"]

    def fields(name, vec):          # the fields of a run command, as wires {name}_first, ...
        return "".join(f"  wire [{w - 1}:0] {name}_{f} = {vec}[{off + w - 1}:{off}];\n"
                       for f, (off, w) in info["cmd"].items())

    probes = "".join(f"  wire [{rg[r] - 1}:0] {r}_probe;\n" for r in ("credit", "f1", "fs",
                                                                       "f2", "f3"))
    regs, checks = _stream_env(iw, ow)
    cw = info["cmd"]["count"][1]
    mems = (("rlist", "rlist", sb, 2 * ns, ab["rlist"], "the run lists, two banks"),
            ("sphere", "spheres", sw, ns, ab["sphere"], "Sphere Memory"),
            ("plane", "planes", pw, 2 * n, ab["plane"], "Plane Memory, two banks"))
    return f"""module stream_check(input clk, input rst, input i_valid,
                    input [{iw - 1}:0] i_payload, input o_ready, input [1:0] plane_written,
                    input retired);
  reg init = 1;
{_memories("feeder", mems)}\
  wire i_ready, o_valid, pw_en, spheres_out;
  wire [{ow - 1}:0] o_payload;
  wire [{info["pw_addr"] - 1}:0] pw_addr;
  wire [{pw - 1}:0] pw_data;
  stage dut(.clk(clk), .rst(rst), .cmd__valid(i_valid), .cmd__payload(i_payload),
            .cmd__ready(i_ready), .o__valid(o_valid), .o__payload(o_payload),
            .o__ready(o_ready), .plane_written(plane_written), .retired(retired),
            .spheres(spheres_out), .pw_en(pw_en), .pw_addr(pw_addr), .pw_data(pw_data),
            .rlist__addr(rlist_addr), .rlist__en(rlist_en), .rlist__data(rlist_data),
            .sphere__addr(sphere_addr), .sphere__en(sphere_en), .sphere__data(sphere_data),
            .plane__addr(plane_addr), .plane__en(plane_en), .plane__data(plane_data));
  // the feeder's credits, the credit on its way back, its pipeline (bit 0: valid) and its
  // sphere FIFO's inner level (connect -set)
  wire freed_probe;
{probes}  wire [2:0] fifo_level_probe;
  // runs taken (run n at n mod 8, more than fit in the cycles checked); runs whose marker
  // left; items of run n_done out
  reg [2:0] n_in = 0, n_done = 0;
  reg [{cw - 1}:0] pos = 0;
  reg [{8 * iw - 1}:0] slots = 0;
  wire [2:0] n_last = n_in - 1;
  wire [{iw - 1}:0] head = slots >> (n_done * {iw}), last = slots >> (n_last * {iw});
{fields("h", "head")}{fields("last", "last")}\
  // the array behind o: items in it (taken from o, not yet retired by the selector), the
  // bank of its planes and how many of them the current load wrote
  reg [3:0] in_array = 0;
  reg arr_bank = 0;
  reg [2:0] arr_n = 0;
  // what the head run sends next: a sphere (direct or from its bank's run list), or its marker
  wire marker = pos == h_count;
  wire [{sb - 1}:0] direct = h_first + pos;
  wire [{sb - 1}:0] listed = {_word("rlist", f"h_bank * {ns} + direct", sb, 2 * ns)};
  wire [{sb - 1}:0] sid = h_indirect ? listed : direct;
  wire [{sw - 1}:0] word = {_word("spheres", "sid", sw, ns)};
  wire [{pw - 1}:0] plane_word = {_word("planes", f"last_bank * {n} + pw_addr", pw, 2 * n)};
  wire o_take = o_valid && o_ready;
  reg [4:0] n_items = 0;                    // items out (for the covers)
{regs}  always @(posedge clk) begin
    init <= 0;
    if (rst) begin
      n_in <= 0; n_done <= 0; pos <= 0; in_array <= 0; arr_n <= 0; n_items <= 0;
    end else begin
      if (i_valid && i_ready) begin
        slots[n_in * {iw} +: {iw}] <= i_payload;
        n_in <= n_in + 1;
      end
      if (o_take) begin
        pos <= marker ? 0 : pos + 1;
        if (marker) n_done <= n_done + 1;
        n_items <= n_items + 1;
      end
      in_array <= in_array + o_take - retired;
      if (pw_en) begin
        arr_bank <= last_bank;
        arr_n <= pw_addr == 0 ? 1 : arr_n + 1;
      end
    end
{checks}      // a run stays inside the run list and the Sphere Memory
      if (i_valid) assume(i_payload[{info["cmd"]["first"][0] + sb - 1}:{info["cmd"]["first"][0]}]
                          + i_payload[{info["cmd"]["count"][0] + cw - 1}:{info["cmd"]["count"][0]}]
                          <= {ns});
      assume(!retired || in_array != 0);     // the selector takes an item that is there
      if (o_take) begin
        assert(n_done != n_in);              // nothing that was not asked for
        // the head run's next sphere, then its marker, with the run's tag bits
        assert(o_payload[{tag["marker"]}] == marker && o_payload[{tag["bank"]}] == h_bank
               && o_payload[{tag["keep_all"]}] == h_keep_all);
        if (!marker) assert(o_payload[{tag["sphere"] + sb - 1}:{tag["sphere"]}] == sid
                            && o_payload[{c_at + c_w - 1}:{c_at}] == word[{c_w - 1}:0]
                            && o_payload[{r_at + r_w - 1}:{r_at}] == word[{c_w + r_w - 1}:{c_w}]);
        // ... while the array holds all the planes of the run's bank
        assert(arr_n == {n} && arr_bank == h_bank);
      end
      // planes are written only while no item is on its way to or through the array (every
      // run before the last has left, the last has sent nothing), in order, the words of the
      // last run's bank
      if (pw_en) assert(n_done == n_last && pos == 0 && in_array == 0
                        && (pw_addr == 0 || pw_addr == arr_n) && pw_addr < {n}
                        && pw_data == plane_word);
      // the credits: every entry of the sphere FIFO is free for the feeder, claimed by an
      // item in its pipeline, full, or on its way back
      assert(credit_probe + f1_probe[0] + fs_probe[0] + f2_probe[0] + f3_probe[0]
             + fifo_level_probe + o_valid + freed_probe == {d});
      cover(o_take && !marker && h_indirect);   // a sphere from a run list
      cover(o_take && marker && h_count == 2);   // the marker of a run of two spheres
      cover(off && o_take);                  // an item held under !o.ready, then taken
      cover(pw_en && n_items != 0);          // a load after an item went through the array
    end
  end
endmodule
"""


def _reducer_harness_head(info: dict) -> str:
    """The reducer harnesses' ports, the reducer (``dut``) and its probed ``valid`` bits."""
    n, iw, ow = info["rays"], info["iw"], info["ow"]
    return f"""module stream_check(input clk, input rst, input i_valid,
                    input [{iw - 1}:0] i_payload, input o_ready, input wr_en,
                    input [31:0] wr_addr, input [31:0] wr_data, input rb_valid,
                    input rb_payload);
  reg init = 1;
  wire i_ready, o_valid, rb_ready;
  wire [{ow - 1}:0] o_payload;
  wire [{n - 1}:0] blocked;
  wire [{SEQ - 1}:0] seq;
  stage dut(.clk(clk), .rst(rst), .i__valid(i_valid), .i__payload(i_payload),
            .i__ready(i_ready), .o__valid(o_valid), .o__payload(o_payload),
            .o__ready(o_ready), .wr_en(wr_en), .wr_addr(wr_addr), .wr_data(wr_data),
            .run_bank__valid(rb_valid), .run_bank__payload(rb_payload),
            .run_bank__ready(rb_ready), .blocked(blocked), .seq(seq));
  wire [{n - 1}:0] valid_probe;              // the rays with an answer (connect -set)
"""


def _reducer_check(info: dict) -> str:
    n, rb, iw, ow, at, ot = (info["rays"], info["rb"], info["iw"], info["ow"], info["i"],
                             info["o"])
    regs, checks = _stream_env(iw, ow)
    return _reducer_harness_head(info) + f"""\
  wire i_take = i_valid && i_ready, o_take = o_valid && o_ready;
  wire i_last = i_payload[{at["last"]}];
  wire i_hit = i_payload[{at["hit"]}] && !i_payload[{at["empty"]}];   // a hit beat
  wire [{rb - 1}:0] i_ray = i_payload[{at["ray_id"] + rb - 1}:{at["ray_id"]}];
  wire o_last = o_payload[{ot["last"]}], o_empty = o_payload[{ot["empty"]}];
  wire [{rb - 1}:0] o_ray = o_payload[{ot["ray_id"] + rb - 1}:{ot["ray_id"]}];
  wire [{n - 1}:0] upto = ({n + 1}'d2 << o_ray) - 1;   // rays 0 .. o_ray
  // runs whose last beat was taken, runs whose last answer left (mod 16); in flight: at
  // most one per pipeline register (6) and the run being sent, whose last beat has left r
  reg [3:0] n_in = 0, n_out = 0;
  wire [3:0] in_flight = n_in - n_out;
  // the rays with a hit beat, per run (run r at r mod 8: a beat is taken only while no run
  // is sent, so with at most 6 runs in flight, and the slot the next run takes is free)
  reg [{8 * n - 1}:0] hits = 0;
  wire [{n - 1}:0] out_hits = hits >> (n_out[2:0] * {n});
  wire [2:0] next_slot = n_in[2:0] + 3'd1;
  reg sent = 0;                              // an answer of run n_out has left ...
  reg [{rb - 1}:0] prev = 0;                 // ... this ray's the latest
  // the run-bank stream: held until taken (assumed, as on i)
  reg rb_held = 0, rb_held_payload = 0;
{regs}  always @(posedge clk) begin
    init <= 0;
    if (rst) begin n_in <= 0; n_out <= 0; hits <= 0; sent <= 0; end
    else begin
      if (i_take && i_hit) hits[n_in[2:0] * {n} + i_ray] <= 1;
      if (i_take && i_last) begin
        n_in <= n_in + 1;
        hits[next_slot * {n} +: {n}] <= 0;
      end
      if (o_take) begin
        sent <= !o_last;
        if (o_last) n_out <= n_out + 1;
        prev <= o_ray;
      end
    end
    rb_held <= !rst && rb_valid && !rb_ready;
    rb_held_payload <= rb_payload;
{checks}      if (rb_held) assume(rb_valid && rb_payload == rb_held_payload);   // the stream rule
      assert(in_flight <= 7);
      if (i_take) assert(in_flight <= 6);
      if (o_valid) begin
        assert(in_flight != 0);              // only for a run whose last beat came in
        if (o_empty) assert(o_last && !sent && valid_probe == 0);   // one empty beat: no answer
        else begin
          assert(!sent || o_ray > prev);     // lowest first: ascending, each ray once
          assert(out_hits[o_ray]);           // a ray with a hit beat in its run
          // the rays still to send: later ones, with hits; last exactly when there is none
          assert((valid_probe & upto) == 0 && (valid_probe & ~out_hits) == 0);
          assert(o_last == (valid_probe == 0));
        end
      end
      cover(o_take && o_last && !o_empty && sent);   // a run's second answer, last
      cover(o_take && o_empty);              // a run without answers
      cover(off && o_take && !o_empty);      // an answer held under !o.ready, then taken
    end
  end
endmodule
"""


def _reducer_certified_check(info: dict) -> str:
    """The certified reducer's output order: every beat taken on ``i`` carries its number
    in ``u`` (assumed; ``u`` is carried, never compared), so a passed-on pair (``outcome``
    2) names the beat it is; its ``hit`` bit is ``outcome == 1`` (assumed, as the
    ray-triangle unit makes it), every other field free. Asserted: the pairs the stage
    passes on in ``r`` (its ``emit``, probed) = those out + the one in the output register
    + the one in the skid register (none lost or doubled); passed-on pairs leave in stream
    order, each once, each one of the beats of the run being reduced (taken, and not after
    that run's ``last``), with that beat's ray and an uncertain or certain-hit outcome, and
    none after an answer of their run; answers (``outcome`` 1) as in ``reducer-send``;
    ``empty`` is outcome 0, after no answer; the stream rule on ``o``."""
    n, rb, iw, ow, uw, at, ot = (info["rays"], info["rb"], info["iw"], info["ow"],
                                 info["uw"], info["i"], info["o"])
    regs, checks = _stream_env(iw, ow)
    nb = 1 << uw                                    # beat numbers (mod 2**uw; < 20 here)
    return _reducer_harness_head(info) + f"""\
  wire emit_probe, en_probe, sk_probe;       // a pair passed on in r; r moves; skid full
  wire i_take = i_valid && i_ready, o_take = o_valid && o_ready;
  wire i_last = i_payload[{at["last"]}];
  wire i_hit = i_payload[{at["hit"]}] && !i_payload[{at["empty"]}];
  wire [1:0] i_outcome = i_payload[{at["outcome"] + 1}:{at["outcome"]}];
  wire [{rb - 1}:0] i_ray = i_payload[{at["ray_id"] + rb - 1}:{at["ray_id"]}];
  wire [{uw - 1}:0] i_u = i_payload[{at["u"] + uw - 1}:{at["u"]}];
  wire o_last = o_payload[{ot["last"]}], o_empty = o_payload[{ot["empty"]}];
  wire [1:0] o_outcome = o_payload[{ot["outcome"] + 1}:{ot["outcome"]}];
  wire o_unc = o_outcome == 2'd2;
  wire [{rb - 1}:0] o_ray = o_payload[{ot["ray_id"] + rb - 1}:{ot["ray_id"]}];
  wire [{uw - 1}:0] o_u = o_payload[{ot["u"] + uw - 1}:{ot["u"]}];
  wire [{n - 1}:0] upto = ({n + 1}'d2 << o_ray) - 1;   // rays 0 .. o_ray
  reg [3:0] n_in = 0, n_out = 0;             // runs whose last beat came in / left
  wire [3:0] in_flight = n_in - n_out;
  reg [{8 * n - 1}:0] hits = 0;              // per run slot, the rays with a hit beat
  wire [{n - 1}:0] out_hits = hits >> (n_out[2:0] * {n});
  wire [2:0] next_slot = n_in[2:0] + 3'd1;
  reg sent = 0;                              // an answer of run n_out has left ...
  reg [{rb - 1}:0] prev = 0;                 // ... this ray's the latest
  reg [{uw - 1}:0] n_beats = 0;              // beats taken: the next one's number
  reg [{uw - 1}:0] n_pass = 0, n_unc = 0;    // pairs passed on in r; passed-on pairs out
  reg [{uw - 1}:0] u_next = 0;               // passed-on pairs leave from this number up
  reg [{8 * uw - 1}:0] first = 0;            // per run slot, the number of its first beat
  wire [{uw - 1}:0] run_first = first >> (n_out[2:0] * {uw});
  wire [{uw - 1}:0] run_end = first >> ((n_out[2:0] + 3'd1) * {uw});  // past its last
  reg [{nb * rb - 1}:0] ray_of = 0;          // per beat number, its ray
  reg [{nb * 2 - 1}:0] outcome_of = 0;       // ... and its outcome
  wire [{rb - 1}:0] o_beat_ray = ray_of >> (o_u * {rb});
  wire [1:0] o_beat_outcome = outcome_of >> (o_u * 2);
  reg rb_held = 0, rb_held_payload = 0;
{regs}  always @(posedge clk) begin
    init <= 0;
    if (rst) begin
      n_in <= 0; n_out <= 0; hits <= 0; sent <= 0; n_beats <= 0; u_next <= 0; first <= 0;
      n_pass <= 0; n_unc <= 0;
    end else begin
      if (emit_probe && en_probe) n_pass <= n_pass + 1;
      if (o_take && o_unc) n_unc <= n_unc + 1;
      if (i_take) begin
        n_beats <= n_beats + 1;
        ray_of[i_u * {rb} +: {rb}] <= i_ray;
        outcome_of[i_u * 2 +: 2] <= i_outcome;
      end
      if (i_take && i_hit) hits[n_in[2:0] * {n} + i_ray] <= 1;
      if (i_take && i_last) begin
        n_in <= n_in + 1;
        hits[next_slot * {n} +: {n}] <= 0;
        first[next_slot * {uw} +: {uw}] <= n_beats + 1;
      end
      if (o_take && o_unc) u_next <= o_u + 1;
      if (o_take && !o_unc) begin
        sent <= !o_last;
        if (o_last) n_out <= n_out + 1;
        prev <= o_ray;
      end
    end
    rb_held <= !rst && rb_valid && !rb_ready;
    rb_held_payload <= rb_payload;
{checks}      if (rb_held) assume(rb_valid && rb_payload == rb_held_payload);   // the stream rule
      if (i_valid) assume(i_u == n_beats);   // the environment numbers its beats in u
      // the ray-triangle unit's certified hit bit is its outcome 1
      if (i_valid) assume(i_payload[{at["hit"]}] == (i_outcome == 2'd1));
      assert(in_flight <= 7);
      if (i_take) assert(in_flight <= 6);
      // none lost or doubled: passed on = out + in the output register + in the skid
      assert(n_pass == n_unc + (o_valid && o_unc) + sk_probe);
      if (o_valid) begin
        assert(o_empty == (o_outcome == 2'd0));
        if (o_unc) begin                     // a passed-on pair, maybe before its run's last
          assert(!o_last && !sent);          // before its run's answers, never its last
          assert(o_u >= u_next && o_u < n_beats);      // in stream order, once each
          // a beat of run n_out (the one being reduced), up to its last if that came in
          assert(o_u >= run_first && (in_flight == 0 || o_u < run_end));
          assert(o_ray == o_beat_ray);       // that beat's ray
          assert(o_beat_outcome != 2'd0);    // uncertain, or a certain hit
        end else assert(in_flight != 0);     // an answer only for a run whose last came in
        if (o_empty) assert(o_last && !sent && valid_probe == 0);
        else if (!o_unc) begin
          assert(!sent || o_ray > prev);     // lowest first: ascending, each ray once
          assert(out_hits[o_ray]);           // a ray with a hit beat in its run
          assert((valid_probe & upto) == 0 && (valid_probe & ~out_hits) == 0);
          assert(o_last == (valid_probe == 0));
        end
      end
      cover(o_take && o_unc && o_u != 0);    // a passed-on pair after another beat
      cover(o_valid && o_unc && off);        // one held under !o.ready (the skid fills)
      cover(o_take && !o_unc && !o_empty && u_next != 0);   // an answer after passed-on pairs
      cover(o_take && o_empty && u_next != 0);   // a run with passed-on pairs, no answer
    end
  end
endmodule
"""


def _check_text(name: str, info: dict) -> str:
    if name in ("bram-fifo", "sync-fifo-buffered", "credit-fifo", "credit-fifo-banked"):
        return _fifo_check(info["width"], info["depth"], info.get("credits", False))
    if name == "output-credits":
        return _credits_check(info)
    if name == "job-distributor":
        return _distributor_check(info)
    if name == "result-framing":
        return _framing_check(info)
    if name in ("pair-selector", "pair-selector-reduce"):
        return _selector_check(info)
    if name == "record-fetch":
        return _fetch_check(info)
    if name == "sphere-feeder":
        return _feeder_check(info)
    if name == "reducer-send":
        return _reducer_check(info)
    if name == "reducer-certified":
        return _reducer_certified_check(info)
    return _merger_check(info)


def _run(work: Path, mode: str, depth: int, timeout: float, probes: tuple
         ) -> tuple[str, float, str]:
    job = f"{mode}.sby"
    tie = "".join(f"connect -set {wire} {inner}\n" for wire, inner in probes)
    (work / job).write_text(_SBY.format(mode=mode, depth=depth, timeout=max(1, int(timeout)),
                                        probes=tie))
    status, seconds, out = run_job(work, job, timeout)
    if status == "timeout":
        return "unknown", seconds, f"no answer after {timeout:g} s"
    (work / f"{mode}.log").write_text(out)
    if status == "pass":
        return ("proved" if mode != "bmc" else "bounded", seconds,
                {"prove": "k-induction", "bmc": f"no failure in {depth} cycles from reset",
                 "cover": "every cover reached"}[mode])
    if status == "fail":
        return "counterexample", seconds, f"trace under {work / mode}"
    return "unknown", seconds, out


def check_stage(name: str, *, timeout: float = 300, cwd: Path | str = ".",
                mutate=None) -> dict:
    """Check stream stage ``name`` (one of :data:`STAGES`): the properties by k-induction,
    then the cover statements (non-vacuity).

    Returns ``{"stage", "what", "result", "seconds", "steps", "reason"}``: ``result`` is
    ``proved`` only if the induction passed and every cover was reached, ``bounded`` for a
    stage checked to a bounded depth (:attr:`Stage.mode`) whose covers were reached. ``mutate``
    (``str -> str``) changes the stage's Verilog (negative controls).

    Raises
    ------
    ValueError
        For an unknown stage, or a mutation that leaves the Verilog unchanged.
    """
    if name not in STAGES:
        raise ValueError(f"stage must be one of {', '.join(STAGES)}, not {name!r}")
    stage = STAGES[name]
    text, info = stage_verilog(name)
    if mutate is not None:
        changed = mutate(text)
        if changed == text:
            raise ValueError("the mutation did not change the Verilog")
        text = changed
    check = _check_text(name, info)
    digest = hashlib.sha256((text + check).encode()).hexdigest()[:12]
    work = Path(cwd) / WORK_DIR / f"stream-{name}-{digest}"
    work.mkdir(parents=True, exist_ok=True)
    (work / "stage.v").write_text(text)
    (work / "check.v").write_text(check)
    steps, result, reason = [], "proved" if stage.mode == "prove" else "bounded", ""
    cover = stage.depth + 4 if stage.cover is None else stage.cover
    for mode, depth in ((stage.mode, stage.depth), ("cover", cover)):
        res, secs, detail = _run(work, mode, depth, timeout, stage.probes)
        steps.append({"proves": f"sby {mode}: {detail}", "result": res,
                      "seconds": round(secs, 3)})
        if res not in ("proved", "bounded"):
            result, reason = res, detail
            if mode == "cover" and res == "counterexample":
                result, reason = "unknown", f"a cover was not reached ({detail}): vacuous?"
            break
    return {"stage": name, "what": stage.what, "result": result,
            "seconds": round(sum(s["seconds"] for s in steps), 3), "steps": steps,
            "reason": reason}
