# amaranth: UnusedElaboratable=no
"""The Virtex-4 target option (issue 6, point 4): ``DSP48`` multipliers inside the FP units.

``FPMul(fmt, multiplier="virtex4")`` replaces the combinational significand multiply with
:class:`~raplas_hdl.rtl.dsp48.DSP48Mul` (AREG/BREG, MREG, PREG in use), and every unit built
from FPMul takes the same option. Checked here:

* the stated latencies (FP24: multiplier 4 instead of 3, tester 13, ray-triangle 30) and the
  errors for a bad target, in Python;
* FP24 FPMul in ``rtz`` and ``rne``, generic and virtex4 side by side in one batch-harness
  DUT (:func:`raplas_hdl.sim.cosim.fp.fp_bundle`), under Icarus and Verilator with Yosys's
  ``DSP48`` model:
  every result bit and flag against :mod:`raplas_hdl.fp.model`, with random gaps and
  clock-enable stalls. The bundle delays each unit to the longest *stated* latency, so
  every unit valid on every beat proves that the virtex4 unit's ``latency`` is its true one
  and that it stalls and flags ``o_valid`` exactly like the generic unit;
* the whole ray-triangle unit built with virtex4 multipliers under Icarus (cocotb, gaps and
  back-pressure) against :func:`raplas_hdl.model.ray_triangle.intersect`, and its measured
  latency against ``latency``;
* Yosys synthesis of FP24 FPMul virtex4: exactly one DSP48;
* ``raplas-hdl verilog --target`` and its manifest.
"""

import json

import numpy as np
import pytest

from raplas_hdl.cli import main
from raplas_hdl.fp import FP16, FP24, FP32
from raplas_hdl.rtl.dsp48 import dsp48_sim_model
from raplas_hdl.rtl.fp_mul import FPMul, fp_mul_latency
from raplas_hdl.rtl.plane_sphere import PlaneSphereArray, PlaneSphereTester
from raplas_hdl.rtl.ray_triangle import RayTriangleUnit
from raplas_hdl.sim.build.harness import run_batch
from raplas_hdl.sim.build.runner import require_simulator, run_cocotb
from raplas_hdl.sim.cosim.fp import check_bundle, fp_bundle, fp_expected
from raplas_hdl.sim.tb.ray_triangle import read_payloads, write_payloads
from tests.support.fp_vectors import fp24_vectors
from tests.support.ray_triangle import compare, expected, pack_inputs, unpack_outputs

# Faster C++ build of the harness (as in test_ray_triangle_cocotb): one file, no optimisation.
VERILATOR_ARGS = ("--output-split", "0", "-CFLAGS", "-O0")


# -- latency and parameters ---------------------------------------------------------------

@pytest.mark.parametrize("fmt, stages, latency", [
    (FP24, 3, 4), (FP24, 1, 4), (FP24, 2, 4), (FP24, 4, 5), (FP24, 5, 6),
    (FP16, 3, 4), (FP32, 3, 5),            # FP32: four DSP48 and a limb sum, one more
])
def test_virtex4_latency(fmt, stages, latency):
    unit = FPMul(fmt, stages, multiplier="virtex4")
    assert unit.latency == latency == fp_mul_latency(fmt, stages, "virtex4")
    assert len(unit.stage_steps) == latency
    assert unit.stage_steps[0] == ("unpack",) and unit.stage_steps[-1][-1] == "pack"
    assert FPMul(fmt, stages).latency == stages == fp_mul_latency(fmt, stages)


def test_units_follow_the_multiplier_latency():
    assert PlaneSphereTester(FP24).latency == 17
    assert PlaneSphereTester(FP24, multiplier="virtex4").latency == 18
    generic = PlaneSphereArray(FP24, rows=4, cols=4)
    v4 = PlaneSphereArray(FP24, rows=4, cols=4, multiplier="virtex4")
    assert (v4.latency, v4.tester_latency) == (generic.latency + 1, 18)
    assert v4.fifo_depth == generic.fifo_depth + 1
    # ray-triangle: two multiplies on the critical path
    for mode, lat in (("paper", 41), ("conservative", 47)):
        assert RayTriangleUnit(FP24, mode=mode).latency == lat
        assert RayTriangleUnit(FP24, mode=mode, multiplier="virtex4").latency == lat + 2
    assert RayTriangleUnit(FP32, multiplier="virtex4").latency == 45


