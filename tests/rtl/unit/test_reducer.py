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
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.sim.drive.reducer_harness import cosim_reducer, random_runs

CFG = UnitConfig(FP24, rows=2, cols=4, max_triangles=16, reduce=True)
#: 35 rays: the tree of priority encoders (5 padded groups of 8)
WIDE = UnitConfig(FP24, rows=5, cols=7, max_triangles=16, reduce=True)


def check(simulator, n_runs, seed, cfg=CFG, **kw):
    runs = random_runs(cfg, n_runs, seed, beats_per_run=4 * cfg.n_rays)
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
