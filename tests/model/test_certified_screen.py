"""The certified block path's screen (raplas_hdl/model/certified.py, ``vscreen``): its bounds
are at least the unit's, lane by lane, so that an outcome it decides is the unit's; the
fast-path values of lanes with zero operands (``_lane_fast``) are the reference's bits.

The block path's outcomes themselves are compared with the pair path in
``test_certified_block.py``; here the screen is checked where it could be wrong without
changing an outcome of those vectors."""

import numpy as np
import pytest

from raplas_hdl.fp import FP16, FP20, FP24
from raplas_hdl.fp.format import FPFormat
from raplas_hdl.fp.kernels import rmode_code
from raplas_hdl.model import certified, stress_cases
from raplas_hdl.model.pair_kernels import BLOCK, vpair
from raplas_hdl.model.triangles import make_triangles
from raplas_hdl.fp.model import encode

KEYS = ("o", "d", "v0", "e1", "e2", "n")
FORMATS = [FPFormat(f.exp_bits, f.man_bits, rnd) for f in (FP16, FP20, FP24)
           for rnd in ("rtz", "rne", "chop")]
#: the bounds of pair_bounds, in the order of the screen's rows 0-4
BOUND_NAMES = ("det", "t'", "u'", "v'", "w")


def _with_zeros(vec, fmt, rate, rng):
    """``vec`` with a fraction ``rate`` of the components replaced by +0 or -0 (axis-aligned
    geometry, a ray along an axis)."""
    out = {}
    for key, val in vec.items():
        val = val.copy()
        hit = rng.random(val.shape) < rate
        val[hit] = np.where(rng.random(val.shape) < 0.5, 0, 1 << (fmt.width - 1))[hit]
        out[key] = val
    return out


def _axis_aligned(fmt, count, rng):
    """Pairs against axis-aligned triangles (a floor and walls: N, E1, E2 with zero
    components) from random origins, aimed near the triangles."""
    tris = []
    for _ in range(count):
        c = rng.uniform(-2, 2, 3)
        s = rng.uniform(0.1, 1.0)
        axis = rng.integers(0, 3)
        a, b = [(axis + 1) % 3, (axis + 2) % 3]
        v = np.repeat(c[None], 3, 0)
        v[1, a] += s
        v[2, b] += s
        tris.append(v)
    tris = np.array(tris)
    recs = make_triangles(tris, fmt, on_bad="skip")
    k = recs.ids
    o = rng.uniform(-4, 4, (len(k), 3))
    target = tris[k].mean(1) + rng.normal(0, 0.2, (len(k), 3))
    d = target - o
    return {"o": encode(o, fmt), "d": encode(d, fmt), "v0": recs.v0_bits, "e1": recs.e1_bits,
            "e2": recs.e2_bits, "n": recs.n_bits}


def _screen_and_exact(vec, fmt, variant=certified.DEFAULT_VARIANT):
    """Per flag-free lane: the screen's five bounds, the unit's, and whether the fast-path
    values equal the reference's. Returns ``(screen, exact, same_values, zero_lanes)``."""
    e, m, r = fmt.exp_bits, fmt.man_bits, rmode_code(fmt)
    cc = certified.certified_constants(fmt, 1.0, variant)
    arrs = [np.ascontiguousarray(vec[k], np.uint32) for k in KEYS]
    count = len(arrs[0])
    screen, exact, same, zero_lanes = [], [], [], 0
    g = np.zeros((18, BLOCK), np.int64)
    w = np.zeros((13, BLOCK), np.int64)
    gs = np.zeros((certified.N_SCREEN_ROWS, BLOCK))
    for start in range(0, count, BLOCK):
        n = min(BLOCK, count - start)
        for row, a in enumerate(arrs):
            g[3 * row:3 * row + 3, :n] = a[start:start + n].T
        vpair(g, w, n, True, e, m, r)
        for q in range(n):
            if w[11, q] < 0:
                zero_lanes += bool(certified._lane_fast(g, w, q, e, m, r))
        certified.vscreen(g, w, gs, n, e, m, r, cc)
        for q in range(n):
            i = start + q
            tp, up, vp, det, ww, *bounds, cnt = certified.pair_bounds(
                arrs[0], i, arrs[1], i, *arrs[2:], i, e, m, r, cc)
            if w[11, q] < 0:                  # left the fast paths: pair_full decides
                continue
            assert cnt == 0, "a lane of the fast paths raised an event in the reference"
            same.append((w[0, q], w[1, q], w[2, q], w[3, q], w[5, q]) == (tp, up, vp, det, ww))
            screen.append(gs[:5, q].copy())
            exact.append(bounds)
    return np.array(screen), np.array(exact), np.array(same), zero_lanes


