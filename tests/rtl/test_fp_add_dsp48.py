# amaranth: UnusedElaboratable=no
"""The DSP48 adder (``FPAdd(fmt, target="virtex4")``, :mod:`raplas_hdl.rtl.fp_add_dsp48`).

One DUT holds, for every rounding, the virtex4 adder and the generic adder (delayed to the
virtex4 latency), fed the same operands; the batch harness runs it under Icarus and
Verilator with Yosys's ``DSP48`` model (``share/xilinx/cells_sim.v``), random gaps in
``i_valid`` and clock-enable stalls, and every result bit and flag of every unit is
compared with :mod:`raplas_hdl.fp.model` (:func:`raplas_hdl.sim.cosim.fp.check_bundle`).
All units valid on every output beat shows that the stated latency (7) is the true one.

* ``make test``: E4M3 every operand pair, add and subtract, under Verilator (all three
  roundings; 131,072 vectors) and Icarus (a random 6,000 of them plus the specials);
* ``full``: FP16, FP20, FP24 under Verilator (100,000 random and special pairs each) and
  FP24 under Icarus.

Plus: latency and errors in Python, and the Yosys mapping (two DSP48, fewer LUTs).
"""

import numpy as np
import pytest
from amaranth.back import verilog
from amaranth.hdl import Cat, Const, Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from raplas_hdl.fp import FP16, FP20, FP24, FP32, ROUNDINGS, FPFormat
from raplas_hdl.rtl.dsp48 import dsp48_sim_model
from raplas_hdl.rtl.fp_add import FPAdd, fp_add_latency
from raplas_hdl.rtl.fp_add_dsp48 import LATENCY
from raplas_hdl.rtl.pipeline import delay
from raplas_hdl.sim.build.harness import HarnessSpec, run_batch
from raplas_hdl.sim.build.runner import require_simulator
from raplas_hdl.sim.cosim.fp import check_bundle
from tests.support.fp_vectors import fp24_vectors, special_values

VERILATOR_ARGS = ("--output-split", "0", "-CFLAGS", "-O0")
E4M3 = FPFormat(4, 3)


class _Bundle(wiring.Component):
    """Generic and virtex4 adders of every rounding of one format, results side by side."""

    def __init__(self, exp_bits, man_bits):
        self._fmts = [FPFormat(exp_bits, man_bits, r) for r in ROUNDINGS]
        w = 1 + exp_bits + man_bits
        self.units = {}
        ports = {"a": In(w), "b": In(w), "sub": In(1), "i_valid": In(1), "en": In(1),
                 "o_valid": Out(1)}
        for fmt in self._fmts:
            for target in ("generic", "virtex4"):
                suffix = f"add_{fmt.rounding}" + ("_virtex4" if target == "virtex4" else "")
                self.units[suffix] = ("fp-add", fmt)
                ports[f"o_{suffix}"] = Out(w)
                ports[f"f_{suffix}"] = Out(3)
        ports["valids"] = Out(len(self.units))
        super().__init__(ports)

    def elaborate(self, platform):
        m = Module()
        valids = []
        for suffix, (_, fmt) in self.units.items():
            unit = FPAdd(fmt, target="virtex4" if suffix.endswith("virtex4") else "generic")
            m.submodules[suffix] = unit
            m.d.comb += [unit.a.eq(self.a), unit.b.eq(self.b), unit.sub.eq(self.sub),
                         unit.i_valid.eq(self.i_valid), unit.en.eq(self.en)]
            # every unit delayed (on enabled edges) to the virtex4 adder's stated latency
            out = delay(m, Cat(unit.o, unit.flags, unit.o_valid), LATENCY - unit.latency,
                        en=self.en, name=f"{suffix}_dly", reset_less=False)
            w = len(unit.o)
            m.d.comb += [getattr(self, f"o_{suffix}").eq(out[:w]),
                         getattr(self, f"f_{suffix}").eq(out[w:w + 3])]
            valids.append(out[w + 3])
        m.d.comb += [self.valids.eq(Cat(*valids)), self.o_valid.eq(self.valids.any())]
        return m


_BUILT = {}


