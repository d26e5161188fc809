"""The certified mode a block at a time equals it one pair at a time, bit for bit: the model
(raplas_hdl/model/certified.py, ``block_certified``) and the renderer's certified pass
(raplas_hdl/engine/certified.py, ``certified_pass`` with and without ``block``)."""

import numpy as np
import pytest

from raplas_hdl.engine import certified as engine_certified
from raplas_hdl.fp import FP16, FP20, FP24
from raplas_hdl.fp.format import FPFormat
from raplas_hdl.fp.kernels import rmode_code
from raplas_hdl.host.backends import ModelBackend
from raplas_hdl.host.modes import resolved
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene
from raplas_hdl.model import certified, stress_cases
from raplas_hdl.model.pair_kernels import BLOCK, vpair

KEYS = ("o", "d", "v0", "e1", "e2", "n")
FORMATS = [FPFormat(f.exp_bits, f.man_bits, rnd) for f in (FP16, FP20, FP24)
           for rnd in ("rtz", "rne", "chop")]


def _random_patterns(fmt, count, rng):
    """Uniformly random finite patterns of moderate exponent (most lanes in the common
    case, some leaving it through overflow, underflow or cancellation)."""
    bias = (1 << (fmt.exp_bits - 1)) - 1
    span = 4
    out = {}
    for key in KEYS:
        field = rng.integers(bias - span, bias + span, (count, 3))
        frac = rng.integers(0, 1 << fmt.man_bits, (count, 3))
        sign = rng.integers(0, 2, (count, 3))
        out[key] = ((sign << (fmt.width - 1)) | (field << fmt.man_bits) | frac).astype(np.uint32)
    return out


def _common_fraction(vec, fmt):
    """Share of the first BLOCK pairs whose every operation takes the common case (the
    lanes the vectorised bounds decide)."""
    n = min(BLOCK, len(vec["o"]))
    g = np.zeros((18, BLOCK), np.int64)
    for r, key in enumerate(KEYS):
        g[3 * r:3 * r + 3, :n] = vec[key][:n].T
    w = np.zeros((13, BLOCK), np.int64)
    vpair(g, w, n, True, fmt.exp_bits, fmt.man_bits, rmode_code(fmt))
    return float(np.mean(w[11, :n] >= 0))


def _same(vec, fmt, scale=1.0, variant=certified.DEFAULT_VARIANT):
    arrs = [np.ascontiguousarray(vec[k], np.uint32) for k in KEYS]
    one = certified.intersect_certified(arrs, fmt, scale, variant, block=False)
    blk = certified.intersect_certified(arrs, fmt, scale, variant, block=True)
    for key, val in one.items():
        assert np.array_equal(val, blk[key]), (fmt.name, key,
                                               np.flatnonzero((val != blk[key]).reshape(
                                                   len(val), -1).any(1))[:5])
    return one


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f.name)
def test_block_equals_pair_path(fmt):
    rng = np.random.default_rng([21, fmt.man_bits, rmode_code(fmt)])
    # the stress families (flush family included), as encoded
    fam = stress_cases.vectors(fmt, 600, seed=5, special_rate=0.0, random_rate=0.0)
    assert _common_fraction(fam, fmt) > 0.5
    res = _same(fam, fmt)
    decided = res["outcome"] != 2
    assert decided.mean() > 0.1 and (res["outcome"] == 1).any()
    # random patterns: common lanes, overflows, underflows, cancellations
    rnd = _random_patterns(fmt, 400, rng)
    assert _common_fraction(rnd, fmt) > 0.3
    _same(rnd, fmt)
    # special values (zeros, infinities, NaNs, denormals, extremes) mixed into every family
    spec = stress_cases.vectors(fmt, 400, seed=6, special_rate=0.05, random_rate=0.1)
    res = _same(spec, fmt)
    assert (res["event_counts"].sum(1) > 0).sum() > 20


@pytest.mark.parametrize("variant", sorted(certified.VARIANTS))
def test_block_equals_pair_path_variants_and_scale(variant):
    fmt = FPFormat(7, 16, "rne")
    vec = stress_cases.vectors(fmt, 300, seed=8, special_rate=0.01, random_rate=0.05)
    full = _same(vec, fmt, 1.0, variant)
    small = _same(vec, fmt, 2.0 ** -10, variant)
    assert (small["outcome"] != 2).sum() > (full["outcome"] != 2).sum()


