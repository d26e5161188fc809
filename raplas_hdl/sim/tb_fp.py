"""cocotb testbenches for streaming pipelines (the FP units first) around the batch harness.

The top level is the harness of :mod:`raplas_hdl.sim.harness` (so one build serves both tests). The
pytest side passes everything through environment variables and files:

``RAPLAS_SPEC``
    The :class:`raplas_hdl.sim.harness.HarnessSpec` as JSON.
``RAPLAS_TB_IN`` (per-cycle test)
    An ``.npz`` with one array per input data port, and scalars ``idle`` (probability of a
    gap in ``valid``), ``stall`` (probability that ``en``/``o_ready`` is low) and ``seed``.
``RAPLAS_TB_OUT``
    Per-cycle test: an ``.npz`` written with one array per output data port, in beat order.
    Batch test: a JSON file with the cycle count (the results come from the harness file).

Tests: ``test_batch`` (cocotb starts the clock, resets, waits for ``done``) and
``test_percycle`` (:class:`StreamTB` drives and monitors every cycle from Python). Neither
compares with a model: the pytest side does, in bulk, and asserts.
"""

from __future__ import annotations

import json
import os
import random
import re

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, ReadOnly, RisingEdge, Timer

from raplas_hdl.fp import FPFormat
from raplas_hdl.rtl.emit import emit_verilog
from raplas_hdl.sim.harness import HarnessSpec, run_batch, run_percycle

CLOCK_NS = 10


class StreamTB:
    """Per-cycle driver and monitor of a pipelined unit with valid and enable/ready ports.

    Parameters
    ----------
    dut : cocotb handle
        The harness top level (its DUT-facing registers are named as the DUT's ports).
    spec : HarnessSpec
        The unit's streaming interface.
    idle : float
        Probability of an idle cycle (``valid`` low) before each vector (idle inserter).
    stall : float
        Probability that ``en`` (or ``o_ready``) is low in a cycle (back-pressure inserter).
    seed : int
        Seed of the inserters.
    """

    def __init__(self, dut, spec: HarnessSpec, idle=0.0, stall=0.0, seed=1):
        self.dut = dut
        self.spec = spec
        self.idle = float(idle)
        self.stall = float(stall)
        self.rng = random.Random(seed)
        self.clk = getattr(dut, spec.clk)
        self._clock_started = False

    def start_clock(self):
        if not self._clock_started:
            Clock(self.clk, CLOCK_NS, unit="ns").start()
            self._clock_started = True

    def _set_ready(self, value: int):
        s = self.spec
        if s.en:
            getattr(self.dut, s.en).value = value
        if s.o_ready:
            getattr(self.dut, s.o_ready).value = value

    async def reset(self, cycles: int = 3):
        """Start the clock, hold reset for ``cycles`` cycles, leave the inputs idle."""
        self.start_clock()
        s = self.spec
        getattr(self.dut, s.i_valid).value = 0
        self._set_ready(0)
        getattr(self.dut, s.rst).value = 1
        await ClockCycles(self.clk, cycles)
        await RisingEdge(self.clk)
        getattr(self.dut, s.rst).value = 0

    async def run_test(self, vectors: dict, n_out: int | None = None,
                       max_cycles: int | None = None) -> dict:
        """Drive every vector of ``vectors`` (``{input port: values}``), collect ``n_out``
        output beats (default: one per vector); returns ``{output port: list of ints}``."""
        s, dut = self.spec, self.dut
        n_in = len(vectors[s.inputs[0].name])
        n_out = n_in if n_out is None else n_out
        max_cycles = 64 * n_in + 1000 if max_cycles is None else max_cycles
        cols = {p.name: [int(v) for v in vectors[p.name]] for p in s.inputs}
        in_h = [(getattr(dut, p.name), cols[p.name]) for p in s.inputs]
        out_h = [(p.name, getattr(dut, p.name)) for p in s.outputs]
        valid_h = getattr(dut, s.i_valid)
        o_valid_h = getattr(dut, s.o_valid)
        i_ready_h = getattr(dut, s.i_ready) if s.i_ready else None
        results = {p.name: [] for p in s.outputs}
        idx, got, cycles = 0, 0, 0
        valid = 0
        while got < n_out:
            if cycles >= max_cycles:
                raise AssertionError(f"{got} of {n_out} outputs after {cycles} cycles")
            # inputs for this cycle (a raised valid stays until taken)
            if not valid and idx < n_in and self.rng.random() >= self.idle:
                for h, col in in_h:
                    h.value = col[idx]
                valid = 1
            valid_h.value = valid
            ready = 0 if self.stall and self.rng.random() < self.stall else 1
            self._set_ready(ready)
            await ReadOnly()
            in_ready = ready if s.en else (int(i_ready_h.value) if i_ready_h is not None else 1)
            out_ready = ready if (s.en or s.o_ready) else 1
            if int(o_valid_h.value) and out_ready:
                for name, h in out_h:
                    results[name].append(int(h.value))
                got += 1
            taken = valid and in_ready
            await RisingEdge(self.clk)
            cycles += 1
            if taken:
                idx += 1
                valid = 0
        self.cycles = cycles
        return results