def bundle(exp_bits, man_bits):
    """``(spec, verilog, units)`` of the format's bundle (built once per session)."""
    key = (exp_bits, man_bits)
    if key not in _BUILT:
        top = _Bundle(exp_bits, man_bits)
        text = verilog.convert(top, name="fp_add_dsp48_bundle", emit_src=False)
        assert text.count("DSP48 ") == 2 * 3          # two per virtex4 adder
        w = 1 + exp_bits + man_bits
        outputs = [("valids", len(top.units))]
        for suffix in top.units:
            outputs += [(f"o_{suffix}", w), (f"f_{suffix}", 3)]
        spec = HarnessSpec(dut="fp_add_dsp48_bundle", inputs=[("a", w), ("b", w), ("sub", 1)],
                           outputs=outputs, en="en")
        _BUILT[key] = spec, text + dsp48_sim_model(), top.units
    return _BUILT[key]


def check(simulator, fmt, a, b, sub, seed, timeout_s=600):
    require_simulator(simulator)
    spec, text, units = bundle(fmt.exp_bits, fmt.man_bits)
    out, info = run_batch(simulator, spec, text, f"fp_add_dsp48-e{fmt.exp_bits}m{fmt.man_bits}",
                          {"a": a, "b": b, "sub": sub}, valid_density=0.8, stall_density=0.2,
                          seed=seed, timeout_s=timeout_s,
                          build_args=VERILATOR_ARGS if simulator == "verilator" else ())
    msgs = check_bundle(units, out, a, b, sub)
    assert not msgs, f"{simulator}:\n" + "\n".join(msgs)
    assert info["cycles"] > 1.2 * a.size              # gaps and stalls happened
    return info


def every_pair(fmt):
    x = np.arange(1 << fmt.width, dtype=np.uint32)
    ga, gb = np.meshgrid(x, x)
    a = np.concatenate([ga.ravel(), ga.ravel()]).astype(np.uint32)
    b = np.concatenate([gb.ravel(), gb.ravel()]).astype(np.uint32)
    sub = np.repeat(np.array([0, 1], dtype=np.uint32), ga.size)
    return a, b, sub


def random_vectors(fmt, n, seed):
    """Specials, cancellation (near operands), every alignment distance, random pairs."""
    if fmt == FP24:
        return fp24_vectors(n, seed)
    rng = np.random.default_rng(seed)
    sp = special_values(fmt)
    a = rng.integers(0, 1 << fmt.width, n, dtype=np.uint32)
    b = rng.integers(0, 1 << fmt.width, n, dtype=np.uint32)
    near = rng.random(n) < 0.3
    b[near] = a[near] ^ rng.integers(0, 1 << 6, near.sum(), dtype=np.uint32)
    # exponent of b = exponent of a minus 0 .. M+4 (every alignment shift and beyond)
    dist = rng.random(n) < 0.3
    shift = rng.integers(0, fmt.man_bits + 5, dist.sum()).astype(np.uint32)
    emask = (1 << fmt.exp_bits) - 1
    exp_b = np.clip((a[dist] >> fmt.man_bits & emask).astype(np.int64) - shift, 0, None)
    b[dist] = (b[dist] & ~np.uint32(emask << fmt.man_bits)) | (
        exp_b.astype(np.uint32) << fmt.man_bits)
    ga, gb = np.meshgrid(sp, sp)
    a = np.concatenate([ga.ravel(), a]).astype(np.uint32)
    b = np.concatenate([gb.ravel(), b]).astype(np.uint32)
    return a, b, rng.integers(0, 2, a.size).astype(np.uint32)


# -- co-simulation --------------------------------------------------------------------------

def test_e4m3_every_pair_verilator():
    a, b, sub = every_pair(E4M3)
    check("verilator", E4M3, a, b, sub, seed=3)


def test_e4m3_random_icarus():
    a, b, sub = every_pair(E4M3)
    pick = np.random.default_rng(4).choice(a.size, 6000, replace=False)
    sp = special_values(E4M3)
    ga, gb = np.meshgrid(sp, sp)
    a = np.concatenate([ga.ravel(), a[pick]]).astype(np.uint32)
    b = np.concatenate([gb.ravel(), b[pick]]).astype(np.uint32)
    sub = np.concatenate([np.arange(ga.size) % 2, sub[pick]]).astype(np.uint32)
    check("icarus", E4M3, a, b, sub, seed=5)


@pytest.mark.full
@pytest.mark.parametrize("fmt", [FP16, FP20, FP24], ids=["FP16", "FP20", "FP24"])
def test_random_verilator(fmt):
    a, b, sub = random_vectors(fmt, 100_000, seed=fmt.width)
    check("verilator", fmt, a, b, sub, seed=fmt.width, timeout_s=1200)


