"""A live simulation of the intersection unit fed job streams at full clock rate.

The per-cycle cocotb driver (:mod:`raplas_hdl.sim.tb.intersection`) pays a Python round trip
on every clock and reloads the scene on every call. Here a generated Verilog harness around
the unit (module ``unit_harness``) runs as a plain simulator process (Verilator with the
C++ main of :func:`raplas_hdl.sim.build.runner.build_plain_verilator`,
or Icarus's ``vvp``) that stays alive for a whole session: Python sits only at round
boundaries.

The harness reads *ops* from a control pipe, each three little-endian 32-bit words (``op addr
data``, binary: ``$fscanf`` with ``%u``, no text to parse per clock) and executes them at full
rate (one write per clock):

====  ==========================================================================================
op    meaning
====  ==========================================================================================
0     write ``data`` at ``addr`` through the unit's write port (one clock)
1     present the command ``data`` (the packed ``CMD`` record) until the unit takes it
2     wait until ``addr`` runs (counted since the start) have sent their ``last`` beat
3     write the ``counters`` port and the highest pair-FIFO level to the counters file, then
      clear the counters (one clock)
4     end of round: flush the output files and write ``done <clock cycles>`` to the status pipe
5     quit
====  ==========================================================================================

Every result beat goes to the beats file in binary (the ``RESULT`` record; ``ANSWER`` with
``UnitConfig.reduce``): ``$fwrite`` with ``%u`` under Verilator (two-state: 32-bit words, least
significant first, little-endian), with ``%z`` under Icarus (four-state: each word followed by
its X/Z mask, which must be zero: an X from the unit is an error, not a silent 0); decoded in
bulk with :meth:`~raplas_hdl.model.records.Layout.unpack_words`, no text formatted or parsed
per beat (:func:`parse_beats`). ``o.ready`` is driven by a seeded LFSR
(``+READY_THR=t``: probability times 65536 that it is high in a cycle). Every clock the
harness checks that the pair FIFO never overflowed and stays within its depth; a breach
(or a wait without progress for ``+MAX_STALL`` clocks) writes ``error ...`` to the status pipe
and ends the simulation.

A session (:class:`UnitSession`) loads the scene once: by default through a backdoor,
``$readmemh`` of the Triangle, Sphere, count and triangle-list memories (hierarchical
references into the unit's RAM instances, no change to the unit) from images the host
writes (:func:`scene_images`: the words the write port would store); with
``backdoor=False`` through the write port from the op stream, one word per clock (the
bunny's 0.95 M words take 4-6 s under Verilator, no Python per word). Then it runs rounds
of runs (:meth:`UnitSession.run`): per run its bundle writes (into the other bank while the
previous run goes: the double buffer), then, without overlap, a wait for the previous run
and its counters, then the command; exactly the order of the cocotb testbench, so streams
and counters equal the model's bit for bit. ``record=path`` keeps every op sent in a file:
:func:`replay` runs it again without a host (the limit that ``benchmarks/bench_rtl_render.py``
measures the co-simulated render against).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import select
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from raplas_hdl.locks import file_lock
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.memory_image import REGIONS, SceneMemory, as_run, scene_writes
from raplas_hdl.model.records import CMD, COUNTERS, output_record
# the hex digit tables, defined once
from raplas_hdl.sim.build.harness import HEX_DIGITS, HEX_VALUES
from raplas_hdl.sim.build.runner import BUILD_ROOT, build_plain_verilator, simulator_env
from raplas_hdl.sim.drive.unit_driver import encode_runs, unit_verilog

__all__ = [
    "BACKDOOR",
    "TOPLEVEL",
    "HarnessError",
    "UnitSession",
    "build_harness",
    "encode_ops",
    "harness_verilog",
    "ops_bytes",
    "parse_beats",
    "parse_hex",
    "replay",
    "scene_images",
]

TOPLEVEL = "unit_harness"
OP_WRITE, OP_CMD, OP_WAIT, OP_COUNTERS, OP_END, OP_QUIT = range(6)


class HarnessError(AssertionError):
    """The harness reported an error (FIFO overflow, stall) or the simulator died."""


# -- Verilog ---------------------------------------------------------------------------------
def harness_verilog(config: UnitConfig, four_state: bool = False) -> str:
    """Verilog of module ``unit_harness`` (ports ``clk``, ``rst`` unused, ``done``, ``timeout``)
    around ``intersection_unit`` of ``config`` (not included); ``four_state``: beats written
    with ``%z`` (value and X/Z mask per word, for a four-state simulator) instead of ``%u``."""
    cw = CMD.bind(config).size
    rw = output_record(config).bind(config).size
    kw = COUNTERS.bind(config).size
    lw = max(1, config.fifo_depth.bit_length())
    last = output_record(config).bind(config)["last"].offset
    if cw > 32:
        raise ValueError(f"the CMD record has {cw} bits; the harness takes up to 32")
    return f"""// Job-stream harness of intersection_unit; generated by