@pytest.mark.parametrize("make", [
    lambda t: FPMul(FP24, multiplier=t),
    lambda t: PlaneSphereTester(FP24, multiplier=t),
    lambda t: PlaneSphereArray(FP24, rows=2, cols=2, multiplier=t),
    lambda t: RayTriangleUnit(FP24, multiplier=t),
], ids=["fp-mul", "tester", "array", "ray-triangle"])
def test_bad_multiplier_names_the_option(make):
    from raplas_hdl.rtl.intersection import IntersectionUnit

    for bad in ("virtex7", "", None, "VIRTEX4"):
        with pytest.raises(ValueError, match="multiplier must be one of generic, virtex4"):
            make(bad)
    with pytest.raises(ValueError, match="multiplier must be one of"):
        IntersectionUnit(rows=2, cols=2, multiplier="xc7")


def test_verilog_instantiates_dsp48_per_multiply():
    from amaranth.back import verilog

    from raplas_hdl.rtl.intersection import IntersectionUnit, build_intersection_unit

    v4 = verilog.convert(FPMul(FP24, multiplier="virtex4"), name="fp_mul", emit_src=False)
    generic = verilog.convert(FPMul(FP24), name="fp_mul", emit_src=False)
    assert v4.count("DSP48 ") == 1 and "DSP48" not in generic
    assert " * " in generic and " * " not in v4          # no inferred multiply left
    # the intersection unit hands the option to both subunits (converting the whole unit
    # to Verilog takes about 20 s: the subunits' own Verilog is checked elsewhere)
    unit = IntersectionUnit(rows=1, cols=2, multiplier="virtex4")
    psa, rtu = unit._subunits()
    psa._MustUse__silence = rtu._MustUse__silence = True    # built only to be inspected
    assert (unit.multiplier, psa.multiplier, rtu.multiplier) == ("virtex4",) * 3
    assert (psa.tester_latency, rtu.latency) == (18, 43)
    built = build_intersection_unit(FP24, multiplier="virtex4", rows=2)
    built._MustUse__silence = True
    assert built.multiplier == "virtex4"
    tester = verilog.convert(PlaneSphereTester(FP24, multiplier="virtex4"), name="t",
                             emit_src=False)
    assert tester.count("DSP48 ") == 3


# -- FPMul under cocotb --------------------------------------------------------------------

@pytest.mark.parametrize("simulator, n", [("icarus", 12_000), ("verilator", 100_000)])
def test_fp24_fpmul_virtex4_bit_exact(simulator, n):
    """Generic and virtex4 FPMul, rtz and rne, in one DUT against the model, with stalls."""
    require_simulator(simulator)
    targets = ("generic", "virtex4")
    spec, text, units = fp_bundle(7, 16, ("rtz", "rne"), ops=("fp-mul",),
                                  multipliers=targets)
    assert set(units) == {"mul_rtz", "mul_rne", "mul_rtz_virtex4", "mul_rne_virtex4"}
    assert text.count("\nmodule DSP48 (") == 1 and text.count("DSP48 ") >= 2
    a, b, _ = fp24_vectors(n, seed=48 + len(simulator))
    out, info = run_batch(simulator, spec, text, f"fp_mul_{'_'.join(targets)}-e7m16",
                          {"a": a, "b": b},
                          valid_density=0.7, stall_density=0.25, seed=13, timeout_s=900,
                          build_args=VERILATOR_ARGS if simulator == "verilator" else ())
    msgs = check_bundle(units, out, a, b)
    assert not msgs, f"{simulator}:\n" + "\n".join(msgs)
    assert info["cycles"] > 1.5 * a.size        # gaps and stalls happened
    # the operands reached the interesting results: specials, overflow, underflow, invalid
    from raplas_hdl.fp import model
    _, flags = model.mul(a, b, FP24, flags=True)
    assert all(np.any(flags & f) for f in (1, 2, 4))