def test_block_boundaries():
    """Ranges that are not multiples of the block (a last partial block; pairs not
    starting at zero) give the same rows as the whole run."""
    fmt = FPFormat(6, 13, "rtz")
    vec = stress_cases.vectors(fmt, 2 * BLOCK + 37, seed=9, special_rate=0.01, random_rate=0.05)
    arrs = [np.ascontiguousarray(vec[k], np.uint32) for k in KEYS]
    whole = certified.intersect_certified(arrs, fmt, block=False)
    for lo, hi in ((0, 1), (3, BLOCK + 5), (BLOCK - 1, 2 * BLOCK + 37)):
        part = certified.intersect_certified([a[lo:hi] for a in arrs], fmt, block=True)
        for key, val in whole.items():
            assert np.array_equal(val[lo:hi], part[key]), (lo, hi, key)


SMALL = RenderSettings(width=16, height=16, rows=4, cols=4, shadow_rows=2, shadow_cols=2,
                       progress=False)


def _render(monkeypatch, name, fmt, pairs):
    """A certified render, with every certified pass's counters and pending list."""
    seen = []
    inner = engine_certified.certified_pass

    def recording(*args, **kw):
        ctr, pend = inner(*args, **kw, block=not pairs)
        # best_lo, best_hi, best_tri (arguments 7 to 9) after the pass
        seen.append((ctr.copy(), pend.copy(), np.stack([a.astype(np.float64)
                                                        for a in args[7:10]])))
        return ctr, pend

    monkeypatch.setattr(resolved, "certified_pass", recording)
    result = render(get_scene(name), ModelBackend(fmt, mode="certified"), SMALL)
    monkeypatch.undo()
    return result, seen


@pytest.mark.parametrize("name,fmt", [("soup", FP16), ("cornell", FP24)])
def test_engine_block_equals_pairs(monkeypatch, name, fmt):
    blk, seen_blk = _render(monkeypatch, name, fmt, pairs=False)
    one, seen_one = _render(monkeypatch, name, fmt, pairs=True)
    assert len(seen_blk) == len(seen_one) >= 2                 # primary and shadow passes
    for (cb, pb, tb), (co, po, to) in zip(seen_blk, seen_one):
        assert np.array_equal(cb, co)
        assert np.array_equal(pb, po)
        assert np.array_equal(tb, to, equal_nan=True)
    assert np.array_equal(blk.tri_id, one.tri_id)
    assert np.array_equal(blk.t, one.t)
    assert np.array_equal(blk.visibility, one.visibility, equal_nan=True)
    assert blk.stats["certified"] == one.stats["certified"] | {
        "exact_s": blk.stats["certified"]["exact_s"]}


@pytest.mark.parametrize("any_hit,lanes", [(False, None), (True, None), (False, 8)])
def test_pass_block_equals_pairs_with_pending(monkeypatch, any_hit, lanes):
    """Rays through the shared edges of a fan of triangles (the float64 filter leaves
    them pending): the same counters, pending list (in order) and folded hits; also with
    a lane list too short for a run (it grows) and several lists per range."""
    if lanes:
        monkeypatch.setattr(engine_certified, "LANES", lanes)
    from raplas_hdl.engine.passes import round_runs
    from raplas_hdl.host.spheres import build_sphere_tree

    quad = np.array([[[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, 1.0, 0.0]],
                     [[1.0, 1.0, 0.0], [-1.0, 1.0, 0.0], [1.0, -1.0, 0.0]]])
    tris = np.concatenate([quad + [0.0, 0.0, z] for z in (0.0, 0.5, 1.0, 1.5)])
    backend = ModelBackend(FP24, mode="certified")
    backend.load(tris, build_sphere_tree(tris, 4, 2, np.zeros(len(tris))), 4.0)
    batch = backend.batch(np.array([[0.0, 0.0, -4.0]] * 3), np.zeros((3, 3)),
                          np.array([[0.25, 0.0, 0.0]] * 3), np.array([[0.0, 0.25, 0.0]] * 3),
                          8, 8)
    cr = backend.cull(batch)
    runs = round_runs(cr.start, cr.leaves, None, 0)
    out = []
    for block in (True, False):
        lo = np.full((3, 64), np.inf)
        hi = lo.copy()
        best = np.full((3, 64), -1, np.int64)
        ctr, pend = engine_certified.certified_pass(backend.arithmetic(), backend.scene, batch,
                                                    *runs, backend.tris, lo, hi, best,
                                                    any_hit=any_hit, block=block)
        out.append((ctr, pend, lo, hi, best))
    assert len(out[0][1]) > 0 and (out[0][4] >= 0).any()
    assert out[0][0][:, 2].sum() > BLOCK                        # more than one block
    for a, b in zip(*out):
        assert np.array_equal(a, b)
