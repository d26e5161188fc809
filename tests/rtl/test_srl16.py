# amaranth: UnusedElaboratable=no
"""Delay lines in Virtex-4 ``SRL16E`` primitives (issue 15, item 4).

:func:`raplas_hdl.rtl.pipeline.delay` with ``srl`` puts the stages of a reset-less delay line
into ``SRL16E`` primitives (16 stages per bit each, the last stage a flip-flop); the
ray-triangle unit does so for its long delay lines with the DSP48 adders. Checked here:

* the split of a delay into ``SRL16E`` pieces and flip-flops, and the errors for a bad ``srl``;
* the generic target and the DSP48 multipliers alone emit no ``SRL16E`` (their Verilog is
  unchanged); the DSP48-adder ray-triangle unit emits the expected number, all of 16 stages;
* every cycle, delay lines of 1 to 50 stages with ``SRL16E`` pieces of every address against
  flip-flop lines and a list model, under random clock-enable stalls, with Yosys's
  ``SRL16E`` model: 1,500 cycles under Icarus, 20,000 under Verilator (``full``);
* (in ``tests/rtl/test_dsp48_adder_units.py``: the ray-triangle unit with DSP48 multipliers and
  adders, so with its ``SRL16E`` delay lines, against the golden model, every output field,
  with input gaps and output back-pressure);
* Yosys keeps the ``SRL16E`` cells and the slice estimate counts each as one LUT site.
"""

import numpy as np
import pytest
from amaranth.back import verilog
from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from raplas_hdl.fp import FP24
from raplas_hdl.rtl.dsp48 import dsp48_sim_model
from raplas_hdl.rtl.pipeline import SRL_STAGES, Delay, delay, srl_split
from raplas_hdl.rtl.ray_triangle import RayTriangleUnit
from raplas_hdl.sim.build.runner import require_simulator, run_cocotb

V4 = "virtex4"


# -- the split and the parameters ------------------------------------------------------------

@pytest.mark.parametrize("cycles, srl, pieces, ffs", [
    (0, 16, (), 0), (1, 1, (), 1), (2, 1, (1,), 1), (2, 2, (), 2), (7, 16, (), 7),
    (16, 16, (), 16), (17, 16, (16,), 1), (18, 16, (16,), 2), (25, 8, (16, 8), 1),
    (25, 9, (16,), 9), (43, 16, (16, 16), 11), (43, 10, (16, 16, 10), 1), (43, 0, (), 43),
    (33, 1, (16, 16), 1), (34, 1, (16, 16, 1), 1),
])
def test_srl_split(cycles, srl, pieces, ffs):
    assert srl_split(cycles, srl) == (pieces, ffs)
    assert sum(pieces) + ffs == cycles and all(1 <= p <= SRL_STAGES for p in pieces)


@pytest.mark.parametrize("bad", [-1, 17, 1.5, True, None, "16"])
def test_bad_srl_names_the_option(bad):
    with pytest.raises(ValueError, match="srl must be an integer from 0 to 16"):
        srl_split(20, bad)
    with pytest.raises(ValueError, match="srl must be an integer from 0 to 16"):
        delay(Module(), 0, 20, srl=bad)
    with pytest.raises(ValueError, match="srl must be an integer from 0 to 16"):
        Delay(8, 20, srl=bad)
    if bad is not None:                             # None: the unit's default
        with pytest.raises(ValueError, match="srl must be an integer from 0 to 16"):
            RayTriangleUnit(FP24, adder=V4, srl=bad)


def test_delay_with_reset_stays_flip_flops():
    m = Module()
    out = delay(m, 0, 40, srl=1, reset_less=False, name="valid")
    assert out.name == "valid_40" and not m._named_submodules
    m = Module()
    assert delay(m, 0, 40, srl=1, name="data").name == "data_40"
    assert len(m._named_submodules) == 3       # pieces of 16, 16 and 7 stages, one bit each


def _rt_verilog(**kw):
    return verilog.convert(RayTriangleUnit(FP24, **kw), name="rt", emit_src=False)


def test_which_ray_triangle_units_use_srl16():
    assert RayTriangleUnit(FP24).srl == 0 and RayTriangleUnit(FP24, multiplier=V4).srl == 0
    assert RayTriangleUnit(FP24, adder=V4).srl == 16
    assert RayTriangleUnit(FP24, adder=V4, srl=0).srl == 0
    text = _rt_verilog(adder=V4, multiplier=V4)
    # decision cycle 43: the IDs (2 x 16 bits) wait 43 cycles = 2 SRL16E + 11 flip-flops;
    # the operand lines of 18 (168 bits) and 25 cycles (24 bits) take one SRL16E per bit
    assert text.count("SRL16E ") == 2 * 32 + 168 + 24
    # every piece is a full one: address 15
    assert text.count(".A0(1'h1)") == text.count(".A3(1'h1)") == text.count("SRL16E ")