def test_fp32_fpmul_virtex4_four_dsp48_under_icarus():
    """FP32: 24-bit significands on four DSP48 and a limb sum (latency 5), rtz and rne."""
    require_simulator("icarus")
    from tests.support.fp_vectors import special_values

    spec, text, units = fp_bundle(8, 23, ("rtz", "rne"), ops=("fp-mul",),
                                  multipliers=("generic", "virtex4"))
    assert text.count("DSP48 ") >= 8
    rng = np.random.default_rng(32)
    sp = special_values(FP32)
    ga, gb = np.meshgrid(sp, sp)
    a = rng.integers(0, 1 << 32, 4000, dtype=np.uint64).astype(np.uint32)
    b = rng.integers(0, 1 << 32, 4000, dtype=np.uint64).astype(np.uint32)
    b[::3] = (a[::3] ^ rng.integers(0, 1 << 12, a[::3].size, dtype=np.uint32)) & 0x3FFFFFFF
    a = np.concatenate([ga.ravel(), a]).astype(np.uint32)
    b = np.concatenate([gb.ravel(), b]).astype(np.uint32)
    out, info = run_batch("icarus", spec, text, "fp_mul_generic_virtex4-e8m23",
                          {"a": a, "b": b}, valid_density=0.7, stall_density=0.25, seed=5,
                          timeout_s=600)
    msgs = check_bundle(units, out, a, b)
    assert not msgs, "\n".join(msgs)
    assert info["cycles"] > 1.5 * a.size


def test_bundle_check_catches_a_wrong_virtex4_result():
    """The comparison can fail for a virtex4 unit, and says which target."""
    units = {"mul_rtz": ("fp-mul", FP24), "mul_rtz_virtex4": ("fp-mul", FP24)}
    a = np.arange(1000, 1064, dtype=np.uint32) << 8
    b = np.full(64, FP24.one, dtype=np.uint32)
    out = {"valids": np.full(64, 3)}
    for suffix, (op, fmt) in units.items():
        out[f"o_{suffix}"], out[f"f_{suffix}"] = fp_expected(op, fmt, a, b)
    assert check_bundle(units, out, a, b) == []
    out["o_mul_rtz_virtex4"] = out["o_mul_rtz_virtex4"] ^ (np.arange(64) == 5)
    msgs = check_bundle(units, out, a, b)
    assert len(msgs) == 1 and "(virtex4): 1 of 64" in msgs[0]
    out["valids"] = np.where(np.arange(64) == 7, 1, 3)      # one unit a beat late or early
    assert "valids" in check_bundle(units, out, a, b)[0]


# -- the ray-triangle unit with DSP48 multipliers --------------------------------------------

def test_ray_triangle_virtex4_under_icarus(tmp_path):
    require_simulator("icarus")
    from raplas_hdl.rtl.emit import emit_verilog

    fmt = FP24.with_rounding("rne")
    unit = RayTriangleUnit(fmt, mode="paper", multiplier="virtex4")
    latency = unit.latency
    text, _ = emit_verilog(unit, "ray_triangle", {"format": fmt.name, "mode": "paper",
                                                  "multiplier": "virtex4"})
    assert text.count("DSP48 ") == 18
    text += dsp48_sim_model()
    count, seed = 400, 41
    vec = _vectors(fmt, count, seed)
    rng = np.random.default_rng(seed)
    ray_ids = rng.integers(0, 1 << 16, count)
    tri_ids = rng.integers(0, 1 << 16, count)
    write_payloads(tmp_path / "in.txt", pack_inputs(fmt, vec, ray_ids, tri_ids))
    out, lat_file = tmp_path / "out.txt", tmp_path / "latency.txt"
    run_cocotb("icarus", text, "ray_triangle", "raplas_hdl.sim.tb.ray_triangle",
               f"ray_triangle-{fmt.name}-paper-virtex4",
               env={"RAPLAS_RT_IN": tmp_path / "in.txt", "RAPLAS_RT_OUT": out,
                    "RAPLAS_RT_IDLE": 0.25, "RAPLAS_RT_STALL": 0.35, "RAPLAS_RT_SEED": seed,
                    "RAPLAS_RT_LATENCY_OUT": lat_file},
               testcase=["test_stream", "test_latency"])
    got = unpack_outputs(fmt, read_payloads(out))
    exp = expected(fmt, vec, ray_ids, tri_ids, "paper")
    compare(got, exp)
    assert 0 < exp["hit"].sum() < count
    assert int(lat_file.read_text()) == latency == 50   # rne: adders of 7, multipliers 5+1


