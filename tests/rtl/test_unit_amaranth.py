"""The whole intersection unit in Amaranth's simulator against its golden model.

The runs of :func:`tests.support.unit_scenes.scene_and_runs` (a keep-all run among them),
every result bit and counter compared with the model.

A small format (E=5, M=6) and a time-shared tester array keep the Python simulation short;
the cocotb tests run FP24 scenes of a few hundred triangles.
"""

import gc

import pytest

from raplas_hdl.fp import FP24, FPFormat
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.rtl.intersection import IntersectionUnit, build_intersection_unit
from tests.support.unit_amaranth_tb import simulate_runs
from tests.support.unit_scenes import (assert_keep_all, assert_operation_events,
                                       check_against_model, scene_and_runs)

SMALL = UnitConfig(fmt=FPFormat(5, 6), rows=2, cols=3, testers=2, tris_per_sphere=3,
                   max_triangles=32, max_spheres=24, fifo_depth=4)


def test_unit_amaranth_matches_model():
    scene, runs = scene_and_runs(SMALL, 24, seed=5)
    results = simulate_runs(IntersectionUnit(SMALL), scene, runs, seed=2, ready_density=0.5)
    ref = check_against_model(SMALL, scene, runs, results)
    assert_keep_all(SMALL, scene, runs, ref)
    issued = sum(r[1]["pairs_issued"] for r in ref)
    assert issued >= 20, "the scene must issue pairs"
    assert sum(r[1]["pairs_skipped"] for r in ref) > 0
    assert sum(r[1]["hits"] for r in ref) > 0
    assert any(len(r[0]) == 1 and r[0]["empty"][0] for r in ref)
    assert_operation_events(ref)
    # the pair FIFO was used and never went over its depth (the fetch's credits)
    assert 0 < results[-1][1]["_max_fifo_level"] <= SMALL.fifo_depth


@pytest.mark.filterwarnings("ignore::amaranth.hdl.UnusedElaboratable")
@pytest.mark.parametrize("kw, word", [
    ({"rows": 0}, "rows"), ({"cols": 100}, "cols"), ({"testers": 0}, "testers"),
    ({"tris_per_sphere": 0}, "tris_per_sphere"), ({"max_spheres": 0}, "max_spheres"),
    ({"max_triangles": -1}, "max_triangles"), ({"mode": "fast"}, "mode"),
    ({"fifo_depth": 1}, "fifo_depth")])
def test_unit_parameter_errors(kw, word):
    with pytest.raises(ValueError, match=word):
        IntersectionUnit(**kw)
    with pytest.raises(ValueError, match=word):
        build_intersection_unit(FP24, **kw)
    gc.collect()     # the refused units warn while the warning is ignored here


@pytest.mark.filterwarnings("ignore::amaranth.hdl.UnusedElaboratable")
def test_unit_ports():
    unit = build_intersection_unit(FP24, rows=4, cols=4, tris_per_sphere=8)
    assert unit.config.n_testers == 8
    sig = unit.signature.members
    assert {"wr_en", "wr_addr", "wr_data", "cmd", "o", "counters", "clear", "busy",
            "fifo_level", "fifo_overflow"} <= set(sig.keys())
    names = [n for n, _ in unit.result_layout]
    assert names == ["ray_id", "tri_id", "hit", "t", "u", "v", "det", "flags", "last", "empty"]
    assert [n for n, _ in unit.cmd_layout] == ["first", "count", "bank", "indirect",
                                               "keep_all"]
    with pytest.raises(ValueError, match="either"):
        IntersectionUnit(SMALL, rows=3)
    del unit
    gc.collect()
