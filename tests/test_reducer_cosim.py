"""The reducer (raplas_hdl/rtl/unit/reducer.py) alone against the reduction's model
(raplas_hdl/model/reduction.py), every bit of every answer, under Icarus and Verilator:
adversarial streams (exact ties such as 3/6 and 1/2, signs, zeros, infinities, NaNs,
repeated triangles, windows with tmin, per-ray tmax and an excluded triangle), nearest-hit
and any-hit runs in both banks, runs without answers, empty runs, random gaps and
back-pressure."""

from dataclasses import replace

import numpy as np
import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.fp import model as fpm
from raplas_hdl.model.intersection import RESULT_DTYPE
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.reduction import inf_pattern
from raplas_hdl.sim.reducer_harness import cosim_reducer
from test_reduction_model import _bundle, random_beats

CFG = UnitConfig(FP24, rows=2, cols=4, max_triangles=16, reduce=True)
#: 35 rays: the tree of priority encoders (5 padded groups of 8)
WIDE = UnitConfig(FP24, rows=5, cols=7, max_triangles=16, reduce=True)


def reducer_runs(cfg, n_runs, seed, beats_per_run=40):
    rng = np.random.default_rng(seed)
    runs = []
    for k in range(n_runs):
        kind = k % 7
        if kind == 5:                       # a run that issued no pair
            beats = np.zeros(1, RESULT_DTYPE)
            beats["last"] = beats["empty"] = 1
        else:
            beats = random_beats(rng, int(rng.integers(1, beats_per_run)), cfg)
            if kind == 6:                   # pairs, but no hit
                beats["hit"] = 0
        tmax = fpm.encode(rng.uniform(0.5, 6.0, cfg.n_rays), FP24)
        tmax[rng.random(cfg.n_rays) < 0.3] = inf_pattern(FP24)
        tmin = int(fpm.encode(np.array([rng.choice([0.0, -1.0, 0.3])]), FP24)[0])
        bundle = _bundle(cfg, tmin=tmin, tmax=tmax, exclude=int(rng.integers(-1, 12)),
                         any_hit=bool(k % 2))
        runs.append((beats, bundle))
    return runs


def check(simulator, n_runs, seed, cfg=CFG, **kw):
    runs = reducer_runs(cfg, n_runs, seed, beats_per_run=4 * cfg.n_rays)
    got, want, info = cosim_reducer(simulator, cfg, runs, seed=seed, **kw)
    assert got.size == want.size
    for name in want.dtype.names:
        bad = np.flatnonzero(got[name] != want[name])
        assert bad.size == 0, (name, bad[:5], got[bad[:3]], want[bad[:3]])
    assert want["empty"].sum() >= n_runs // 7 and (~want["empty"].astype(bool)).sum() > n_runs
    return info


@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_reducer_matches_model(simulator):
    check(simulator, 30, seed=1)


@pytest.mark.parametrize("simulator", ["icarus", pytest.param("verilator",
                                                                marks=pytest.mark.full)])
def test_wide_reducer_matches_model(simulator):
    check(simulator, 20, seed=4, cfg=WIDE)


@pytest.mark.full
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
@pytest.mark.parametrize("seed", [2, 3])
@pytest.mark.parametrize("cfg", [CFG, replace(WIDE, rows=8, cols=8)], ids=["2x4", "8x8"])
def test_reducer_matches_model_long(simulator, seed, cfg):
    check(simulator, 600, seed=seed, cfg=cfg, valid_density=0.6, stall_density=0.5)