def _spec() -> HarnessSpec:
    return HarnessSpec.from_json(os.environ["RAPLAS_SPEC"])


@cocotb.test()
async def test_percycle(dut):
    """Drive the vectors of ``RAPLAS_TB_IN`` cycle by cycle; write the outputs."""
    spec = _spec()
    data = np.load(os.environ["RAPLAS_TB_IN"])
    tb = StreamTB(dut, spec, idle=float(data["idle"]), stall=float(data["stall"]),
                  seed=int(data["seed"]))
    await tb.reset()
    vectors = {p.name: data[p.name] for p in spec.inputs}
    out = await tb.run_test(vectors)
    np.savez(os.environ["RAPLAS_TB_OUT"],
             cycles=tb.cycles,
             **{k: np.array(v, dtype=np.uint64 if max(v, default=0) < 2**64 else object)
                for k, v in out.items()})


@cocotb.test()
async def test_batch(dut):
    """Wait for the harness's ``done``; fail on its timeout.

    The harness makes its own clock and reset (no GPI call per edge) unless the run has
    ``+EXT_CLK``; then this test starts a cocotb clock and resets."""
    if os.environ.get("RAPLAS_EXT_CLK"):
        Clock(dut.clk, CLOCK_NS, unit="ns").start()
        dut.rst.value = 1
        await ClockCycles(dut.clk, 3)
        dut.rst.value = 0
    if dut.done.value != 1:
        await RisingEdge(dut.done)
    await Timer(1, unit="ns")
    cycles = int(dut.cycles.value)
    if os.environ.get("RAPLAS_TB_OUT"):
        with open(os.environ["RAPLAS_TB_OUT"], "w") as fh:
            json.dump({"cycles": cycles, "timeout": int(dut.timeout.value)}, fh)
    assert not int(dut.timeout.value), f"harness timed out after {cycles} cycles"


# -- the FP units: Verilog, spec, golden results, comparison (pytest / CLI side) --------

FP_OPS = ("fp-add", "fp-mul")


def fp_spec(op: str, fmt) -> HarnessSpec:
    """The harness spec of ``FPAdd`` (``op="fp-add"``) or ``FPMul`` (``"fp-mul"``)."""
    if op not in FP_OPS:
        raise ValueError(f"op must be one of {', '.join(FP_OPS)}, not {op!r}")
    w = fmt.width
    ins = [("a", w), ("b", w)] + ([("sub", 1)] if op == "fp-add" else [])
    return HarnessSpec(dut=op.replace("-", "_"), inputs=ins, outputs=[("o", w), ("flags", 3)],
                       en="en")


def fp_verilog(op: str, fmt, stages: int | None = None, multiplier: str = "generic"
               ) -> tuple[str, int]:
    """``(verilog text, latency)`` of the FP unit, module named ``fp_add``/``fp_mul``.

    ``multiplier`` picks the significand multiplier of ``fp-mul`` and the target of
    ``fp-add`` (its ``multiplier=`` alias of ``target``: the two-DSP48 adder);
    with ``"virtex4"`` the text instantiates ``DSP48`` and a simulation needs
    :func:`raplas_hdl.rtl.dsp48.dsp48_sim_model` appended (once per design).
    """
    # lazy (both): the RTL loads Amaranth, which the testbench in the simulator never needs
    if op == "fp-add":
        from raplas_hdl.rtl.fp_add import FPAdd as cls
    elif op == "fp-mul":
        from raplas_hdl.rtl.fp_mul import FPMul as cls
    else:
        raise ValueError(f"op must be one of {', '.join(FP_OPS)}, not {op!r}")
    kw = {} if stages is None else {"stages": stages}
    if multiplier != "generic":
        kw["multiplier"] = multiplier
    comp = cls(fmt, **kw)
    params = {"exp_bits": fmt.exp_bits, "man_bits": fmt.man_bits, "rounding": fmt.rounding,
              "stages": stages if stages is not None else "default"}
    if "multiplier" in kw:
        params["multiplier"] = multiplier
    text, _ = emit_verilog(comp, op.replace("-", "_"), params)
    return text, comp.latency


