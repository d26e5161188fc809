"""The FP units (``fp-add``, ``fp-mul``) in the batch harness or the per-cycle driver,
against the golden model: their Verilog and harness spec, the model's results, the run and
its comparison (:func:`fp_cosim`), and one DUT holding every rounding of both units
(:func:`fp_bundle`, :func:`check_bundle`) for the tests."""

from __future__ import annotations

import re

import numpy as np

from raplas_hdl.fp import FPFormat
from raplas_hdl.rtl.emit import emit_verilog

from ..build.harness import HarnessSpec, run_batch, run_percycle

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
    # lazy (both): the RTL loads Amaranth; importing raplas_hdl.sim.cosim needs none
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
    # lazy: the golden model loads numba; importing raplas_hdl.sim.cosim needs none
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
        # lazy: rtl.dsp48 loads Amaranth; importing raplas_hdl.sim.cosim needs none
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
        # lazy: rtl.dsp48 loads Amaranth; importing raplas_hdl.sim.cosim needs none
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