@pytest.mark.full
def test_fp24_random_icarus():
    a, b, sub = random_vectors(FP24, 8_000, seed=77)
    check("icarus", FP24, a, b, sub, seed=8, timeout_s=1200)


# -- parameters, latency, errors --------------------------------------------------------

@pytest.mark.parametrize("fmt", [E4M3, FP16, FP20, FP24, FPFormat(8, 15), FPFormat(2, 1)])
def test_latency_and_selection(fmt):
    for kw in ({"target": "virtex4"}, {"multiplier": "virtex4"},
               {"stages": 2, "target": "virtex4"}):
        unit = FPAdd(fmt, **kw)
        assert (unit.target, unit.latency) == ("virtex4", LATENCY)
        assert len(unit.stage_steps) == LATENCY == fp_add_latency(fmt, 4, "virtex4")
    assert FPAdd(fmt).latency == 6 == fp_add_latency(fmt)
    assert FPAdd(fmt, 3, "generic").latency == 3 == fp_add_latency(fmt, 3)
    text = verilog.convert(FPAdd(fmt, target="virtex4"), name="fp_add", emit_src=False)
    assert text.count("DSP48 ") == 2 and " * " not in text


def test_bad_target_or_format_names_the_problem():
    for bad in ("virtex7", "", None, "VIRTEX4", "dsp48"):
        with pytest.raises(ValueError, match="target must be one of generic, virtex4"):
            FPAdd(FP24, target=bad)
    with pytest.raises(ValueError, match="disagree"):
        FPAdd(FP24, target="virtex4", multiplier="xc7")
    with pytest.raises(ValueError, match=r"at most 17 bits .*not 24 \(e8m23"):
        FPAdd(FP32, target="virtex4")
    with pytest.raises(ValueError, match=r"at most 17 bits"):
        fp_add_latency(FP32, 4, "virtex4")
    with pytest.raises(ValueError, match="stages"):
        FPAdd(FP24, 10, target="virtex4")
    assert fp_add_latency(FP32) == 6          # the generic adder takes every format


# -- synthesis --------------------------------------------------------------------------------

def test_fp16_synthesises_to_two_dsp48_and_fewer_luts(tmp_path):
    """Fresh Yosys runs (``synth_xilinx -family xc4v``): two DSP48, and fewer LUTs, slices
    and path cells than the generic adder of the same format."""
    from raplas_hdl.synth.report import adder_option_rows

    generic, v4 = adder_option_rows([FP16], ("rtz",), cache_dir=tmp_path)
    assert (generic["target"], v4["target"]) == ("generic", "virtex4")
    assert not v4["cached"] and (generic["dsp48"], v4["dsp48"]) == (0, 2), v4["cells_by_type"]
    assert v4["latency"] == LATENCY and generic["latency"] == 6
    assert v4["luts"] < generic["luts"] and v4["slices_est"] < generic["slices_est"]
    assert v4["path_cells"] < generic["path_cells"]
    assert adder_option_rows([FP32], ("rtz",), cached_only=True) == []   # does not fit


def test_cli_synth_fp_add_target(tmp_path, capsys, monkeypatch):
    from raplas_hdl.cli import main

    monkeypatch.setenv("RAPLAS_BUILD", str(tmp_path))
    out = tmp_path / "add.md"
    assert main(["synth", "fp-add", "--target", "virtex4", "--format", "E4M3",
                 "-o", str(out)]) == 0
    text = out.read_text()
    assert "| fp-add (target=virtex4) | E4M3 | rtz | 7 | 2 |" in text
    capsys.readouterr()
    assert main(["synth", "fp-add", "--target", "xc7"]) == 2
    assert "target must be one of generic, virtex4" in capsys.readouterr().err
    assert main(["synth", "fp-add", "--target", "virtex4", "--format", "FP32"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("raplas-hdl synth: error: the DSP48 adder") and "not 24" in err
    assert len(err.strip().splitlines()) == 1


def test_dsp48_helper_refuses_wide_operands():
    from raplas_hdl.rtl.dsp48 import dsp48

    m = Module()
    with pytest.raises(ValueError, match="operand a has 18 bits; at most 17"):
        dsp48(m, "d", Const(0, 18), Const(0, 4), en=Const(1, 1))
    with pytest.raises(ValueError, match="addend c has 48 bits; at most 47"):
        dsp48(m, "d", Const(0, 4), Const(0, 4), en=Const(1, 1), c=Const(0, 48))