def fp_expected(op: str, fmt, a, b, sub=None) -> tuple[np.ndarray, np.ndarray]:
    """Golden ``(bits uint32, flags uint8)`` of ``op`` on operand arrays (``sub`` for add)."""
    # lazy: the golden model loads numba, which the testbench in the simulator never needs
    from raplas_hdl.fp import model

    a = np.asarray(a, dtype=np.uint32)
    b = np.asarray(b, dtype=np.uint32)
    if op == "fp-mul":
        return model.mul(a, b, fmt, flags=True)
    if op != "fp-add":
        raise ValueError(f"op must be one of {', '.join(FP_OPS)}, not {op!r}")
    if sub is None:
        return model.add(a, b, fmt, flags=True)
    bits, flags = model.add(a, b, fmt, flags=True)
    sbits, sflags = model.sub(a, b, fmt, flags=True)
    s = np.asarray(sub).astype(bool)
    return np.where(s, sbits, bits).astype(np.uint32), np.where(s, sflags, flags).astype(np.uint8)


def fp_cosim(op: str, fmt, a, b, sub=None, *, simulator: str, stages: int | None = None,
             mode: str = "batch", valid_density: float = 0.7, stall_density: float = 0.2,
             seed: int = 1, expected=None, timeout_s: float | None = None,
             multiplier: str = "generic") -> dict:
    """Run operand arrays through the FP unit's Verilog and compare with the model.

    Parameters
    ----------
    op : str
        ``"fp-add"`` or ``"fp-mul"``.
    fmt : FPFormat
        Format and rounding.
    a, b : array of uint32
        Operand bit patterns.
    sub : array of 0/1, optional
        Per-operation subtract select (``fp-add``; default all 0).
    simulator : str
        ``"icarus"`` or ``"verilator"``.
    stages : int, optional
        Pipeline depth (default: the unit's).
    mode : str
        ``"batch"`` (harness streams files at full clock rate) or ``"percycle"``
        (:class:`StreamTB` drives every cycle from Python).
    valid_density, stall_density : float
        Probability that ``i_valid`` is high, and that ``en`` is low, in a cycle.
    expected : (bits, flags), optional
        Expected results (default: :func:`fp_expected`); flags may be None (not checked).
    multiplier : str
        ``fp-mul``: ``"generic"`` or ``"virtex4"`` (DSP48 primitives, simulated with
        Yosys's model, :func:`raplas_hdl.rtl.dsp48.dsp48_sim_model`).

    Returns
    -------
    dict
        ``n``, ``mismatches`` (count), ``bad`` (indices), ``got`` and ``got_flags``,
        ``expected`` and ``expected_flags``, ``vectors_per_s``, ``cycles``, ``run_s``,
        ``build_s``, ``latency``.
    """
    a = np.asarray(a, dtype=np.uint32)
    b = np.asarray(b, dtype=np.uint32)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"a and b must be 1-D arrays of one length, not {a.shape}, {b.shape}")
    spec = fp_spec(op, fmt)
    cols = {"a": a, "b": b}
    if op == "fp-add":
        cols["sub"] = (np.zeros(a.shape, np.uint32) if sub is None
                       else np.asarray(sub).astype(np.uint32))
    verilog, latency = fp_verilog(op, fmt, stages, multiplier)
    key = f"{spec.dut}-{fmt.name}-s{stages if stages is not None else 'd'}"
    if multiplier != "generic":
        # lazy: rtl.dsp48 loads Amaranth, which the testbench in the simulator never needs
        from raplas_hdl.rtl.dsp48 import dsp48_sim_model

        verilog += "\n" + dsp48_sim_model()
        key += f"-{multiplier}"
    if mode == "batch":
        out, info = run_batch(simulator, spec, verilog, key, cols, valid_density,
                              stall_density, seed, timeout_s=timeout_s)
    elif mode == "percycle":
        out, info = run_percycle(simulator, spec, verilog, key, cols, 1.0 - valid_density,
                                 stall_density, seed, timeout_s=timeout_s)
    else:
        raise ValueError(f"mode must be 'batch' or 'percycle', not {mode!r}")
    if expected is None:
        exp_bits, exp_flags = fp_expected(op, fmt, a, b, cols.get("sub"))
    else:
        exp_bits, exp_flags = expected
    exp_bits = np.asarray(exp_bits, dtype=np.uint32)
    got = out["o"].astype(np.uint32)
    got_flags = out["flags"].astype(np.uint8)
    bad = got != exp_bits
    if exp_flags is not None:
        exp_flags = np.asarray(exp_flags, dtype=np.uint8)
        bad |= got_flags != exp_flags
    idx = np.flatnonzero(bad)
    return {"n": int(a.size), "mismatches": int(idx.size), "bad": idx, "got": got,
            "got_flags": got_flags, "expected": exp_bits, "expected_flags": exp_flags,
            "vectors_per_s": info["vectors_per_s"], "cycles": info["cycles"],
            "run_s": info["run_s"], "build_s": info["build_s"], "latency": latency}