# -- delay lines against flip-flops and a list model, every cycle -----------------------------

#: (cycles, srl) of the delay lines of the test top: a piece of every SRL16E length (1 to 16
#: stages: addresses 0 to 15), chains of one to three pieces, remainders left to flip-flops.
LINES = [(c, 1) for c in range(1, 18)] + [(17, 16), (18, 2), (24, 8), (33, 1), (34, 1),
                                          (43, 16), (50, 3)]
WIDTH = 5


class _Lines(wiring.Component):
    def __init__(self):
        ports = {"i": In(WIDTH), "en": In(1)}
        for cycles, srl in LINES:
            ports[f"o_srl_{cycles}_{srl}"] = Out(WIDTH)
            ports[f"o_ff_{cycles}_{srl}"] = Out(WIDTH)
        super().__init__(ports)

    def elaborate(self, platform):
        m = Module()
        for cycles, srl in LINES:
            for kind, s in (("srl", srl), ("ff", 0)):
                m.submodules[f"{kind}_{cycles}_{srl}"] = d = Delay(WIDTH, cycles, srl=s)
                m.d.comb += [d.i.eq(self.i), d.en.eq(self.en),
                             getattr(self, f"o_{kind}_{cycles}_{srl}").eq(d.o)]
        return m


def _model(data, en, cycles):
    line, out = [0] * cycles, []
    for x, e in zip(data, en):
        if e and cycles:
            line = [int(x)] + line[:-1]
        out.append(line[-1] if cycles else int(x))
    return out


def check_lines(simulator, tmp_path, n=1500, seed=3):
    require_simulator(simulator)
    text = verilog.convert(_Lines(), name="srl_lines", emit_src=False)
    n_srl = sum(WIDTH * len(srl_split(c, s)[0]) for c, s in LINES)
    assert text.count("SRL16E ") == n_srl
    assert {p for c, s in LINES for p in srl_split(c, s)[0]} == set(range(1, SRL_STAGES + 1))
    rng = np.random.default_rng(seed)
    data = rng.integers(0, 1 << WIDTH, n)
    en = (rng.random(n) < 0.6).astype(np.uint8)      # stalls 40 % of the cycles
    en[:60] = 1                                      # a run at full rate first
    np.savez(tmp_path / "in.npz", i=data, en=en)
    ports = [p for c, s in LINES for p in (f"o_srl_{c}_{s}", f"o_ff_{c}_{s}")]
    run_cocotb(simulator, text + dsp48_sim_model(), "srl_lines", "raplas_hdl.sim.tb.srl16",
               "srl_lines", env={"RAPLAS_TB_IN": tmp_path / "in.npz",
                                 "RAPLAS_TB_OUT": tmp_path / "out.npz",
                                 "RAPLAS_TB_PORTS": ",".join(ports)})
    got = np.load(tmp_path / "out.npz")
    for cycles, srl in LINES:
        want = _model(data.tolist(), en.tolist(), cycles)
        for kind in ("srl", "ff"):
            seen = got[f"o_{kind}_{cycles}_{srl}"].tolist()
            bad = [k for k in range(n) if seen[k] != want[k]]
            assert not bad, f"{kind} line of {cycles} (srl={srl}) wrong at cycles {bad[:10]}"
    assert len(set(got[f"o_srl_{LINES[-1][0]}_{LINES[-1][1]}"].tolist())) > 1


def test_srl16_lines_equal_flip_flop_lines_icarus(tmp_path):
    check_lines("icarus", tmp_path)


@pytest.mark.full
def test_srl16_lines_equal_flip_flop_lines_verilator(tmp_path):
    check_lines("verilator", tmp_path, n=20_000, seed=4)


# -- synthesis: the SRL16E cells are kept and counted ----------------------------------------

def test_yosys_counts_srl16_as_lut_sites(tmp_path):
    from raplas_hdl.synth.yosys import synthesize

    text = verilog.convert(Delay(6, 20, srl=16), name="dly", emit_src=False)
    r = synthesize(text, "dly", cache_dir=tmp_path)
    # 6 bits x (one SRL16E of 16 stages + 4 flip-flops)
    assert r.cells_by_type.get("SRL16E") == 6 and r.lutram == 6 and r.ffs == 6 * 4
    assert r.slices_est == 12 and r.luts == 0       # ceil(max(0 + 6, 24) / 2)
    assert r.path_cells <= 1
