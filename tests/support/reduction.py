"""Result streams and bundle windows of the on-chip reduction's tests
(``model/test_reduction.py``, ``rtl/unit/test_reducer.py``, ``rtl/test_certified_unit.py``)."""

import numpy as np

from raplas_hdl.fp import FP24
from raplas_hdl.fp import model as fpm
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.intersection import RESULT_DTYPE
from raplas_hdl.model.memory_image import BundleMemory
from raplas_hdl.model.reduction import inf_pattern

#: The reduction model's configuration (``model/test_reduction.py``).
CFG = UnitConfig(FP24, rows=2, cols=4, max_triangles=64, reduce=True)


def window_bundle(cfg, **window):
    """A bundle of zero planes and rays with the window ``window`` (tmin, tmax, exclude,
    any_hit)."""
    z3 = np.zeros((cfg.n_rays, 3), np.uint32)
    return BundleMemory(np.zeros((cfg.n_planes, 3), np.uint32),
                        np.zeros(cfg.n_planes, np.uint32), z3, z3.copy(), **window)


def random_beats(rng, n, cfg=CFG, fmt=FP24):
    """Result beats with random and deliberately tied ratios t'/det (3/6 = 1/2, scaled by
    powers of two), signs, zeros, infinities and NaNs, tri IDs with repeats."""
    b = np.zeros(n, RESULT_DTYPE)
    b["ray_id"] = rng.integers(0, cfg.n_rays, n)
    b["tri_id"] = rng.integers(0, 12, n)
    b["hit"] = rng.random(n) < 0.8
    t = rng.uniform(-0.5, 4.0, n)
    det = rng.choice([-1.0, 1.0], n) * rng.uniform(0.01, 2.0, n)
    # ties: t'/det = a/b for small a, b, times a power of two
    k = rng.random(n) < 0.4
    num, den = rng.integers(1, 6, n), rng.integers(1, 4, n)
    mult = rng.integers(1, 4, n) * 2.0 ** rng.integers(-3, 3, n)
    sgn = rng.choice([-1.0, 1.0], n)
    t = np.where(k, sgn * num * mult, t)
    det = np.where(k, sgn * den * mult, det)
    bits_t = fpm.encode(t, fmt)
    bits_d = fpm.encode(det, fmt)
    special = rng.random(n)
    inf = inf_pattern(fmt)
    bits_t = np.where(special < 0.02, inf, bits_t)
    bits_d = np.where((special > 0.02) & (special < 0.04), 0, bits_d)
    bits_t = np.where((special > 0.04) & (special < 0.05), inf | 1, bits_t)
    bits_t = np.where((special > 0.05) & (special < 0.06), 0, bits_t)
    b["t"], b["det"] = bits_t, bits_d
    b["u"], b["v"] = rng.integers(0, fmt.mask, n), rng.integers(0, fmt.mask, n)
    b["flags"] = rng.integers(0, 8, n)
    b["last"][-1] = 1
    return b



def reducer_runs(cfg, n_runs, seed, beats_per_run=40):
    """``n_runs`` (beats, bundle) runs for the reducer: random beats (:func:`random_beats`),
    a run that issued no pair and one without a hit every seven, random windows, nearest-hit
    and any-hit runs alternating."""
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
        bundle = window_bundle(cfg, tmin=tmin, tmax=tmax, exclude=int(rng.integers(-1, 12)),
                               any_hit=bool(k % 2))
        runs.append((beats, bundle))
    return runs

