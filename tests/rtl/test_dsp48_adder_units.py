# amaranth: UnusedElaboratable=no
"""The DSP48 adder inside the units (issue 15, point 1's remainder): ``adder="virtex4"``.

Every unit built from FP adders (the plane-sphere tester and array, the ray-triangle unit in
all its modes, the intersection unit, the board top) takes ``adder`` beside ``multiplier``;
``raplas-hdl verilog``/``cosim`` take it as ``--adder``. The two-DSP48 adder has latency 7
instead of 4, so every schedule (the delay lines that meet the adders' results) moves.
Checked here:

* the stated latencies against ``fp_add_latency`` and the errors for a bad adder, in Python;
* the option reaches every adder (DSP48 instances in the emitted Verilog);
* co-simulation against the golden model, every output field of every case: the ray-triangle
  unit with DSP48 adders under Icarus (and with both targets, its long delay lines in
  ``SRL16E`` and its output FIFO in block RAM: 300 pairs under Icarus, more under both
  simulators as ``full`` tests), a time-shared plane-sphere array with DSP48 adders and
  multipliers under Verilator, a small whole intersection unit with both targets under Icarus
  (results and counters against the model, and its ``cycles`` against the cycle model)
  (make test); the conservative and certified ray-triangle unit and the whole intersection
  unit under Verilator as ``full`` tests.
"""

import gc
import json

import pytest

from raplas_hdl.cli import main
from raplas_hdl.fp import FP24
from raplas_hdl.rtl.fp_add import fp_add_latency
from raplas_hdl.rtl.plane_sphere import PlaneSphereArray, PlaneSphereTester
from raplas_hdl.rtl.ray_triangle import RayTriangleUnit
from raplas_hdl.sim.build.runner import require_simulator

V4 = "virtex4"


# -- latency and parameters ---------------------------------------------------------------

def test_adder_latency_is_seven_for_virtex4():
    assert fp_add_latency(FP24, 4, V4) == 7 and fp_add_latency(FP24, 4) == 4
    assert fp_add_latency(FP24, 2, V4) == 7 and fp_add_latency(FP24, 2) == 2


@pytest.mark.parametrize("mul, add, tester, array, paper, conservative", [
    ("generic", "generic", 17, 19, 41, 47),     # the generic adder: 6 stages at FP24 rtz
    (V4, "generic", 18, 20, 43, 49),
    # La = 7: tester Lm + 2 La + 1, unit 5 La + 2 Lm + 3 (+ 1: the output FIFO in block RAM)
    ("generic", V4, 19, 21, 47, 54),
    (V4, V4, 20, 22, 49, 56),
])
def test_units_follow_the_adder_latency(mul, add, tester, array, paper, conservative):
    t = PlaneSphereTester(FP24, multiplier=mul, adder=add)
    a = PlaneSphereArray(FP24, rows=4, cols=4, multiplier=mul, adder=add)
    assert (t.latency, t.adder, a.tester_latency, a.latency) == (tester, add, tester, array)
    assert a.fifo_depth == array + 2
    for mode, lat in (("paper", paper), ("conservative", conservative)):
        u = RayTriangleUnit(FP24, mode=mode, multiplier=mul, adder=add)
        assert (u.latency, u.adder, u.fifo_depth) == (lat, add, lat + 1)
    # certified: the decision waits for the last bound, three cycles after the last
    # operation (w): the register of w's rounding term, then the two halves of a bound add
    cert = RayTriangleUnit(FP24, mode="certified", multiplier=mul, adder=add)
    assert cert.latency == conservative + 3


def test_bad_adder_names_the_option():
    from raplas_hdl.rtl.intersection import IntersectionUnit

    makers = (lambda a: PlaneSphereTester(FP24, adder=a),
              lambda a: PlaneSphereArray(FP24, rows=2, cols=2, adder=a),
              lambda a: RayTriangleUnit(FP24, adder=a),
              lambda a: IntersectionUnit(rows=2, cols=2, adder=a))
    for make, bad in zip(makers * 2, ("virtex7", "", None, "VIRTEX4", "xc7", 4, "dsp", " ")):
        with pytest.raises(ValueError, match="adder must be one of generic, virtex4"):
            make(bad)


@pytest.mark.filterwarnings("ignore:.*created but never used")
def test_fp32_refuses_the_dsp48_adder():
    from raplas_hdl.fp import FP32

    with pytest.raises(ValueError, match="at most 17 bits"):
        RayTriangleUnit(FP32, adder=V4)