// raplas_hdl/sim/drive/unit_harness.py.
`default_nettype none
module {TOPLEVEL} (input wire clk, input wire rst, output reg done, output reg timeout);
  reg wr_en = 0;
  reg [31:0] wr_addr = 0, wr_data = 0;
  reg cmd_valid = 0;
  reg [{cw - 1}:0] cmd_payload = 0;
  reg o_ready = 0, clear = 0;
  wire cmd_ready, o_valid, busy, fifo_overflow;
  wire [{rw - 1}:0] o_payload;
  wire [{kw - 1}:0] counters;
  wire [{lw - 1}:0] fifo_level;
  reg gen_clk = 0, gen_rst = 1;
  intersection_unit dut (.clk(gen_clk), .rst(gen_rst), .wr_en(wr_en), .wr_addr(wr_addr),
    .wr_data(wr_data), .cmd__valid(cmd_valid), .cmd__payload(cmd_payload),
    .cmd__ready(cmd_ready), .o__valid(o_valid), .o__payload(o_payload), .o__ready(o_ready),
    .counters(counters), .clear(clear), .busy(busy), .fifo_level(fifo_level),
    .fifo_overflow(fifo_overflow));
  integer fi = 0, fo = 0, fc = 0, fs = 0, rc = 0;
  reg [4095*8:0] p_ctl, p_beats, p_ctr, p_status, p_init;
  reg [31:0] ready_thr = 65536, seed = 1, lfsr = 1, runs_done = 0, max_level = 0;
  reg [63:0] cycles = 0, stall = 0, max_stall = 64'd100000000;
  reg [3:0] op = 0;
  reg [31:0] a = 0, d = 0;
  reg [95:0] opw = 0;     // one op: op, addr, data (32-bit words, least significant first)
  reg [1:0] state = 0;   // 0 fetch, 1 command offered, 2 waiting for runs
  reg fetch = 0;
  initial begin
    done = 0; timeout = 0;
    if (!$value$plusargs("CTRL=%s", p_ctl)) $fatal(1, "unit_harness: +CTRL missing");
    if (!$value$plusargs("BEATS=%s", p_beats)) $fatal(1, "unit_harness: +BEATS missing");
    if (!$value$plusargs("CTRS=%s", p_ctr)) $fatal(1, "unit_harness: +CTRS missing");
    if (!$value$plusargs("STATUS=%s", p_status)) $fatal(1, "unit_harness: +STATUS missing");
    if ($value$plusargs("READY_THR=%d", ready_thr)) ;
    if ($value$plusargs("SEED=%d", seed)) ;
    if ($value$plusargs("MAX_STALL=%d", max_stall)) ;
    lfsr = (seed * 32'h9E3779B1) ^ 32'h1234567;
    if (lfsr == 0) lfsr = 1;
    // scene backdoor: Triangle, Sphere, count and triangle-list memories from hex files
    if ($value$plusargs("TRI_INIT=%s", p_init)) $readmemh(p_init, dut.tri_mem.mem);
    if ($value$plusargs("SPH_INIT=%s", p_init)) $readmemh(p_init, dut.sph_mem.mem);
    if ($value$plusargs("CNT_INIT=%s", p_init)) $readmemh(p_init, dut.cnt_mem.mem);
    if ($value$plusargs("TL_INIT=%s", p_init)) $readmemh(p_init, dut.tlist_mem.mem);
    fi = $fopen(p_ctl, "r");
    if (fi == 0) $fatal(1, "unit_harness: cannot open %0s", p_ctl);
    fs = $fopen(p_status, "w");
    fo = $fopen(p_beats, "w");
    fc = $fopen(p_ctr, "w");
    if (fs == 0 || fo == 0 || fc == 0) $fatal(1, "unit_harness: cannot open the outputs");
    repeat (6) #5 gen_clk = ~gen_clk;
    gen_rst = 0;
    forever #5 gen_clk = ~gen_clk;
  end
  // Galois LFSR (x^32 + x^22 + x^2 + x + 1), one step per clock
  function [31:0] lfsr_step(input [31:0] x);
    lfsr_step = {{1'b0, x[31:1]}} ^ (x[0] ? 32'h80200003 : 32'h0);
  endfunction
  task fail(input [8*64-1:0] why);
    begin
      $fwrite(fs, "error %0s at cycle %0d (runs done %0d, busy %0d, fifo level %0d)\\n",
              why, cycles, runs_done, busy, fifo_level);
      $fflush(fs);
      timeout = 1;
      done = 1;
      $finish;
    end
  endtask
  always @(posedge gen_clk) begin
    if (!gen_rst && !done) begin
      cycles <= cycles + 1;
      lfsr = lfsr_step(lfsr);
      o_ready <= {{16'h0, lfsr[15:0]}} < ready_thr;
      if (fifo_overflow) fail("pair FIFO overflow");
      if (fifo_level > {config.fifo_depth}) fail("pair FIFO level above its depth");
      if (fifo_level > max_level) max_level <= fifo_level;
      if (o_valid && o_ready) begin
        $fwrite(fo, "{'%z' if four_state else '%u'}", o_payload);
        if (o_payload[{last}]) runs_done <= runs_done + 1;
      end
      wr_en <= 0;
      clear <= 0;
      fetch = 0;
      if (state == 0) fetch = 1;
      else if (state == 1) begin
        if (cmd_ready) begin cmd_valid <= 0; fetch = 1; end
      end else if (runs_done >= a) fetch = 1;
      if (fetch || (o_valid && o_ready)) stall = 0;
      else begin
        stall = stall + 1;
        if (stall > max_stall) fail("no progress");
      end
      if (fetch) begin
        rc = $fscanf(fi, "%u", opw);
        if (rc != 1) op = {OP_QUIT};
        else begin op = opw[3:0]; a = opw[63:32]; d = opw[95:64]; end
        state = 0;
        case (op)
          {OP_WRITE}: begin wr_en <= 1; wr_addr <= a; wr_data <= d; end
          {OP_CMD}: begin cmd_valid <= 1; cmd_payload <= d; state = 1; end
          {OP_WAIT}: state = 2;
          {OP_COUNTERS}: begin
            $fwrite(fc, "%h %h\\n", counters, max_level);
            clear <= 1;
          end
          {OP_END}: begin
            $fflush(fo);
            $fflush(fc);
            $fwrite(fs, "done %0d\\n", cycles);
            $fflush(fs);
          end
          default: begin
            $fclose(fo);
            $fclose(fc);
            $fwrite(fs, "quit %0d\\n", cycles);
            $fclose(fs);
            done = 1;
            $finish;
          end
        endcase
      end
    end
  end
endmodule
"""


def _tail(path: Path, n: int = 30) -> str:
    try:
        return "\n".join(Path(path).read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no log)"


def build_harness(simulator: str, config: UnitConfig, build_key: str | None = None,
                  multiplier: str = "generic", adder: str = "generic") -> list:
    """Build (or reuse) the harness and the unit for ``simulator``; the command that runs it
    (``multiplier="virtex4"``: the DSP48 multipliers, ``adder="virtex4"``: the DSP48 adders,
    with Yosys's DSP48 model).

    Verilator: :func:`~raplas_hdl.sim.build.runner.build_plain_verilator` (the cocotb build's flags,
    no tracing, the plain C++ main). Icarus: ``iverilog -g2005``, run with ``vvp -n``. Both
    are built once per Verilog hash under ``build/sim/``.
    """
    text = harness_verilog(config, four_state=simulator == "icarus") + unit_verilog(
        config, multiplier, adder)
    key = build_key or f"unit-harness-{config.fmt.name}-{config.rows}x{config.cols}"
    if simulator == "verilator":
        return [str(build_plain_verilator(text, TOPLEVEL, key))]
    if simulator != "icarus":
        raise ValueError(f"simulator must be icarus or verilator, not {simulator!r}")
    env = simulator_env("icarus")
    digest = hashlib.sha256(("icarus-g2005\0" + text).encode()).hexdigest()[:8]
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in key)
    d = BUILD_ROOT / f"{safe}-{digest}" / "icarus-plain"
    out = d / "sim.vvp"
    stamp = d / ".built"
    if not stamp.exists():
        with file_lock(d.parent / ".icarus-plain.lock"):
            if not stamp.exists():
                if d.exists():
                    shutil.rmtree(d)
                d.mkdir(parents=True)
                src = d / f"{TOPLEVEL}.v"
                src.write_text(text)
                with open(d / "build.log", "w") as log:
                    res = subprocess.run(["iverilog", "-g2005", "-o", str(out), "-s", TOPLEVEL,
                                          str(src)], check=False, env=env, stdout=log,
                                         stderr=subprocess.STDOUT)
                if res.returncode != 0:
                    raise RuntimeError(f"iverilog build of the unit harness failed:\n"
                                       f"{_tail(d / 'build.log')}")
                stamp.write_text("ok\n")
    return ["vvp", "-n", str(out)]


# -- ops -------------------------------------------------------------------------------------
def ops_bytes(op, addr, data) -> bytes:
    """Ops of equal-length arrays as the harness reads them: per op the 32-bit words ``op``,
    ``addr``, ``data``, little-endian."""
    cols = [np.asarray(x, np.uint64).reshape(-1) for x in (op, addr, data)]
    return np.stack(cols, axis=1).astype("<u4").tobytes()


def parse_beats(data: bytes, width: int, four_state: bool = False) -> np.ndarray:
    """Beats of ``width`` bits as the harness writes them (``%u``: ``ceil(width / 32)``
    little-endian 32-bit words per beat, least significant first; ``four_state``, ``%z``:
    each word followed by its X/Z mask) -> ``(n, ceil(width / 64))`` uint64 words, low first.

    Raises
    ------
    HarnessError
        On a file that is not made of whole beats, or (``four_state``) on a beat with an X
        or Z bit.
    """
    n32 = -(-width // 32)
    per = n32 * (2 if four_state else 1)
    raw = np.frombuffer(data, dtype="<u4")
    if len(data) % (4 * per):
        raise HarnessError(f"result file of {len(data)} bytes is not made of "
                           f"{4 * per}-byte beats")
    raw = raw.reshape(-1, per)
    if four_state:
        xz = raw[:, 1::2]
        if np.any(xz):
            bad = int(np.nonzero(xz.any(axis=1))[0][0])
            raise HarnessError(f"result beat {bad} has X or Z bits (mask words "
                               f"{[hex(int(x)) for x in xz[bad]]})")
        raw = raw[:, 0::2]
    out = np.zeros((raw.shape[0], 2 * (-(-n32 // 2))), "<u4")
    out[:, :n32] = raw
    return out.view("<u8").astype(np.uint64, copy=False)


def parse_hex(data: bytes, digits: int) -> np.ndarray:
    """Lines of ``digits`` hex digits -> ``(n, ceil(4 digits / 64))`` uint64 words, low first.

    Raises
    ------
    HarnessError
        On a malformed line or a digit that is not hex (an ``x`` from the unit).
    """
    line = digits + 1
    raw = np.frombuffer(data, dtype=np.uint8)
    if raw.size % line:
        raise HarnessError(f"result file of {raw.size} bytes is not made of {line}-byte lines")
    raw = raw.reshape(-1, line)
    nib = HEX_VALUES[raw[:, :digits]]
    if np.any(nib == 255) or np.any(raw[:, digits] != ord("\n")):
        bad = int(np.nonzero((nib == 255).any(axis=1) | (raw[:, digits] != ord("\n")))[0][0])
        raise HarnessError(f"result line {bad} is not hex: {bytes(raw[bad])!r}")
    nib = nib[:, ::-1].astype(np.uint64)      # least significant nibble first
    n_words = -(-digits // 16)
    out = np.zeros((raw.shape[0], n_words), np.uint64)
    for j in range(digits):
        out[:, j // 16] |= nib[:, j] << np.uint64(4 * (j % 16))
    return out


def encode_ops(config: UnitConfig, scene: SceneMemory, runs, *, first_run: int = 0,
               overlap: bool = False):
    """Ops ``(op, addr, data)`` of one round of ``runs`` (see the module docstring); run
    numbers count from ``first_run`` (the runs of earlier rounds)."""
    stim = encode_runs(config, scene, runs, overlap=overlap, with_scene=False)
    cmd = CMD.bind(config)
    banks, offs = stim["run_bank"], stim["run_offsets"]
    n = len(banks)
    payload = cmd.pack_words({"first": stim["run_first"], "count": stim["run_count"],
                              "bank": banks, "indirect": stim["run_indirect"],
                              "keep_all": stim["run_keep_all"]}).reshape(n, -1)[:, 0] \
        if n else np.zeros(0, np.uint64)
    ops, addrs, datas = [], [], []

    def put(o, a=0, d=0):
        ops.append(np.array([o], np.uint64))
        addrs.append(np.array([a], np.uint64))
        datas.append(np.array([d], np.uint64))

    last_of_bank = {}
    for k in range(n):
        b = int(banks[k])
        if b in last_of_bank:
            put(OP_WAIT, first_run + last_of_bank[b] + 1)
        wa, wd = stim["run_addr"][offs[k]:offs[k + 1]], stim["run_data"][offs[k]:offs[k + 1]]
        ops.append(np.zeros(wa.size, np.uint64))
        addrs.append(wa.astype(np.uint64))
        datas.append(wd.astype(np.uint64))
        if not overlap and k:
            put(OP_WAIT, first_run + k)
            put(OP_COUNTERS)
        put(OP_CMD, 0, int(payload[k]))
        last_of_bank[b] = k
    put(OP_WAIT, first_run + n)
    put(OP_COUNTERS)
    put(OP_END)
    return np.concatenate(ops), np.concatenate(addrs), np.concatenate(datas)


#: The scene memories the backdoor fills: plusarg, instance in the unit, region, fields.
BACKDOOR = (("TRI_INIT", "tri_mem", "tri"), ("SPH_INIT", "sph_mem", "sphere"),
            ("CNT_INIT", "cnt_mem", "sphere"), ("TL_INIT", "tlist_mem", "tlist"))


#: The last scenes' memory images, ``[(config, scene, images)]`` (a render starts two
#: sessions per unit configuration with one scene: the images are built once).
_IMAGES: list = []


def cached_scene_images(config: UnitConfig, scene: SceneMemory) -> dict:
    """:func:`scene_images`, kept for the last two ``(config, scene)`` (the same objects)."""
    for c, sc, images in _IMAGES:
        if c == config and sc is scene:
            return images
    images = scene_images(config, scene)
    _IMAGES[:] = [(config, scene, images), *_IMAGES[:1]]
    return images


def scene_images(config: UnitConfig, scene: SceneMemory) -> dict:
    """``$readmemh`` text of the scene memories, ``{plusarg: bytes}``: exactly the words the
    write port would store for :func:`~raplas_hdl.model.memory_image.scene_writes` (the
    same address decoding, lanes and truncation as the unit's write port)."""
    w = config.fmt.width
    wa, wd = scene_writes(config, scene)
    wa = np.asarray(wa, np.int64)
    wd = np.asarray(wd, np.uint64)
    region, index, fld = wa >> 28, (wa >> 4) & ((1 << 23) - 1), wa & 15
    layout = {   # plusarg: (select, lane, lane width, lanes, depth)
        "TRI_INIT": ((region == REGIONS["tri"]) & (fld < 12), fld, w, 12,
                     config.max_triangles),
        "SPH_INIT": ((region == REGIONS["sphere"]) & (fld < 4), fld, w, 4, config.max_spheres),
        "CNT_INIT": ((region == REGIONS["sphere"]) & (fld == 4), 0 * fld, config.count_bits, 1,
                     config.max_spheres),
        "TL_INIT": ((region == REGIONS["tlist"]) & (fld == 0), 0 * fld, config.tri_id_bits, 1,
                    config.max_spheres * config.tris_per_sphere),
    }
    out = {}
    for name, (sel, lane, lw, lanes, depth) in layout.items():
        sel = sel & (index < depth)
        rows, lane, data = index[sel], lane[sel], wd[sel]
        n = int(rows.max()) + 1 if rows.size else 0
        width = lw * lanes
        digits = -(-width // 4)
        bits = np.zeros((n, 4 * digits), np.uint8)
        for b in range(lw):
            bits[rows, lane * lw + b] = ((data >> np.uint64(b)) & np.uint64(1)).astype(np.uint8)
        nib = bits.reshape(n, digits, 4) @ np.array([1, 2, 4, 8], np.uint8)
        text = np.concatenate([HEX_DIGITS[nib[:, ::-1]], np.full((n, 1), ord("\n"), np.uint8)],
                              axis=1)
        out[name] = text.tobytes()
    return out


def _scene_ops(config: UnitConfig, scene: SceneMemory):
    wa, wd = scene_writes(config, scene)
    return (np.concatenate([np.zeros(wa.size, np.uint64), [OP_END]]),
            np.concatenate([wa.astype(np.uint64), [0]]),
            np.concatenate([wd.astype(np.uint64), [0]]))


# -- session ------------------------------------------------------------------------------------
class UnitSession:
    """One live simulation of the unit for ``config`` with ``scene`` loaded.

    Parameters
    ----------
    simulator : {"icarus", "verilator"}
    config : UnitConfig
    scene : SceneMemory
        Loaded once, through the write port, at full rate.
    seed, ready_density : int, float
        Back-pressure on the result stream (probability that ``o.ready`` is high).
    record : path, optional
        Keep every op sent in this file (:func:`replay` runs it without a host); with the
        backdoor, the memory images go beside it (``<record>.<PLUSARG>.hex``).
    backdoor : bool
        Load the scene memories with ``$readmemh`` at start-up (default) instead of through
        the write port (one word per clock from the op stream).
    multiplier : ``"generic"`` or ``"virtex4"``
        The unit's multiplier target (``virtex4``: DSP48 primitives, simulated with Yosys's
        model).
    adder : ``"generic"`` or ``"virtex4"``
        The unit's FP adder target (``virtex4``: two DSP48 per adder).
    timeout_s : float
        Longest wait for one round's status line.

    Attributes
    ----------
    cycles : int
        Clock cycles simulated so far (scene load included).
    load_cycles, load_s : int, float
        Clocks and wall seconds of the scene load (start-up included).
    rounds : int
    """

    def __init__(self, simulator: str, config: UnitConfig, scene: SceneMemory, *,
                 seed: int = 1, ready_density: float = 1.0, record=None,
                 timeout_s: float = 24 * 3600.0, build_key: str | None = None,
                 max_stall: int = 100_000_000, backdoor: bool = True,
                 multiplier: str = "generic", adder: str = "generic"):
        if not 0.0 < ready_density <= 1.0:
            raise ValueError(f"ready_density must be in (0, 1], not {ready_density}")
        scene.check(config)
        self.simulator, self.config, self.scene = simulator, config, scene
        self.timeout_s = float(timeout_s)
        self.cycles = 0
        self.rounds = 0
        self.runs_done = 0
        self._proc = None
        self._result = output_record(config).bind(config)
        self._counters = COUNTERS.bind(config)
        self._last_bit = self._result["last"].offset
        cmd = build_harness(simulator, config, build_key, multiplier, adder)
        t0 = time.monotonic()
        self._dir = Path(tempfile.mkdtemp(prefix="raplas-unit-session-"))
        ctl, st = self._dir / "ctl", self._dir / "status"
        os.mkfifo(ctl)
        os.mkfifo(st)
        self._beats_path, self._ctr_path = self._dir / "beats.bin", self._dir / "counters.hex"
        self._beats_off = self._ctr_off = 0
        # both ends opened read-write here: neither open blocks, and the simulator sees EOF on
        # the control pipe when this process goes away
        self._ctl = os.open(ctl, os.O_RDWR)
        self._status = os.open(st, os.O_RDWR | os.O_NONBLOCK)
        self._status_buf = b""
        self._record = open(record, "wb") if record else None  # noqa: SIM115 - session-long
        thr = min(65536, max(1, round(ready_density * 65536)))
        self._log_path = self._dir / "sim.log"
        self._log = open(self._log_path, "wb")  # noqa: SIM115 - session-long
        init = []
        if backdoor:
            for name, text in cached_scene_images(config, scene).items():
                path = self._dir / f"{name}.hex"
                path.write_bytes(text)
                if record:
                    shutil.copyfile(path, f"{record}.{name}.hex")
                init.append(f"+{name}={path}")
        self._proc = subprocess.Popen(
            cmd + init + [f"+CTRL={ctl}", f"+BEATS={self._beats_path}", f"+CTRS={self._ctr_path}",
                   f"+STATUS={st}", f"+READY_THR={thr}", f"+SEED={int(seed)}",
                   f"+MAX_STALL={int(max_stall)}"],
            cwd=self._dir, env=simulator_env(simulator), stdout=self._log,
            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        if backdoor:
            self._send(np.array([OP_END]), np.array([0]), np.array([0]))
        else:
            self._send(*_scene_ops(config, scene))
        self._wait_round()
        self.load_cycles = self.cycles
        self.load_s = time.monotonic() - t0

    # -- plumbing
    def _send(self, op, addr, data):
        payload = ops_bytes(op, addr, data)
        if self._record is not None:
            self._record.write(payload)
        view = memoryview(payload)
        try:
            while view:
                k = os.write(self._ctl, view[:1 << 20])
                view = view[k:]
        except OSError as exc:
            self._died(f"control pipe: {exc}")

    def _died(self, why):
        rc = self._proc.poll() if self._proc else None
        self.close(kill=True)
        raise HarnessError(f"{self.simulator} unit harness: {why} (exit {rc}); log "
                           f"{self._log_path}:\n{_tail(self._log_path)}")

    def _wait_round(self) -> int:
        deadline = time.monotonic() + self.timeout_s
        while b"\n" not in self._status_buf:
            if time.monotonic() > deadline:
                self._died("timed out waiting for the round")
            ready, _, _ = select.select([self._status], [], [], 0.5)
            if ready:
                chunk = os.read(self._status, 4096)
                self._status_buf += chunk
            elif self._proc.poll() is not None:
                self._died("the simulator exited")
        line, _, self._status_buf = self._status_buf.partition(b"\n")
        words = line.decode(errors="replace").split()
        if not words or words[0] != "done":
            self._died(line.decode(errors="replace"))
        self.cycles = int(words[1])
        self.rounds += 1
        return self.cycles

    def _read_new(self, path, attr) -> bytes:
        off = getattr(self, attr)
        with open(path, "rb") as f:
            f.seek(off)
            data = f.read()
        setattr(self, attr, off + len(data))
        return data

    # -- API
    def run(self, runs, *, overlap: bool = False):
        """One round: ``runs`` through the unit; ``[(stream, counters)]`` as
        :func:`raplas_hdl.sim.drive.unit_driver.run_runs` returns them (``counters`` also hold
        ``cycles`` and ``_max_fifo_level``; with ``overlap`` only the last run's, the
        round's totals)."""
        if self._proc is None:
            raise HarnessError("the session is closed")
        runs = [as_run(r) for r in runs]
        if not runs:
            return []
        for b, ids, _ in runs:
            b.check(self.config)
            if ids is not None and np.asarray(ids).size and (
                    np.asarray(ids).max() >= self.scene.n_spheres):
                raise ValueError("a run names a sphere the scene does not have")
        self._send(*encode_ops(self.config, self.scene, runs, first_run=self.runs_done,
                               overlap=overlap))
        self._wait_round()
        self.runs_done += len(runs)
        words = parse_beats(self._read_new(self._beats_path, "_beats_off"), self._result.size,
                            four_state=self.simulator == "icarus")
        results = self._result.unpack_words(words)
        ctr_text = self._read_new(self._ctr_path, "_ctr_off").split()
        kd = -(-self._counters.size // 4)
        ctr_words = parse_hex(b"".join(t + b"\n" for t in ctr_text[0::2]), kd)
        ctrs = self._counters.unpack_words(ctr_words)
        levels = [int(t, 16) for t in ctr_text[1::2]]
        last = results["last"].astype(np.int64)
        run_of_beat = np.concatenate([[0], np.cumsum(last)[:-1]]) if last.size else last
        if int(last.sum()) != len(runs):
            self._died(f"{int(last.sum())} last beats for {len(runs)} runs")
        if len(ctrs) != (1 if overlap else len(runs)):
            self._died(f"{len(ctrs)} counter lines for {len(runs)} runs")
        bounds = np.searchsorted(run_of_beat, np.arange(len(runs) + 1))
        out = []
        for k in range(len(runs)):
            stream = results[bounds[k]:bounds[k + 1]]
            if overlap and k != len(runs) - 1:
                counters = None
            else:
                i = 0 if overlap else k
                counters = {name: int(ctrs[name][i]) for name in COUNTERS.names}
                counters["_max_fifo_level"] = levels[i]
            out.append((stream, counters))
        return out

    def close(self, kill: bool = False):
        """End the simulation (idempotent)."""
        proc, self._proc = self._proc, None
        if proc is not None:
            if not kill and proc.poll() is None:
                # closing: on any trouble fall through to kill
                with contextlib.suppress(Exception):
                    self._send(np.array([OP_QUIT]), np.array([0]), np.array([0]))
                    proc.wait(timeout=60)
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        for fd in ("_ctl", "_status"):
            if getattr(self, fd, None) is not None:
                os.close(getattr(self, fd))
                setattr(self, fd, None)
        for f in ("_record", "_log"):
            if getattr(self, f, None) is not None:
                getattr(self, f).close()
                setattr(self, f, None)
        if getattr(self, "_dir", None) is not None and not kill:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        with contextlib.suppress(Exception):
            self.close()


def replay(simulator: str, config: UnitConfig, ops_path, *, seed: int = 1,
           ready_density: float = 1.0, build_key: str | None = None) -> dict:
    """Run a recorded op file in one go, with no host in the loop (``OP_END`` lines only
    flush; the memory images ``<ops_path>.<PLUSARG>.hex`` a backdoor session recorded are
    loaded). Returns ``cycles`` (clock cycles), ``wall_s`` and the beats file size."""
    cmd = build_harness(simulator, config, build_key)
    with tempfile.TemporaryDirectory(prefix="raplas-unit-replay-") as tmp:
        tmp = Path(tmp)
        st = tmp / "status"
        thr = min(65536, max(1, round(ready_density * 65536)))
        t0 = time.monotonic()
        init = [f"+{name}={ops_path}.{name}.hex" for name, _, _ in BACKDOOR
                if Path(f"{ops_path}.{name}.hex").exists()]
        res = subprocess.run(cmd + init + [f"+CTRL={ops_path}", f"+BEATS={tmp / 'beats'}",
                                    f"+CTRS={tmp / 'ctrs'}", f"+STATUS={st}",
                                    f"+READY_THR={thr}", f"+SEED={seed}"],
                             check=False, cwd=tmp, env=simulator_env(simulator),
                             capture_output=True, text=True)
        wall = time.monotonic() - t0
        status = st.read_text().split("\n") if st.exists() else []
        quit_line = [s for s in status if s.startswith(("quit", "error"))]
        if res.returncode != 0 or not quit_line or quit_line[-1].startswith("error"):
            raise HarnessError(f"replay failed ({res.returncode}): {quit_line} "
                               f"{res.stdout[-2000:]} {res.stderr[-2000:]}")
        return {"cycles": int(quit_line[-1].split()[1]), "wall_s": wall,
                "beats_bytes": (tmp / "beats").stat().st_size}