def format_mismatches(res: dict, a, b, sub=None, limit: int = 5) -> str:
    """The first ``limit`` mismatches of :func:`fp_cosim`, one per line, in hex."""
    lines = []
    for i in res["bad"][:limit]:
        s = f" sub={int(sub[i])}" if sub is not None else ""
        ef = res["expected_flags"]
        lines.append(f"#{i}: a={int(a[i]):08x} b={int(b[i]):08x}{s} expected "
                     f"{int(res['expected'][i]):08x}"
                     + (f"/flags {int(ef[i])}" if ef is not None else "")
                     + f" got {int(res['got'][i]):08x}/flags {int(res['got_flags'][i])}")
    return "\n".join(lines)


def fp_bundle(exp_bits: int, man_bits: int, roundings=("rtz", "rne", "chop"),
              ops=FP_OPS, multipliers=("generic",)) -> tuple[HarnessSpec, str, dict]:
    """One DUT holding every (op, rounding) unit of a format, fed the same operands.

    Lets one simulator build (and one batch run) check all roundings of both units: the
    wrapper ``fp_bundle`` has inputs ``a``, ``b``, ``sub`` (adders only), ``i_valid``,
    ``en`` and per unit outputs ``o_<op>_<rounding>``, ``f_<op>_<rounding>`` (flags), plus
    ``valids`` (one ``o_valid`` per unit, all 1 on every beat when the units agree on
    timing). Shorter units are delayed (on enabled edges) to the longest latency.

    ``multipliers`` lists the multiplier targets to build (each rounding once per target);
    the generic units keep the suffix ``mul_<rounding>``, the others get
    ``mul_<rounding>_<target>``. With ``"virtex4"`` (``DSP48`` primitives) Yosys's ``DSP48``
    simulation model (:func:`raplas_hdl.rtl.dsp48.dsp48_sim_model`) is appended to the
    text. As every unit is delayed to the longest *stated* latency, ``valids`` all 1 on every
    beat (checked by :func:`check_bundle`) shows that the targets' ``latency`` values are
    true, stalls included.

    Returns ``(spec, verilog, units)`` with ``units = {output suffix: (op, FPFormat)}``.
    """
    if isinstance(multipliers, str):
        multipliers = (multipliers,)
    units, texts, lat = {}, [], {}
    for op in ops:
        for r in roundings:
            for target in (multipliers if op == "fp-mul" else ("generic",)):
                fmt = FPFormat(exp_bits, man_bits, r)
                text, latency = fp_verilog(op, fmt, multiplier=target)
                suffix = f"{op.split('-')[1]}_{r}" + ("" if target == "generic" else
                                                      f"_{target}")
                units[suffix] = (op, fmt)
                lat[suffix] = latency
                texts.append(_rename_unit(text, op, suffix))
    w = 1 + exp_bits + man_bits
    top = max(lat.values())
    n = len(units)
    lines = ["`default_nettype none", "module fp_bundle(input wire clk, input wire rst,",
             f"  input wire [{w - 1}:0] a, input wire [{w - 1}:0] b, input wire sub,",
             "  input wire i_valid, input wire en,",
             f"  output wire [{n - 1}:0] valids, output wire o_valid,"]
    outs = []
    for suffix in units:
        outs.append(f"  output wire [{w - 1}:0] o_{suffix}, output wire [2:0] f_{suffix}")
    lines.append(",\n".join(outs) + ");")
    for k, (suffix, (op, _)) in enumerate(units.items()):
        d = top - lat[suffix]
        subc = ", .sub(sub)" if op == "fp-add" else ""
        lines.append(f"  wire [{w - 1}:0] o_{suffix}_u; wire [2:0] f_{suffix}_u; "
                     f"wire v_{suffix}_u;")
        lines.append(f"  fp_{suffix} u_{suffix} (.clk(clk), .rst(rst), .a(a), .b(b){subc}, "
                     f".i_valid(i_valid), .en(en), .o(o_{suffix}_u), .flags(f_{suffix}_u), "
                     f".o_valid(v_{suffix}_u));")
        if d == 0:
            lines.append(f"  assign {{valids[{k}], f_{suffix}, o_{suffix}}} = "
                         f"{{v_{suffix}_u, f_{suffix}_u, o_{suffix}_u}};")
            continue
        lines.append(f"  reg [{w + 3}:0] dl_{suffix} [0:{d - 1}];")
        lines.append("  integer i_" + suffix + ";")
        lines.append("  always @(posedge clk) begin")
        lines.append(f"    if (rst) begin for (i_{suffix} = 0; i_{suffix} < {d}; "
                     f"i_{suffix} = i_{suffix} + 1) dl_{suffix}[i_{suffix}] <= 0; end")
        lines.append("    else if (en) begin")
        lines.append(f"      dl_{suffix}[0] <= {{v_{suffix}_u, f_{suffix}_u, o_{suffix}_u}};")
        for i in range(1, d):
            lines.append(f"      dl_{suffix}[{i}] <= dl_{suffix}[{i - 1}];")
        lines.append("    end")
        lines.append("  end")
        lines.append(f"  assign {{valids[{k}], f_{suffix}, o_{suffix}}} = dl_{suffix}[{d - 1}];")
    lines.append("  assign o_valid = |valids;")
    lines.append("endmodule")
    lines.append("`default_nettype wire")
    ins = [("a", w), ("b", w)] + ([("sub", 1)] if "fp-add" in ops else [])
    outputs = [("valids", n)]
    for suffix in units:
        outputs += [(f"o_{suffix}", w), (f"f_{suffix}", 3)]
    if "fp-add" not in ops:
        lines = [ln.replace(", input wire sub", "") for ln in lines]
    spec = HarnessSpec(dut="fp_bundle", inputs=ins, outputs=outputs, en="en")
    if "fp-mul" in ops and set(multipliers) - {"generic"}:
        # lazy: rtl.dsp48 loads Amaranth, which the testbench in the simulator never needs
        from raplas_hdl.rtl.dsp48 import dsp48_sim_model

        texts.append(dsp48_sim_model())
    return spec, "\n\n".join(texts) + "\n\n" + "\n".join(lines) + "\n", units


