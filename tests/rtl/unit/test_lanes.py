"""K ray-triangle lanes behind one culling array (``UnitConfig.lanes``), and the cycle model.

- The unit with ``lanes = 2`` (2x2 bundles) in the job-stream harness under Icarus and
  Verilator: the runs of :func:`tests.support.unit_scenes.scene_and_runs` (every feature of
  the unit) under random back-pressure, every result bit and counter equal to the golden
  model's (the result stream does not depend on ``lanes``); then without back-pressure the
  ``cycles`` counter equal to the cycle model's (:mod:`raplas_hdl.model.throughput`), run
  by run, and for a round of overlapped runs.
- The cycle model alone: its pairs are the model's ``pairs_issued``; one beat per cycle
  bounds the stream; lanes that consume their own results sustain more.
- ``full``: ``lanes = 3`` at 4x4 with the bunny's runs (a render through the rtl backend,
  equal to the model backend's image, hits and counters), both simulators, and the
  cycles of ``lanes`` 1 to 3 against the cycle model.
"""

import dataclasses

import numpy as np
import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.model.intersection import run_runs
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.throughput import Timing, pairs_per_cycle, profile_runs, simulate
from raplas_hdl.rtl.intersection import IntersectionUnit
from raplas_hdl.sim.drive.unit_harness import UnitSession
from tests.support.unit_scenes import check_against_model, scene_and_runs

SMALL = UnitConfig(fmt=FP24, rows=2, cols=2, testers=4, tris_per_sphere=4,
                   max_triangles=256, max_spheres=128, fifo_depth=8, lanes=2)
LARGE = UnitConfig(fmt=FP24, rows=4, cols=4, testers=4, tris_per_sphere=4,
                   max_triangles=256, max_spheres=128, fifo_depth=8, lanes=3)


def timing(cfg: UnitConfig) -> Timing:
    unit = IntersectionUnit(cfg)
    unit._MustUse__silence = True                     # built only to be inspected
    return unit.cycle_timing()


def busy_cycles(t_cmd, t_last) -> int:
    """Cycles with a run outstanding: the union of the runs' [command, last beat)."""
    total, lo, hi = 0, None, None
    for a, b in sorted(zip(t_cmd.tolist(), t_last.tolist())):
        if hi is None or a > hi:
            total += 0 if hi is None else hi - lo
            lo, hi = a, b
        else:
            hi = max(hi, b)
    return total + (0 if hi is None else hi - lo)


def check_cycles(cfg, scene, runs, results, overlap=False):
    """The ``cycles`` counter (no back-pressure) equals the cycle model's: per run when the
    runs go one at a time; with ``overlap``, the round's, with the harness's host writes
    (each run's words after the previous command and after the last beat of the bank's
    previous run)."""
    from raplas_hdl.sim.drive.unit_driver import encode_runs

    prof = profile_runs(cfg, scene, runs)
    if not overlap:
        t_cmd, t_last = simulate(prof, cfg, timing(cfg), overlap=False)
        assert [ctr["cycles"] for _, ctr in results] == [int(x) for x in t_last - t_cmd]
        return
    stim = encode_runs(cfg, scene, runs, overlap=True, with_scene=False)
    last_of, after = {}, []
    for k, bank in enumerate(stim["run_bank"].tolist()):
        after.append(last_of.get(bank, -1))
        last_of[bank] = k
    t_cmd, t_last = simulate(prof, cfg, timing(cfg), overlap=True,
                             host=(np.diff(stim["run_offsets"]), after))
    assert results[-1][1]["cycles"] == busy_cycles(t_cmd, t_last)


def check_binding(cfg, scene, runs, build_key, *shifts):
    """The cycle model's constants of ``shifts`` (``(name, shift)`` pairs) bind in ``runs``
    (each shifted, the model gives other cycles), and the RTL's ``cycles`` counter, run by run,
    equals the model's with the true constants (Verilator, no back-pressure)."""
    prof = profile_runs(cfg, scene, runs)
    tm = timing(cfg)
    t_cmd, t_last = simulate(prof, cfg, tm, overlap=False)
    for name, shift in shifts:
        other = dataclasses.replace(tm, **{name: getattr(tm, name) + shift})
        o_cmd, o_last = simulate(prof, cfg, other, overlap=False)
        assert not np.array_equal(o_last - o_cmd, t_last - t_cmd), name
    with UnitSession("verilator", cfg, scene, ready_density=1.0, build_key=build_key) as s:
        res = s.run(runs)
    check_against_model(cfg, scene, runs, res)
    check_cycles(cfg, scene, runs, res)


@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_lanes_match_model(simulator):
    scene, runs = scene_and_runs(SMALL, 120, seed=4)
    with UnitSession(simulator, SMALL, scene, seed=3, ready_density=0.6,
                     build_key="lanes-test") as s:
        ref = check_against_model(SMALL, scene, runs, s.run(runs))
        assert sum(r[1]["pairs_issued"] for r in ref) > 200
        assert sum(r[1]["pairs_skipped"] for r in ref) > 0
        check_against_model(SMALL, scene, runs, s.run(runs, overlap=True), overlap=True)


# The cycle counts come from the same RTL in both simulators: Icarus checks them in test-full
@pytest.mark.parametrize("simulator", [pytest.param("icarus", marks=pytest.mark.full),
                                       "verilator"])
def test_lanes_cycles_equal_model(simulator):
    scene, runs = scene_and_runs(SMALL, 120, seed=4)
    with UnitSession(simulator, SMALL, scene, ready_density=1.0, build_key="lanes-test") as s:
        res = s.run(runs)
        res_overlap = s.run(runs, overlap=True)
    check_against_model(SMALL, scene, runs, res)
    check_cycles(SMALL, scene, runs, res)
    check_cycles(SMALL, scene, runs, res_overlap, overlap=True)