@pytest.mark.filterwarnings("ignore:.*created but never used")
def test_every_adder_is_two_dsp48():
    from amaranth.back import verilog

    from raplas_hdl.rtl.intersection import IntersectionUnit, build_intersection_unit

    tester = verilog.convert(PlaneSphereTester(FP24, adder=V4), name="t", emit_src=False)
    assert tester.count("DSP48 ") == 3 * 2            # generic multiplies stay inferred
    both = verilog.convert(PlaneSphereTester(FP24, multiplier=V4, adder=V4), name="t",
                           emit_src=False)
    assert both.count("DSP48 ") == 3 * 2 + 3
    unit = IntersectionUnit(rows=1, cols=2, adder=V4)
    psa, rtu = unit._subunits()
    psa._MustUse__silence = rtu._MustUse__silence = True    # built only to be inspected
    assert (unit.adder, psa.adder, rtu.adder, unit.multiplier) == (V4, V4, V4, "generic")
    assert (psa.tester_latency, rtu.latency) == (19, 47)
    built = build_intersection_unit(FP24, adder=V4, rows=2)
    built._MustUse__silence = True
    assert built.adder == V4
    # the board top hands it to its unit
    from raplas_hdl.rtl.board_top import build_board_top

    top = build_board_top(FP24, adder=V4, rows=2, cols=2, max_triangles=64, max_spheres=16)
    inner = top.elaborate(None)._named_submodules["unit"][0]
    assert (inner.adder, inner.multiplier) == (V4, "generic")


@pytest.mark.filterwarnings("ignore:.*created but never used")
def test_cli_adder_option_and_manifest(tmp_path, capsys):
    out = tmp_path / "t.v"
    assert main(["verilog", "plane-sphere-tester", "--adder", V4, "--target", V4,
                 "-o", str(out)]) == 0
    man = json.loads(out.with_suffix(".json").read_text())
    assert man["latency"] == 20
    assert (man["parameters"]["adder"], man["parameters"]["target"]) == (V4, V4)
    assert out.read_text().count("DSP48 ") >= 9
    gen = tmp_path / "g.v"
    assert main(["verilog", "plane-sphere-tester", "-o", str(gen)]) == 0
    assert json.loads(gen.with_suffix(".json").read_text())["parameters"]["adder"] == "generic"
    capsys.readouterr()
    assert main(["verilog", "fp-mul", "--adder", V4, "-o", str(tmp_path / "x.v")]) == 2
    assert "--adder does not apply to unit fp-mul" in capsys.readouterr().err
    assert main(["verilog", "ray-triangle", "--adder", "xc7", "-o", str(tmp_path / "y.v")]) == 2
    assert "adder must be one of generic, virtex4" in capsys.readouterr().err
    assert main(["verilog", "ray-triangle", "--adder", V4, "--format", "FP32",
                 "-o", str(tmp_path / "z.v")]) == 2
    assert "at most 17 bits" in capsys.readouterr().err
    gc.collect()     # the refused unit's warning falls under this test's filter


# -- co-simulation against the golden model ------------------------------------------------

def _cosim(capsys, *argv):
    """Run ``raplas-hdl cosim`` and return its report; it exits 0 only with no mismatch."""
    capsys.readouterr()
    code = main(["cosim", *argv])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "mismatches: 0" in text
    return text


def test_cli_cosim_fp_add_target_virtex4(capsys):
    """``cosim fp-add --target virtex4``: the DSP48 adder through the batch harness."""
    require_simulator("icarus")
    text = _cosim(capsys, "fp-add", "--sim", "icarus", "--target", V4, "--random", "2000",
                  "--format", "FP24/rne", "--stall-density", "0.3")
    assert "latency 7" in text and "cases: 2000" in text


def test_ray_triangle_dsp48_adders_under_icarus(capsys):
    """FP24 rne, paper mode, every adder on two DSP48: 300 pairs (gaps and back-pressure),
    every output field against the model."""
    require_simulator("icarus")
    text = _cosim(capsys, "ray-triangle", "--sim", "icarus", "--adder", V4,
                  "--format", "FP24/rne", "--random", "300", "--seed", "5",
                  "--valid-density", "0.8", "--stall-density", "0.2")
    assert "latency 49" in text and "cases: 300" in text   # rne: multipliers of 5 stages