def _rename_unit(text: str, op: str, suffix: str) -> str:
    """Rename a unit's modules (top and escaped submodules) to ``fp_<suffix>``."""
    base = op.replace("-", "_")
    name = f"fp_{suffix}"
    text = re.sub(rf"(?m)^module {base}\(", f"module {name}(", text)
    return text.replace(f"\\{base}.", f"\\{name}.")


def check_bundle(units: dict, outputs: dict, a, b, sub=None) -> list[str]:
    """Compare every unit's outputs of a :func:`fp_bundle` run with the model.

    Returns one message per failing unit (empty list when all bits and flags agree).
    """
    msgs = []
    n = len(a)
    valids = np.asarray(outputs["valids"])
    if valids.shape[0] != n or np.any(valids != (1 << len(units)) - 1):
        msgs.append(f"valids: {valids.shape[0]} beats for {n} vectors, or not all units "
                    "valid on every beat")
        return msgs
    for suffix, (op, fmt) in units.items():
        eb, ef = fp_expected(op, fmt, a, b, sub if op == "fp-add" else None)
        got, gf = outputs[f"o_{suffix}"], outputs[f"f_{suffix}"]
        bad = np.flatnonzero((got != eb) | (gf != ef))
        if bad.size:
            first = bad[:3]
            tag = "" if suffix.endswith(fmt.rounding) else f" ({suffix.rsplit('_', 1)[1]})"
            msgs.append(f"{op} {fmt.name}{tag}: {bad.size} of {n} mismatch; first: " + "; ".join(
                f"a={int(a[i]):x} b={int(b[i]):x}"
                + (f" sub={int(sub[i])}" if sub is not None and op == "fp-add" else "")
                + f" expected {int(eb[i]):x}/{int(ef[i])} got {int(got[i]):x}/{int(gf[i])}"
                for i in first))
    return msgs
