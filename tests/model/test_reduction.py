"""The on-chip reduction's golden model (raplas_hdl/model/reduction.py): exact against
rational arithmetic, and equal to the host's nearest-hit choice on real render passes."""

from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest

from raplas_hdl.fp import FP24, FPFormat
from raplas_hdl.fp import model as fpm
from raplas_hdl.host.reduction_passes import host_choice, pass_runs, recorded_runs
from raplas_hdl.host.render import RenderSettings
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.intersection import RESULT_DTYPE, run_runs
from raplas_hdl.model.memory_image import bundle_writes
from raplas_hdl.model.reduction import (ANSWER_DTYPE, check_reduce_format, early_out_saving,
                                        inf_pattern, reduce_run)
from raplas_hdl.sim.drive.reducer_harness import random_beats, window_bundle

CFG = UnitConfig(FP24, rows=2, cols=4, max_triangles=64, reduce=True)


def _exact(bits, fmt=FP24):
    """Fraction value of a finite pattern, None for inf/NaN."""
    x = float(fpm.decode(np.array([bits], np.uint32), fmt)[0])
    return Fraction(x) if np.isfinite(x) else None


def reference(cfg, beats, bundle):
    """The reduction in rational arithmetic, one beat at a time."""
    fmt = cfg.fmt
    lo = _exact(bundle.tmin)
    tmax = bundle.window_tmax(cfg)
    best = {}
    for i, bt in enumerate(beats):
        t, d = _exact(bt["t"]), _exact(bt["det"])
        if not bt["hit"] or t is None or d is None or d == 0:
            continue
        r = t / d
        hi = _exact(tmax[bt["ray_id"]])
        if r < lo or (hi is not None and r > hi) or int(bt["tri_id"]) == bundle.exclude:
            continue
        ray = int(bt["ray_id"])
        key = (r, int(bt["tri_id"]), i)
        if ray not in best or (not bundle.any_hit and key < best[ray]):
            best[ray] = key
    del fmt
    return {ray: key[2] for ray, key in best.items()}


@pytest.mark.parametrize("any_hit", [False, True])
@pytest.mark.parametrize("seed", range(3))
def test_reduction_is_exact(seed, any_hit):
    rng = np.random.default_rng(seed)
    beats = random_beats(rng, 600, CFG)
    tmax = fpm.encode(rng.uniform(0.5, 6.0, CFG.n_rays), FP24)
    tmax[0] = inf_pattern(FP24)
    bundle = window_bundle(CFG, tmin=int(fpm.encode(np.array([0.25 * seed]), FP24)[0]),
                           tmax=tmax, exclude=int(rng.integers(-1, 12)), any_hit=any_hit)
    want = reference(CFG, beats, bundle)
    got = reduce_run(CFG, beats, bundle)
    assert not got["empty"].any()
    assert got["last"].tolist() == [0] * (got.size - 1) + [1]
    assert got["ray_id"].tolist() == sorted(want)
    for a in got:
        w = beats[want[int(a["ray_id"])]]
        for key in ("tri_id", "t", "u", "v", "det", "flags"):
            assert a[key] == w[key], (key, a, w)


def test_ties_go_to_the_lowest_triangle():
    beats = np.zeros(3, RESULT_DTYPE)
    beats["hit"] = 1
    beats["tri_id"] = [9, 4, 7]
    # 3/6, 1/2 and 4/8: equal ratios, differently rounded as t' * (1/det)
    beats["t"] = fpm.encode(np.array([3.0, 1.0, 4.0]), FP24)
    beats["det"] = fpm.encode(np.array([6.0, 2.0, 8.0]), FP24)
    beats["last"][-1] = 1
    out = reduce_run(CFG, beats, window_bundle(CFG))
    assert out.size == 1 and out["tri_id"][0] == 4 and out["last"][0] == 1


def test_run_without_answers_gives_one_empty_beat():
    beats = np.zeros(2, RESULT_DTYPE)
    beats["last"][-1] = 1
    out = reduce_run(CFG, beats, window_bundle(CFG))
    assert out.dtype == ANSWER_DTYPE and out.size == 1
    assert out["empty"][0] == 1 and out["last"][0] == 1 and out["ray_id"][0] == 0


def test_window_is_checked():
    with pytest.raises(ValueError, match="tmin must be a finite"):
        reduce_run(CFG, np.zeros(1, RESULT_DTYPE), window_bundle(CFG, tmin=inf_pattern(FP24)))
    with pytest.raises(ValueError, match="no NaN"):
        bundle_writes(CFG, window_bundle(CFG, tmax=np.full(CFG.n_rays, inf_pattern(FP24) | 1)))
    with pytest.raises(ValueError, match="exclude must be"):
        bundle_writes(CFG, window_bundle(CFG, exclude=64))
    with pytest.raises(ValueError, match="man_bits <= 24"):
        check_reduce_format(FPFormat(5, 26))


def test_window_writes_only_with_reduce():
    b = window_bundle(CFG, tmin=5, exclude=3, any_hit=True)
    a0, _ = bundle_writes(replace(CFG, reduce=False), b)
    a1, d1 = bundle_writes(CFG, b)
    assert a1.size == a0.size + CFG.n_rays + 3
    assert d1[-3:].tolist() == [5, 4, 1]


SETTINGS = RenderSettings(width=24, height=24, rows=4, cols=4, shadow_rows=2, shadow_cols=2,
                          progress=False)


@pytest.fixture(scope="module", params=["cornell", "stanford-bunny"])
def passes(request):
    return recorded_runs(request.param, SETTINGS)


def test_answers_equal_the_host_choice_on_render_passes(passes):
    """Primary (nearest) and shadow (any-hit, own triangle excluded, tmin = eps, per-ray
    tmax) passes of real renders: the reduced answers are the host's choice, ray for ray."""
    backend, recs = passes
    assert {r.any_hit for r in recs} == {False, True}
    answers = 0
    for rec in recs:
        cfg = backend.config(rec.batch.rows, rec.batch.cols)
        runs = pass_runs(backend, rec, cfg)
        plain = run_runs(cfg, backend.scene_memory, runs)
        reduced = run_runs(replace(cfg, reduce=True), backend.scene_memory, runs)
        for run, (beats, ctr), (ans, ctr2) in zip(runs, plain, reduced):
            assert ctr == ctr2
            tri, idx = host_choice(cfg, beats, run.bundle)
            got = np.full(cfg.n_rays, -1)
            if not ans["empty"][0]:
                got[ans["ray_id"].astype(np.int64)] = ans["tri_id"]
            if rec.any_hit:
                assert np.array_equal(got >= 0, tri >= 0)
                assert early_out_saving(cfg, beats, run.bundle) <= beats.size
            else:
                assert np.array_equal(got, tri)
                if got.max() >= 0:
                    won = beats[idx[ans["ray_id"].astype(np.int64)]]
                    for key in ("t", "u", "v", "det", "flags"):
                        assert np.array_equal(won[key], ans[key])
            answers += int((got >= 0).sum())
    assert answers > 100
