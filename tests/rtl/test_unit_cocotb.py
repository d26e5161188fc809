"""The intersection unit's Verilog under cocotb (Icarus and Verilator) against its model.

A FP24 scene of 200 random triangles in spheres of up to 4, seven runs over three bundles
(range and list runs, an early-out rewrite of the enable bits, an empty run, a keep-all run
that culls nothing, an all-disabled run, a run whose ray directions raise overflow,
underflow and invalid in several operations per pair), random back-pressure on the result
stream. Without overlap every run's stream and
counters must equal the model's; with overlap (runs started back to back, the next
bundle loading into the other bank while a run goes) every stream, and the counters summed
over the runs. The testbench asserts every cycle that the pair FIFO stays within its depth
and its overflow flag stays clear.
"""

import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.sim.drive.unit_driver import run_runs
from tests.support.unit_scenes import (assert_keep_all, assert_operation_events,
                                       check_against_model, scene_and_runs)

CFG = UnitConfig(fmt=FP24, rows=4, cols=4, testers=4, tris_per_sphere=4, max_triangles=256,
                 max_spheres=128, fifo_depth=8)


@pytest.fixture(scope="module")
def scene_runs():
    return scene_and_runs(CFG, 200, seed=11)


# Verilator builds the unit in about 35 s because only the top's ports are public
# (see raplas_hdl/sim/build/runner.py, mark_ports_public); with every signal public it took
# over 40 min. make test runs each simulator in one of the two ways, the full suite all four.
@pytest.mark.parametrize("simulator, overlap", [
    ("icarus", False), pytest.param("icarus", True, marks=pytest.mark.full),
    pytest.param("verilator", False, marks=pytest.mark.full), ("verilator", True)],
    ids=["icarus-sequential", "icarus-overlap", "verilator-sequential", "verilator-overlap"])
def test_unit_cocotb_matches_model(simulator, overlap, scene_runs):
    scene, runs = scene_runs
    results = run_runs(simulator, CFG, scene, runs, seed=3 + overlap, ready_density=0.6,
                       overlap=overlap, build_key="unit-test")
    ref = check_against_model(CFG, scene, runs, results, overlap=overlap)
    assert_keep_all(CFG, scene, runs, ref)
    assert sum(r[1]["pairs_issued"] for r in ref) > 300
    assert sum(r[1]["hits"] for r in ref) > 0
    assert sum(r[1]["pairs_skipped"] for r in ref) > 0
    assert_operation_events(ref)
    assert results[-1][1]["_max_fifo_level"] == CFG.fifo_depth
