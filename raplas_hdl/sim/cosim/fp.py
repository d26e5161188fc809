"""``fp-add`` and ``fp-mul`` against the golden model, in the batch harness or under the
per-cycle cocotb driver (:class:`FPCosim`): their Verilog and harness spec, the model's
results, their vectors files (:func:`read_vectors`, :func:`write_vectors`: ``A B [SUB]
EXPECTED [FLAGS]``, docs/cosim.md); and one DUT holding every rounding of both units
(:func:`fp_bundle`, :func:`check_bundle`) for the tests."""

from __future__ import annotations

import re

import numpy as np

from raplas_hdl.fp import FPFormat
from raplas_hdl.rtl.emit import emit_verilog

from ..build.harness import HarnessSpec, run_batch, run_percycle
from .base import UnitCosim
from .vectors import MAX_LINES, check_header, hex_fields, match_header, text_lines

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


def read_vectors(path, unit: str, fmt=None):
    """``(a, b, sub or None, expected, flags or None)`` from a vectors file.

    Checks everything before returning: the field count of ``unit`` (and the same on every
    line), hex numbers, ``SUB`` 0 or 1, ``FLAGS`` 0 to 7, and with ``fmt`` that ``A``, ``B``
    and ``EXPECTED`` fit its width; a header naming another unit or format is refused.

    Raises
    ------
    ValueError
        One line naming the file, the line and the problem.
    """
    if unit not in FP_OPS:
        raise ValueError(f"unit must be one of {', '.join(FP_OPS)}, not {unit!r}")
    nops = 3 if unit == "fp-add" else 2
    names = ["A", "B"] + (["SUB"] if unit == "fp-add" else []) + ["EXPECTED", "FLAGS"]
    rows = []
    width = None
    for lineno, line in enumerate(text_lines(path), 1):
        m = match_header(line.strip())
        if m:
            check_header(path, lineno, m, unit, fmt)
            continue
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        if len(fields) not in (nops + 1, nops + 2):
            raise ValueError(f"{path}:{lineno}: expected {nops + 1} or {nops + 2} hex fields "
                             f"for {unit} ({' '.join(names[:-1])} [FLAGS]), got {len(fields)}")
        if width is None:
            width = len(fields)
        elif len(fields) != width:
            raise ValueError(f"{path}:{lineno}: {len(fields)} fields where line 1 has "
                             f"{width} (FLAGS on all lines or on none)")
        values = hex_fields(path, lineno, fields, names)
        for name, v in zip(names, values):
            if name == "SUB" and v > 1:
                raise ValueError(f"{path}:{lineno}: SUB must be 0 or 1, not {v:#x}")
            if name == "FLAGS" and v > 7:
                raise ValueError(f"{path}:{lineno}: FLAGS must be 0 to 7 (1 overflow, "
                                 f"2 underflow, 4 invalid), not {v:#x}")
            if fmt is not None and name in ("A", "B", "EXPECTED") and v > fmt.mask:
                raise ValueError(f"{path}:{lineno}: {name} {v:#x} is wider than the "
                                 f"{fmt.width} bits of {fmt.name}")
            if v >= 1 << 32:
                raise ValueError(f"{path}:{lineno}: {name} {v:#x} is wider than 32 bits")
        rows.append(values)
        if len(rows) > MAX_LINES:
            raise ValueError(f"{path}: more than {MAX_LINES:,} cases")
    if not rows:
        raise ValueError(f"{path}: no cases")
    arr = np.array(rows, dtype=np.uint64)
    a, b = arr[:, 0].astype(np.uint32), arr[:, 1].astype(np.uint32)
    sub = arr[:, 2].astype(np.uint32) if unit == "fp-add" else None
    exp = arr[:, nops].astype(np.uint32)
    flags = arr[:, nops + 1].astype(np.uint8) if arr.shape[1] == nops + 2 else None
    return a, b, sub, exp, flags


def write_vectors(path, unit: str, a, b, sub, expected, flags=None, fmt=None) -> None:
    """Write cases in the vectors-file format (docs/cosim.md); the header names the unit
    and, when given, the format."""
    cols = [a, b] + ([sub] if unit == "fp-add" else []) + [expected]
    if flags is not None:
        cols.append(flags)
    spec = "%x"
    tag = f"{unit} {fmt.name}" if fmt is not None else unit
    np.savetxt(path, np.stack([np.asarray(c, dtype=np.uint64) for c in cols], axis=1),
               fmt=" ".join([spec] * len(cols)),
               header=f"{tag}: A B {'SUB ' if unit == 'fp-add' else ''}EXPECTED FLAGS (hex)")


