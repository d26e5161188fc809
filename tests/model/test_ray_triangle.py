"""Golden model of the ray-triangle unit: operation order, decision rules, special values.

The compiled loop is checked against the same 33 (34) operations composed from the NumPy
API of :mod:`raplas_hdl.fp.model`, written here from the order documented in the model,
and the decision rules against hand-made cases and the float64 reference.
"""

import numpy as np
import pytest

from raplas_hdl.fp import FP24, FP32, FPFormat
from raplas_hdl.fp import model as fpm
from raplas_hdl.host.exact import float64_intersect
from raplas_hdl.model.conservative import margins
from raplas_hdl.model.ray_triangle import intersect
from raplas_hdl.model.stress_cases import vectors
from tests.support.ray_triangle import NAMES, event_pairs


def composed(vec, fmt, mode):
    """The documented operation order, one NumPy-API operation at a time."""
    o, d, v0, e1, e2, n = (vec[k].astype(np.uint32) for k in NAMES)
    flags = np.zeros(len(o), np.uint8)
    counts = np.zeros((len(o), 3), np.uint8)       # operations with each event

    def op(fn, a, b):
        r, f = fn(a, b, fmt, flags=True)
        f2 = f.reshape(len(o), -1)
        flags[:] |= np.bitwise_or.reduce(f2, axis=1)
        for k, bit in enumerate((1, 2, 4)):
            counts[:, k] += np.count_nonzero(f2 & bit, axis=1).astype(np.uint8)
        return r

    def dot(a, b):                      # (a0*b0 + a1*b1) + a2*b2
        p = op(fpm.mul, a, b)
        return op(fpm.add, op(fpm.add, p[:, 0], p[:, 1]), p[:, 2])

    t = op(fpm.sub, v0, o)
    det = dot(n, d)
    tp = dot(n, t)
    # q_k = d_(k+1) t_(k+2) - d_(k+2) t_(k+1)
    i1, i2 = [1, 2, 0], [2, 0, 1]
    q = op(fpm.sub, op(fpm.mul, d[:, i1], t[:, i2]), op(fpm.mul, d[:, i2], t[:, i1]))
    up = fpm.neg(dot(q, e2), fmt)
    vp = dot(q, e1)
    s = op(fpm.add, up, vp)
    z = np.zeros_like(det)
    le, lt = (lambda a, b: fpm.le(a, b, fmt)), (lambda a, b: fpm.lt(a, b, fmt))
    if mode == "paper":
        pos = le(z, up) & le(z, vp) & le(s, det) & le(z, tp)
        neg = le(up, z) & le(vp, z) & le(det, s) & le(tp, z)
        hit = (lt(z, det) & pos) | (lt(det, z) & neg)
    else:
        w = op(fpm.sub, det, s)
        m = margins(o, d, v0, e1, e2, n, fmt)
        nm = {k: fpm.neg(v, fmt) for k, v in m.items()}
        isnan = lambda x: ~le(x, x)                              # noqa: E731
        bad = (isnan(det) | isnan(tp) | isnan(up) | isnan(vp) | isnan(w)
               | ((flags & 1) != 0))
        pos = le(nm["u"], up) & le(nm["v"], vp) & le(nm["w"], w) & le(nm["t"], tp)
        neg = le(up, m["u"]) & le(vp, m["v"]) & le(w, m["w"]) & le(tp, m["t"])
        hit = bad | (le(nm["det"], det) & pos) | (le(det, m["det"]) & neg)
    return {"hit": hit, "t": tp, "u": up, "v": vp, "det": det, "flags": flags,
            "event_counts": counts}


@pytest.mark.parametrize("fmt, mode", [
    (FP24, "paper"), (FP24.with_rounding("chop"), "paper"), (FPFormat(5, 10, "rne"), "paper"),
    (FPFormat(4, 3, "chop"), "paper"), (FP24.with_rounding("rne"), "conservative"),
    (FP32.with_rounding("chop"), "conservative"),
])
def test_model_is_the_documented_operation_order(fmt, mode):
    vec = vectors(fmt, 1500, seed=5, special_rate=0.03, random_rate=0.15)
    got = intersect(*(vec[k] for k in NAMES), fmt, mode=mode)
    exp = composed(vec, fmt, mode)
    for key in exp:
        assert np.array_equal(got[key], exp[key]), key
    assert 0 < got["hit"].sum() < len(got["hit"])
    assert (got["flags"] != 0).any()
    # some pairs raise an event in more than one operation
    assert got["event_counts"].max() >= 2


@pytest.mark.parametrize("fmt, mode", [(FP24, "paper"), (FP24.with_rounding("rne"),
                                                          "conservative"),
                                       (FPFormat(5, 10, "chop"), "paper")])