def _check(vec, fmt, variant=certified.DEFAULT_VARIANT, min_lanes=50):
    screen, exact, same, zero_lanes = _screen_and_exact(vec, fmt, variant)
    assert len(screen) >= min_lanes
    assert same.all(), f"{(~same).sum()} lanes' fast-path values differ from the reference"
    low = screen < exact
    for x, name in enumerate(BOUND_NAMES):
        bad = np.flatnonzero(low[:, x])
        assert not bad.size, (f"{fmt.name} {variant}: the screen's B_{name} is below the "
                              f"unit's on {bad.size} lanes, e.g. {screen[bad[0], x]!r} < "
                              f"{exact[bad[0], x]!r}")
    return screen, exact, zero_lanes


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f.name)
def test_screen_bounds_dominate_the_units(fmt):
    rng = np.random.default_rng([31, fmt.man_bits, rmode_code(fmt)])
    fam = stress_cases.vectors(fmt, 1200, seed=11, special_rate=0.0, random_rate=0.05)
    screen, exact, _ = _check(fam, fmt)
    # the screen is an upper bound close to the unit's, not a loose one: a screen a few
    # percent too low would fail above on some lane
    ratio = screen / np.where(exact > 0, exact, np.inf)
    ratio = ratio[np.isfinite(ratio) & (ratio > 0)]
    assert ratio.min() < 2.0 and np.median(ratio) < 4.0
    _, _, zeros = _check(_with_zeros(fam, fmt, 0.08, rng), fmt)
    assert zeros > 20                             # lanes with zero operands were screened
    _, _, zeros = _check(_axis_aligned(fmt, 600, rng), fmt)
    assert zeros > 100


@pytest.mark.parametrize("variant", sorted(certified.VARIANTS))
def test_screen_bounds_every_variant(variant):
    fmt = FPFormat(7, 16, "rne")
    fam = stress_cases.vectors(fmt, 800, seed=12, special_rate=0.01, random_rate=0.05)
    _check(fam, fmt, variant)
    _check(_axis_aligned(fmt, 300, np.random.default_rng(3)), fmt, variant)


def test_screen_decides_most_lanes_of_a_scene():
    """On geometry like a render's (rays aimed near axis-aligned triangles), the screen's
    outcome is the unit's wherever it decides, and it leaves uncertain few lanes the unit's
    own bounds decide (the lanes the block path recomputes alone)."""
    fmt = FP24
    e, m, r = fmt.exp_bits, fmt.man_bits, rmode_code(fmt)
    vec = _axis_aligned(fmt, 3000, np.random.default_rng(5))
    arrs = [np.ascontiguousarray(vec[k], np.uint32) for k in KEYS]
    unit = certified.intersect_certified(arrs, fmt, block=False)["outcome"]
    assert (unit == 1).sum() > 300 and (unit == 0).sum() > 300
    cc = certified.certified_constants(fmt)
    g = np.zeros((18, BLOCK), np.int64)
    w = np.zeros((13, BLOCK), np.int64)
    gs = np.zeros((certified.N_SCREEN_ROWS, BLOCK))
    oc = np.zeros(BLOCK, np.int64)
    screened = []
    for start in range(0, len(unit), BLOCK):
        n = min(BLOCK, len(unit) - start)
        for row, a in enumerate(arrs):
            g[3 * row:3 * row + 3, :n] = a[start:start + n].T
        vpair(g, w, n, True, e, m, r)
        for q in range(n):
            if w[11, q] < 0:
                certified._lane_fast(g, w, q, e, m, r)
        certified.vscreen(g, w, gs, n, e, m, r, cc)
        certified.voutcome(w, gs, oc, n, cc[0], e, m)
        screened.append(oc[:n].copy())
    screened = np.concatenate(screened)
    decided = screened < 2
    assert decided.mean() > 0.95
    assert np.array_equal(screened[decided], unit[decided])
    left = (~decided & (unit != 2)).sum()
    assert left <= 0.02 * len(unit), f"the screen leaves {left} decided lanes uncertain"