class FPCosim(UnitCosim):
    """``fp-add`` and ``fp-mul``: a case is one operation (``a``, ``b``, and ``sub`` for the
    adder); compared: the result ``o`` and the event flags (when the expected results have
    them). Driver ``"batch"``: the batch harness; ``"percycle"``: the cocotb driver
    (:class:`raplas_hdl.sim.tb.stream.StreamTB`), stalls on ``en`` in both."""

    outputs = ("o", "flags")
    drivers = ("batch", "percycle")

    def __init__(self, fmt, options, driver="batch"):
        super().__init__(fmt, options, driver)
        self.harness = driver
        self.sub = self.name == "fp-add"

    def label(self):
        return f"target={self.target}" if self.target != "generic" else ""

    def random(self, n, seed):
        rng = np.random.default_rng(seed)
        a = rng.integers(0, self.fmt.mask + 1, n, dtype=np.uint32)
        b = rng.integers(0, self.fmt.mask + 1, n, dtype=np.uint32)
        sub = rng.integers(0, 2, n).astype(np.uint32) if self.sub else None
        return {"a": a, "b": b, "sub": sub}

    def expected(self, cases):
        o, flags = fp_expected(self.name, self.fmt, cases["a"], cases["b"], cases["sub"])
        return {"o": o, "flags": flags}

    def n_cases(self, cases):
        return len(cases["a"])

    def read(self, path):
        a, b, sub, o, flags = read_vectors(path, self.name, self.fmt)
        return {"a": a, "b": b, "sub": sub}, {"o": o, "flags": flags}

    def write(self, path, cases, expected):
        write_vectors(path, self.name, cases["a"], cases["b"], cases["sub"], expected["o"],
                      expected["flags"], fmt=self.fmt)

    def show(self, cases, expected, got, i):
        nd = (self.fmt.width + 3) // 4
        sub = cases["sub"]
        e, g = int(expected["o"][i]), int(got["o"][i])
        lines = [f"  case {i}: a={int(cases['a'][i]):0{nd}x} b={int(cases['b'][i]):0{nd}x}"
                 + (f" sub={int(sub[i])}" if sub is not None else ""),
                 f"    {'o':12s} expected {e:0{nd}x}, got {g:0{nd}x}"
                 + ("   <- differs" if e != g else "")]
        if expected["flags"] is not None:
            e, g = int(expected["flags"][i]), int(got["flags"][i])
            lines.append(f"    {'flags':12s} expected {e}, got {g}"
                         + ("   <- differs" if e != g else ""))
        return lines

    def simulate(self, cases, simulator, *, valid_density, stall_density, seed,
                 timeout_s=None):
        spec = fp_spec(self.name, self.fmt)
        cols = {"a": np.asarray(cases["a"], np.uint32), "b": np.asarray(cases["b"], np.uint32)}
        if self.sub:
            cols["sub"] = np.asarray(cases["sub"]).astype(np.uint32)
        stages = self.options.get("stages")
        verilog, latency = fp_verilog(self.name, self.fmt, stages, self.target)
        key = f"{spec.dut}-{self.fmt.name}-s{stages if stages is not None else 'd'}"
        if self.target != "generic":
            # lazy: rtl.dsp48 loads Amaranth; importing raplas_hdl.sim.cosim needs none
            from raplas_hdl.rtl.dsp48 import dsp48_sim_model

            verilog += "\n" + dsp48_sim_model()
            key += f"-{self.target}"
        if self.driver == "batch":
            out, info = run_batch(simulator, spec, verilog, key, cols, valid_density,
                                  stall_density, seed, timeout_s=timeout_s)
        else:
            out, info = run_percycle(simulator, spec, verilog, key, cols, 1.0 - valid_density,
                                     stall_density, seed, timeout_s=timeout_s)
        info["latency"] = latency
        return {"o": out["o"].astype(np.uint32), "flags": out["flags"].astype(np.uint8)}, info


class FPAddCosim(FPCosim):
    name = "fp-add"


class FPMulCosim(FPCosim):
    name = "fp-mul"


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