def test_feeder_credits_bound_cycles_equal_model():
    """Runs whose every sphere is culled (the selector takes one per cycle) and the array
    takes one sphere per cycle: the feeder's credits are the limit (the model with one
    credit fewer, or a credit one cycle slower, gives other cycles), and the ``cycles``
    counter equals the cycle model's, run by run."""
    from raplas_hdl.model.memory_image import Run
    from raplas_hdl.sim.drive.unit_driver import random_bundle, random_scene

    scene = random_scene(SMALL, 120, seed=4, size=1.2, extent=4.0, empty_spheres=2)
    away = random_bundle(SMALL, seed=5, target=np.array([0.0, 60.0, 0.0]), spread=0.01)
    runs = [Run(away, np.resize(np.arange(scene.n_spheres), 120), False),
            Run(away, None, False)]
    prof = profile_runs(SMALL, scene, runs)
    assert prof.pairs == 0 and prof.spheres > 150
    from raplas_hdl.rtl.unit.feeder import SPHERE_FIFO_DEPTH

    assert timing(SMALL).feed_registers == SPHERE_FIFO_DEPTH
    check_binding(SMALL, scene, runs, "lanes-test", ("feed_registers", -1),
                  ("feed_return", +1))


def test_fetch_credits_bound_cycles_equal_model():
    """A 4-deep pair FIFO: the record fetch's credits (one per entry, back two cycles after
    the pair reached the ray-triangle unit) halve its rate, and the ``cycles`` counter
    equals the cycle model's, run by run (a credit a cycle faster or slower in the model
    gives other cycles)."""
    cfg = dataclasses.replace(SMALL, fifo_depth=4)
    scene, runs = scene_and_runs(cfg, 120, seed=4)
    check_binding(cfg, scene, runs, "lanes-fetch-credits", ("fetch_return", -1),
                  ("fetch_return", +1))


def test_cycle_model_bounds():
    cfg = dataclasses.replace(SMALL, rows=4, cols=4, testers=8, lanes=1)
    scene, runs = scene_and_runs(cfg, 200, seed=11)
    prof = profile_runs(cfg, scene, runs)
    assert prof.pairs == sum(c["pairs_issued"] for _, c in run_runs(cfg, scene, runs))
    assert prof.spheres == sum(c["spheres"] for _, c in run_runs(cfg, scene, runs))
    tm = timing(cfg)
    one = pairs_per_cycle(prof, cfg, tm, lanes=1)[1]
    assert 0.5 < one <= 1.0
    for lanes in (2, 3, 4):
        stream = pairs_per_cycle(prof, cfg, tm, lanes=lanes)[1]
        own = pairs_per_cycle(prof, cfg, tm, lanes=lanes, results="lanes")[1]
        assert stream <= 1.0 < own
    # one at a time, every run takes at least its pairs' beats and the pipeline's depth
    t_cmd, t_last = simulate(prof, cfg, tm, overlap=False)
    pairs = [c["pairs_issued"] for _, c in run_runs(cfg, scene, runs)]
    assert all(t_last - t_cmd > np.array(pairs) + tm.rt_latency)
    with pytest.raises(ValueError, match="results"):
        simulate(prof, cfg, tm, results="wide")


@pytest.mark.full
@pytest.mark.parametrize("simulator, size", [("icarus", (4, 4)), ("verilator", (16, 16))])
def test_lanes_bunny_render_equals_model(simulator, size):
    """The bunny through a unit of three lanes (4x4 primary and shadow bundles): image,
    nearest triangle, visibility and every counter equal to the model backend's."""
    from raplas_hdl.host.backends import ModelBackend, RtlBackend
    from raplas_hdl.host.render import RenderSettings, render
    from raplas_hdl.host.scenes import get_scene

    class Lanes3(RtlBackend):
        def config(self, rows, cols):
            return dataclasses.replace(super().config(rows, cols), lanes=3)

    scene = get_scene("stanford-bunny")
    settings = RenderSettings(*size, rows=4, cols=4, shadow_rows=4, shadow_cols=4,
                              progress=False)
    backend = Lanes3(FP24, "paper", sim=simulator)
    try:
        rtl = render(scene, backend, settings)
        assert {c.lanes for c in backend._sessions} == {3}
    finally:
        backend.close()
    model = render(scene, ModelBackend(FP24, "paper"), settings)
    np.testing.assert_array_equal(rtl.tri_id, model.tri_id)
    np.testing.assert_array_equal(rtl.image, model.image)
    np.testing.assert_array_equal(rtl.visibility, model.visibility)
    unit_rtl = {k: v for k, v in rtl.stats["unit"].items() if not k.startswith(("_", "cycles"))}
    assert unit_rtl == model.stats["unit"]
    assert model.stats["unit"]["pairs_issued"] > 1000


@pytest.mark.full
@pytest.mark.parametrize("lanes", [1, 2, 3])
def test_lanes_cycles_equal_model_large(lanes):
    cfg = dataclasses.replace(LARGE, lanes=lanes)
    scene, runs = scene_and_runs(cfg, 200, seed=11)
    with UnitSession("verilator", cfg, scene, ready_density=1.0,
                     build_key="lanes-test") as s:
        res = s.run(runs)
        res_overlap = s.run(runs, overlap=True)
    check_against_model(cfg, scene, runs, res)
    check_cycles(cfg, scene, runs, res)
    check_cycles(cfg, scene, runs, res_overlap, overlap=True)