def test_event_counts_of_constructed_pairs(fmt, mode):
    ops, want = event_pairs(fmt)
    got = intersect(*ops, fmt, mode=mode)
    exp = composed(dict(zip(NAMES, ops)), fmt, mode)
    assert np.array_equal(got["event_counts"], exp["event_counts"])
    assert np.array_equal(got["event_counts"], want)
    # the OR flags are the non-zero counts
    ored = ((got["event_counts"] != 0) * np.array([1, 2, 4])).sum(axis=1)
    assert np.array_equal(got["flags"], ored)


def _case(fmt, o, d, v0, v1, v2):
    v0, v1, v2 = (np.asarray(x, float) for x in (v0, v1, v2))
    e1, e2 = v1 - v0, v2 - v0
    enc = lambda x: fpm.encode(np.atleast_2d(x), fmt)          # noqa: E731
    return (enc(o), enc(d), enc(v0), enc(e1), enc(e2), enc(np.cross(e1, e2)))


TRI = ([0, 0, 0], [1, 0, 0], [0, 1, 0])


@pytest.mark.parametrize("o, d, hit", [
    ([0.25, 0.25, 1], [0, 0, -1], True),       # front, det < 0 for this winding
    ([0.25, 0.25, -1], [0, 0, 1], True),       # back side, det > 0
    ([0.25, 0.25, 1], [0, 0, 1], False),       # triangle behind the origin
    ([0.75, 0.75, 1], [0, 0, -1], False),      # outside the hypotenuse
    ([0.5, 0.5, 1], [0, 0, -1], True),         # exactly on the hypotenuse: closed
    ([0, 0, 1], [0, 0, -1], True),             # exactly through a vertex
    ([0.25, 0.25, 0], [0, 0, -1], True),       # origin on the triangle (t' = 0)
    ([0.25, 0.25, 1], [1, 0, 0], False),       # parallel: det = 0
])
def test_paper_decisions(o, d, hit):
    res = intersect(*_case(FP24, o, d, *TRI), FP24)
    assert bool(res["hit"][0]) is hit


def test_nan_misses_in_paper_mode_and_hits_in_conservative_mode():
    args = list(_case(FP24, [0.25, 0.25, 1], [0, 0, -1], *TRI))
    args[0] = args[0].copy()
    args[0][0, 0] = FP24.nan
    assert not intersect(*args, FP24)["hit"][0]
    assert intersect(*args, FP24, mode="conservative")["hit"][0]


def test_t_over_det_is_the_distance():
    res = intersect(*_case(FP24, [0.2, 0.3, 2.5], [0, 0, -1], *TRI), FP24)
    t = fpm.decode(res["t"], FP24) / fpm.decode(res["det"], FP24)
    assert t[0] == 2.5
    assert res["flags"][0] == 0


def test_agrees_with_float64_on_random_pairs():
    rng = np.random.default_rng(3)
    n = 10000
    v = rng.normal(size=(n, 3, 3))
    o = rng.normal(size=(n, 3)) * 0.5
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    enc = lambda x: fpm.encode(x, FP24)                         # noqa: E731
    res = intersect(enc(o), enc(d), enc(v[:, 0]), enc(e1), enc(e2), enc(np.cross(e1, e2)), FP24)
    ref = float64_intersect(o, d, v[:, 0], v[:, 1], v[:, 2])
    assert ref["hit"].sum() > 500
    assert (res["hit"] != ref["hit"]).mean() < 2e-3
    both = res["hit"] & ref["hit"]
    t = fpm.decode(res["t"], FP24) / fpm.decode(res["det"], FP24)
    assert np.median(np.abs(t[both] / ref["t"][both] - 1)) < 1e-4


@pytest.mark.parametrize("kwargs, word", [
    ({"mode": "exact"}, "mode"),
    ({"mode": "conservative", "margin_scale": 0}, "margin_scale"),
])
def test_bad_options(kwargs, word):
    args = _case(FP24, [0.25, 0.25, 1], [0, 0, -1], *TRI)
    with pytest.raises(ValueError, match=word):
        intersect(*args, FP24, **kwargs)


def test_bad_arrays():
    args = list(_case(FP24, [0.25, 0.25, 1], [0, 0, -1], *TRI))
    with pytest.raises(ValueError, match="shape"):
        intersect(args[0][:, :2], *args[1:], FP24)
    wide = args[1].copy()
    wide[0, 0] = 1 << 24
    with pytest.raises(ValueError, match="wider"):
        intersect(args[0], wide, *args[2:], FP24)
    with pytest.raises(ValueError, match="rows"):
        intersect(np.concatenate([args[0], args[0]]), *args[1:], FP24)
    small = np.zeros((1, 3), np.uint32)
    with pytest.raises(ValueError, match="man_bits"):
        intersect(*([small] * 6), FPFormat(4, 3), mode="conservative")
