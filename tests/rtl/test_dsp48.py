"""The Virtex-4 DSP48 multiplier against the inferred multiply, under Icarus with Yosys's model.

One top holds :class:`DSP48Mul` (``DSP48`` primitives, simulated with the ``DSP48`` module of
Yosys's ``share/xilinx/cells_sim.v``) and :class:`PipelinedMul` (inferred ``a * b``); the
cocotb TB (:mod:`raplas_hdl.sim.tb.dsp48`) drives random operands (edge values first) with random
clock-enable stalls, and every cycle's outputs are compared with each other and with a
Python model of the pipeline. The synthesis test checks that the DSP48 version leaves no
flip-flop of the multiply in the fabric.
"""

import numpy as np
import pytest
from amaranth.back import verilog
from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from raplas_hdl.rtl.dsp48 import (DSP48Mul, PipelinedMul, dsp48_count, dsp48_sim_model,
                                  make_multiplier, multiplier_latency)
from raplas_hdl.synth.yosys import synthesize
from raplas_hdl.sim.build.runner import run_cocotb


class _Pair(wiring.Component):
    def __init__(self, width):
        self._w = width
        super().__init__({"a": In(width), "b": In(width), "en": In(1),
                          "p_dsp": Out(2 * width), "p_ref": Out(2 * width)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.dsp = dsp = DSP48Mul(self._w)
        m.submodules.ref = ref = PipelinedMul(self._w)
        self.latencies = (dsp.latency, ref.latency)
        for unit in (dsp, ref):
            m.d.comb += [unit.a.eq(self.a), unit.b.eq(self.b), unit.en.eq(self.en)]
        m.d.comb += [self.p_dsp.eq(dsp.p), self.p_ref.eq(ref.p)]
        return m


def _vectors(width, n, seed):
    rng = np.random.default_rng(seed)
    top = (1 << width) - 1
    edge = [0, 1, top, top - 1, 1 << (width - 1), (1 << (width - 1)) - 1]
    ea, eb = np.meshgrid(edge, edge)
    a = np.concatenate([ea.ravel(), rng.integers(0, top + 1, n)]).astype(np.uint64)
    b = np.concatenate([eb.ravel(), rng.integers(0, top + 1, n)]).astype(np.uint64)
    en = np.concatenate([np.ones(ea.size), rng.random(n) < 0.7]).astype(np.uint8)
    en[-8:] = 1                                  # flush the pipeline at the end
    return a, b, en


def _model(a, b, en, latency):
    pipe, out = [0] * latency, []
    for x, y, e in zip(a.tolist(), b.tolist(), en.tolist()):
        if e:
            pipe = [int(x) * int(y)] + pipe[:-1]
        out.append(pipe[-1])
    return out


@pytest.mark.parametrize("width", [17, 24, 11])
def test_dsp48_multiplier_bit_exact_under_icarus(width, tmp_path):
    top = _Pair(width)
    text = verilog.convert(top, name="dsp48_pair", emit_src=False) + dsp48_sim_model()
    a, b, en = _vectors(width, 400, seed=width)
    np.savez(tmp_path / "in.npz", a=a, b=b, en=en)
    out = tmp_path / "out.npz"
    run_cocotb("icarus", text, "dsp48_pair", "raplas_hdl.sim.tb.dsp48", f"dsp48_pair-w{width}",
               env={"RAPLAS_TB_IN": tmp_path / "in.npz", "RAPLAS_TB_OUT": out})
    res = np.load(out)
    p_dsp = [int(x) for x in res["p_dsp"]]
    p_ref = [int(x) for x in res["p_ref"]]
    latency = multiplier_latency(width)
    assert top.latencies == (latency, latency)
    want = _model(a, b, en, latency)
    assert len(p_dsp) == len(want)
    bad = [i for i in range(len(want)) if p_dsp[i] != p_ref[i]]
    assert not bad, f"DSP48 and inferred multiply differ at cycles {bad[:10]}"
    bad = [i for i in range(len(want)) if p_dsp[i] != want[i]]
    assert not bad, f"DSP48 product wrong at cycles {bad[:10]}"
    assert sum(1 for x in want if x) > 300       # the comparison saw real products


def test_latency_dsp_count_and_targets():
    assert (multiplier_latency(17), multiplier_latency(24)) == (3, 4)
    assert (dsp48_count(17), dsp48_count(24)) == (1, 4)
    v4 = verilog.convert(make_multiplier(17, "virtex4"), name="m", emit_src=False)
    generic = verilog.convert(make_multiplier(17, "generic"), name="m", emit_src=False)
    assert "DSP48 " in v4 and "DSP48" not in generic
    with pytest.raises(ValueError, match="target"):
        make_multiplier(17, "virtex7")
    with pytest.raises(ValueError, match="width"):
        multiplier_latency(35)


def test_dsp48_multiplier_keeps_its_registers_inside(tmp_path):
    text = verilog.convert(DSP48Mul(17), name="dsp48_mul", emit_src=False)
    r = synthesize(text, "dsp48_mul", cache_dir=tmp_path)
    assert r.dsp48 == 1
    assert r.ffs == 0 and r.luts == 0, r.cells_by_type