def test_plane_sphere_array_virtex4_under_icarus(tmp_path):
    """A time-shared FP24 array (2x3 planes, 2 testers, 3 passes) with virtex4 multipliers:
    the plane slot and radius delay lines must meet the 4-cycle products."""
    require_simulator("icarus")
    from raplas_hdl.rtl.emit import emit_verilog
    from tests.support.plane_sphere import (ID_BITS, check_beats, expected_beats, make_cases,
                                            unpack_beat, write_stimulus)

    rows, cols, fmt = 2, 3, FP24.with_rounding("rne")
    dut = PlaneSphereArray(fmt, rows=rows, cols=cols, testers=2, sphere_id_bits=ID_BITS,
                           multiplier="virtex4")
    assert (dut.passes, dut.tester_latency, dut.latency) == (3, 21, 25)   # rne: adders of 7 stages
    text, _ = emit_verilog(dut, "plane_sphere", {"rows": rows, "cols": cols, "testers": 2,
                                                  "format": fmt.name, "multiplier": "virtex4"})
    assert text.count("DSP48 ") == 2 * 3
    cases = make_cases(rows, cols, fmt, n_spheres=60, seed=77)
    stim, result = tmp_path / "in.npz", tmp_path / "out.npz"
    write_stimulus(stim, cases, fmt)
    run_cocotb("icarus", text + dsp48_sim_model(), "plane_sphere", "raplas_hdl.sim.tb.plane_sphere",
               f"plane_sphere-{rows}x{cols}-t2-{fmt.name}-virtex4",
               env={"RAPLAS_PS_IN": stim, "RAPLAS_PS_OUT": result})
    got = [unpack_beat(int(v, 16), rows, cols) for v in np.load(result)["results"]]
    want = expected_beats(cases, rows, cols)
    check_beats(got, want)
    assert any(r or c for _, r, c in want) and any(not (r and c) for _, r, c in want)


def _vectors(fmt, count, seed):
    from raplas_hdl.model.stress_cases import vectors

    return vectors(fmt, count, seed)


# -- synthesis and CLI -----------------------------------------------------------------------

def test_fp24_fpmul_virtex4_synthesises_to_one_dsp48(tmp_path):
    from raplas_hdl.synth.report import synth_row

    row = synth_row("fp-mul", FP24, {"target": "virtex4"}, cache_dir=tmp_path)
    assert not row["cached"]
    assert row["dsp48"] == 1, row["cells_by_type"]
    assert row["latency"] == 5 and row["options"]["target"] == "virtex4"
    assert row["ffs"] > 0 and row["luts"] > 0      # the rest of the unit is in the fabric


def test_cli_target_option(tmp_path, capsys):
    v4, gen = tmp_path / "v4.v", tmp_path / "gen.v"
    assert main(["verilog", "fp-mul", "--target", "virtex4", "-o", str(v4)]) == 0
    assert main(["verilog", "fp-mul", "-o", str(gen)]) == 0
    m4 = json.loads(v4.with_suffix(".json").read_text())
    mg = json.loads(gen.with_suffix(".json").read_text())
    assert (m4["parameters"]["target"], m4["latency"]) == ("virtex4", 5)
    assert (mg["parameters"]["target"], mg["latency"]) == ("generic", 4)
    assert "target = virtex4" in v4.read_text() and "DSP48 " in v4.read_text()
    assert "DSP48" not in gen.read_text()
    rt = tmp_path / "rt.v"
    assert main(["verilog", "plane-sphere-tester", "--target", "virtex4", "-o", str(rt)]) == 0
    assert json.loads(rt.with_suffix(".json").read_text())["latency"] == 18
    capsys.readouterr()
    assert main(["verilog", "fp-mul", "--target", "xc7", "-o", str(tmp_path / "x.v")]) == 2
    assert "target must be one of generic, virtex4" in capsys.readouterr().err
    # fp-add: --target is the adder's own (two DSP48, latency 7; issue 15)
    add = tmp_path / "add.v"
    assert main(["verilog", "fp-add", "--target", "virtex4", "-o", str(add)]) == 0
    madd = json.loads(add.with_suffix(".json").read_text())
    assert (madd["parameters"]["target"], madd["latency"]) == ("virtex4", 7)
    assert add.read_text().count("DSP48 ") == 2
    capsys.readouterr()
    assert main(["verilog", "fp-add", "--adder", "virtex4", "-o", str(tmp_path / "y.v")]) == 2
    assert "--adder does not apply to unit fp-add" in capsys.readouterr().err
