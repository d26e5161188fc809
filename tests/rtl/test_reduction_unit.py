"""The intersection unit built with the on-chip reduction (``UnitConfig(reduce=True)``) in a
live simulation (:class:`raplas_hdl.sim.drive.unit_harness.UnitSession`) against the model's
reduced ``run_runs``: every answer bit of every run equal; the counters equal except that
the any-hit early-out lets the unit issue fewer pairs (``pairs_issued``, and the ``hits``
and event counters of those pairs, at most the model's, which has no early-out).

The runs are the cocotb test's seven (range and list runs, enable rewrites, an empty run,
keep-all, all disabled, arithmetic events) with a window on every bundle: nearest-hit and
any-hit bundles alternate, each with a ``tmin``, per-ray ``tmax`` (some infinite) and an
excluded triangle; then a round of overlapped runs.
"""

from dataclasses import replace

import numpy as np
import pytest
from tests.support.unit_amaranth_tb import simulate_runs
from tests.support.unit_scenes import scene_and_runs

from raplas_hdl.fp import FP24, FPFormat
from raplas_hdl.fp import model as fpm
from raplas_hdl.model.intersection import run_runs
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.memory_image import Run, as_run
from raplas_hdl.model.reduction import inf_pattern
from raplas_hdl.rtl.intersection import IntersectionUnit
from raplas_hdl.sim.drive.unit_harness import UnitSession

CFG = UnitConfig(fmt=FP24, rows=2, cols=4, testers=3, tris_per_sphere=4, max_triangles=128,
                 max_spheres=64, fifo_depth=8, reduce=True)
EXACT = ("spheres", "plane_tests", "pairs_skipped")
AT_MOST = ("pairs_issued", "hits", "overflow", "underflow", "invalid")


def windowed_runs(config, scene, runs, seed, scale=1.0):
    rng = np.random.default_rng(seed)
    out = []
    for k, run in enumerate(map(as_run, runs)):
        tmax = fpm.encode(rng.uniform(6.0, 20.0, config.n_rays) * scale, config.fmt)
        tmax[rng.random(config.n_rays) < 0.4] = inf_pattern(config.fmt)
        used = scene.tri_lists[scene.tri_counts > 0, 0]
        bundle = replace(run.bundle, tmin=int(fpm.encode(np.array([0.05 * (k % 3)]),
                                                         config.fmt)[0]),
                         tmax=tmax, exclude=int(rng.choice(used)) if k % 3 else -1,
                         any_hit=bool(k % 2))
        out.append(Run(bundle, run.sphere_ids, run.keep_all))
    return out


def check(config, runs, got, want, overlap=False):
    saved = 0
    for k, (run, (stream, ctr), (ref, rctr)) in enumerate(zip(runs, got, want)):
        assert stream.dtype == ref.dtype
        assert len(stream) == len(ref), f"run {k}: {len(stream)} answers, model {len(ref)}"
        bad = np.flatnonzero(stream != ref)
        assert bad.size == 0, f"run {k}: answer {bad[0]}: {stream[bad[0]]} != {ref[bad[0]]}"
        if overlap:
            continue
        exact = EXACT if run.bundle.any_hit else EXACT + AT_MOST
        assert {n: ctr[n] for n in exact} == {n: rctr[n] for n in exact}, k
        assert all(ctr[n] <= rctr[n] for n in AT_MOST), (k, ctr, rctr)
        saved += rctr["pairs_issued"] - ctr["pairs_issued"]
    return saved


@pytest.fixture(scope="module")
def scene_runs():
    scene, runs = scene_and_runs(CFG, 100, seed=11, size=3.0, extent=2.0)
    return scene, windowed_runs(CFG, scene, runs, seed=4)


def session_check(simulator, scene_runs):
    scene, runs = scene_runs
    want = run_runs(CFG, scene, runs)
    assert sum(int((~r["empty"].astype(bool)).sum()) for r, _ in want) > 15
    with UnitSession(simulator, CFG, scene, seed=7, ready_density=0.5) as s:
        saved = check(CFG, runs, s.run(runs), want)
        again = runs[::-1]
        check(CFG, again, s.run(again, overlap=True), run_runs(CFG, scene, again),
              overlap=True)
    assert saved > 0, "the any-hit early-out saved no pair"


def test_reduced_unit_matches_model_icarus(scene_runs):
    session_check("icarus", scene_runs)


@pytest.mark.full
def test_reduced_unit_matches_model_verilator(scene_runs):
    session_check("verilator", scene_runs)


SMALL = UnitConfig(fmt=FPFormat(5, 6), rows=2, cols=3, testers=2, tris_per_sphere=3,
                   max_triangles=32, max_spheres=24, fifo_depth=4, reduce=True)


@pytest.mark.parametrize("lanes", [pytest.param(1, marks=pytest.mark.full), 2])
def test_reduced_unit_amaranth(lanes):
    """The same in Amaranth's simulator, a small format, with one and two ray-triangle
    lanes (the reducer sees the merged stream, the early-out reaches the one selector)."""
    cfg = replace(SMALL, lanes=lanes)
    scene, runs = scene_and_runs(cfg, 24, seed=5, size=3.0, extent=2.0)
    runs = windowed_runs(cfg, scene, runs, seed=lanes)
    want = run_runs(cfg, scene, runs)
    assert sum(int((~r["empty"].astype(bool)).sum()) for r, _ in want) > 5
    got = simulate_runs(IntersectionUnit(cfg), scene, runs, seed=2, ready_density=0.5)
    check(cfg, runs, got, want)