def test_plane_sphere_array_dsp48_adders_under_verilator(capsys):
    """A time-shared array (2x3 planes on 2 testers, 3 passes) with DSP48 adders and
    multipliers: the plane slot, radius and ID delay lines must meet 19-cycle testers."""
    require_simulator("verilator")
    text = _cosim(capsys, "plane-sphere", "--sim", "verilator", "--rows", "2", "--cols", "3",
                  "--testers", "2", "--adder", V4, "--target", V4, "--random", "200")
    assert "latency 24" in text and "cases: 200" in text


def test_ray_triangle_srl16_under_icarus(capsys):
    """FP24 rtz, paper mode, DSP48 multipliers and adders, so the delay lines of 17 stages
    and more in SRL16E (``tests/rtl/test_srl16.py``): 300 pairs with input gaps and output
    back-pressure, every output field against the model."""
    require_simulator("icarus")
    text = _cosim(capsys, "ray-triangle", "--sim", "icarus", "--target", V4, "--adder", V4,
                  "--format", "FP24/rtz", "--random", "300", "--seed", "11",
                  "--valid-density", "0.7", "--stall-density", "0.3")
    assert "latency 49" in text and "cases: 300" in text


@pytest.mark.full
@pytest.mark.parametrize("simulator, n", [("icarus", 4000), ("verilator", 30000)])
def test_ray_triangle_srl16_many_pairs(capsys, simulator, n):
    require_simulator(simulator)
    text = _cosim(capsys, "ray-triangle", "--sim", simulator, "--target", V4, "--adder", V4,
                  "--format", "FP24/rtz", "--random", str(n), "--seed", "12",
                  "--valid-density", "0.8", "--stall-density", "0.2")
    assert f"cases: {n}" in text


@pytest.mark.full
@pytest.mark.parametrize("mode", ["conservative", "certified"])
def test_ray_triangle_dsp48_adders_modes_under_verilator(capsys, mode):
    require_simulator("verilator")
    text = _cosim(capsys, "ray-triangle", "--sim", "verilator", "--adder", V4, "--target", V4,
                  "--mode", mode, "--random", "3000", "--seed", "9")
    assert "cases: 3000" in text


@pytest.mark.full
def test_intersection_unit_dsp48_adders_under_verilator(capsys):
    """The whole unit with DSP48 adders and multipliers: every beat of every run and the
    counters against the transaction-level model."""
    require_simulator("verilator")
    text = _cosim(capsys, "intersection-unit", "--sim", "verilator", "--adder", V4,
                  "--target", V4, "--random", "40")
    assert "cases: 40" in text


def test_intersection_unit_cycles_equal_model_with_bram_fifo():
    """The whole unit with DSP48 adders and multipliers (so the ray-triangle unit's output
    FIFO in block RAM, one cycle more): under Icarus with back-pressure every result bit and
    counter against the golden model; without it, every run's ``cycles`` counter equals the
    cycle model's (:mod:`raplas_hdl.model.throughput`, the unit's own ``cycle_timing``)."""
    import dataclasses

    from tests.support.unit_scenes import check_against_model, scene_and_runs

    from raplas_hdl.model.config import UnitConfig
    from raplas_hdl.model.throughput import profile_runs, simulate
    from raplas_hdl.rtl.intersection import IntersectionUnit
    from raplas_hdl.sim.drive.unit_harness import UnitSession

    require_simulator("icarus")
    cfg = UnitConfig(fmt=FP24, rows=2, cols=2, testers=2, tris_per_sphere=4,
                     max_triangles=256, max_spheres=128, fifo_depth=8)
    unit = IntersectionUnit(dataclasses.replace(cfg), adder=V4, multiplier=V4)
    unit._MustUse__silence = True                     # built only to be inspected
    tm = unit.cycle_timing()
    assert tm.rt_latency == 49 and tm.rt_fifo_depth == 50
    scene, runs = scene_and_runs(cfg, 40, seed=6)
    kw = dict(build_key="bram-fifo-test", adder=V4, multiplier=V4)
    with UnitSession("icarus", cfg, scene, seed=2, ready_density=0.6, **kw) as s:
        check_against_model(cfg, scene, runs, s.run(runs))
    with UnitSession("icarus", cfg, scene, ready_density=1.0, **kw) as s:
        res = s.run(runs)
    check_against_model(cfg, scene, runs, res)
    t_cmd, t_last = simulate(profile_runs(cfg, scene, runs), cfg, tm, overlap=False)
    assert [ctr["cycles"] for _, ctr in res] == [int(x) for x in t_last - t_cmd]
