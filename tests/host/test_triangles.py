"""Triangle records and the references R (exact) and float64, against Fraction arithmetic."""

from fractions import Fraction

import numpy as np
import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.fp import model as fpm
from raplas_hdl.host.exact import exact_intersect, exact_intersect_bits, float64_intersect
from raplas_hdl.host.triangles import exact_edges, make_triangles
from raplas_hdl.model.conservative import domain


def _fr(x):
    return [Fraction(float(v)) for v in x]


def _fcross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _fdot(a, b):
    return sum(x * y for x, y in zip(a, b))


def _oracle(o, d, v0, v1, v2):
    """Moller-Trumbore in Fractions, written independently of the module."""
    o, d, v0, v1, v2 = (_fr(x) for x in (o, d, v0, v1, v2))
    e1 = [b - a for a, b in zip(v0, v1)]
    e2 = [b - a for a, b in zip(v0, v2)]
    n = _fcross(e1, e2)
    t = [a - b for a, b in zip(v0, o)]
    det = _fdot(n, d)
    if det == 0:
        return False, None
    tt = _fdot(n, t) / det
    q = _fcross(d, t)
    u = -_fdot(q, e2) / det
    v = _fdot(q, e1) / det
    return (u >= 0 and v >= 0 and u + v <= 1 and tt >= 0), tt


def _wide_vertices(rng, n):
    mags = 2.0 ** rng.integers(-30, 30, (n, 3, 3))
    return rng.normal(size=(n, 3, 3)) * mags


def test_exact_edges_are_correctly_rounded():
    rng = np.random.default_rng(1)
    vs = _wide_vertices(rng, 200)
    e1, e2, n, zero = exact_edges(vs[:, 0], vs[:, 1], vs[:, 2])
    assert not zero.any()
    for i in range(len(vs)):
        a, b, c = (_fr(vs[i, k]) for k in range(3))
        fe1 = [y - x for x, y in zip(a, b)]
        fe2 = [y - x for x, y in zip(a, c)]
        assert list(e1[i]) == [float(x) for x in fe1]
        assert list(e2[i]) == [float(x) for x in fe2]
        assert list(n[i]) == [float(x) for x in _fcross(fe1, fe2)]


def test_records_encode_the_exact_edges():
    rng = np.random.default_rng(2)
    vs = rng.normal(size=(100, 3, 3))
    recs = make_triangles(vs, FP24)
    e1, e2, n, _ = exact_edges(vs[:, 0], vs[:, 1], vs[:, 2])
    assert np.array_equal(recs.e1_bits, fpm.encode(e1, FP24))
    assert np.array_equal(recs.n_bits, fpm.encode(n, FP24))
    assert np.array_equal(recs.v0_bits, fpm.encode(vs[:, 0], FP24))
    assert list(recs.ids) == list(range(100)) and recs.n_skipped == 0


BAD = {
    "repeated": ([0, 0, 0], [1, 1, 1], [1, 1, 1]),
    "collinear": ([0, 0, 0], [1, 2, 3], [2, 4, 6]),
    "nan": ([0, 0, np.nan], [1, 0, 0], [0, 1, 0]),
    "inf": ([0, 0, 0], [np.inf, 0, 0], [0, 1, 0]),
    "tiny": ([0, 0, 0], [1e-25, 0, 0], [0, 1e-25, 0]),
}


@pytest.mark.parametrize("name, words", [
    ("repeated", "degenerate"), ("collinear", "degenerate"), ("nan", "NaN or infinite"),
    ("inf", "NaN or infinite"), ("tiny", "too small")])
def test_bad_triangles_raise(name, words):
    good = ([0, 0, 0], [1, 0, 0], [0, 1, 0])
    with pytest.raises(ValueError, match=f"triangle 1 .*{words}"):
        make_triangles([good, BAD[name]], FP24)


def test_bad_triangles_are_counted_when_skipped():
    good = ([0, 0, 0], [1, 0, 0], [0, 1, 0])
    far = ([0, 0, 0], [2.0 ** 20, 0, 0], [0, 1, 0])
    tris = [good, BAD["repeated"], BAD["nan"], good, BAD["collinear"], BAD["tiny"], far]
    recs = make_triangles(tris, FP24, on_bad="skip", check_domain=True)
    assert list(recs.ids) == [0, 3]
    assert recs.skipped == {"nonfinite": 1, "degenerate": 2, "flushed": 1, "out_of_domain": 1}
    assert list(recs.skipped_ids["degenerate"]) == [1, 4]
    assert domain(FP24).max_coord < 2.0 ** 20
    # without the domain check the far triangle is kept
    assert len(make_triangles(tris, FP24, on_bad="skip")) == 3


def test_exact_reference_against_fractions():
    rng = np.random.default_rng(3)
    n = 300
    v = rng.normal(size=(n, 3, 3)) * 2.0 ** rng.integers(-8, 8, (n, 1, 1))
    o = rng.normal(size=(n, 3))
    d = rng.normal(size=(n, 3))
    # aim a third of the rays at vertices and edge points: exact boundary cases
    tgt = v[:, 0] + rng.integers(0, 2, (n, 1)) * 0.5 * (v[:, 1] - v[:, 0])
    d[: n // 3] = (tgt - o)[: n // 3]
    r = exact_intersect(o, d, v[:, 0], v[:, 1], v[:, 2])
    for i in range(n):
        hit, tt = _oracle(o[i], d[i], v[i, 0], v[i, 1], v[i, 2])
        assert bool(r["hit"][i]) == hit, i
        if tt is not None:
            assert r["t"][i] == float(tt)
    assert 0 < r["hit"].sum() < n


def test_exact_reference_is_watertight_on_a_shared_edge():
    rng = np.random.default_rng(4)
    # exactly coplanar (z = 0) triangles sharing the edge a-b; rays aimed at points of the
    # edge (the float64 direction misses the exact point a little, to either side)
    a, b = np.array([0.0, 0.0, 0.0]), np.array([4.0, 2.0, 0.0])
    c1, c2 = np.array([1.0, 3.0, 0.0]), np.array([2.0, -3.0, 0.0])
    o = rng.normal(size=(500, 3)) * 3
    o[:, 2] = np.abs(o[:, 2]) + 0.1
    lam = rng.uniform(0.01, 0.99, (500, 1))
    d = a + lam * (b - a) - o
    t1 = exact_intersect(o, d, *(np.tile(x, (500, 1)) for x in (a, b, c1)))
    t2 = exact_intersect(o, d, *(np.tile(x, (500, 1)) for x in (b, a, c2)))
    assert (t1["hit"] | t2["hit"]).all()


def test_r_uses_the_encoded_ray():
    o = np.array([[0.1, 0.1, 1.0]])
    d = np.array([[0.0, 0.0, -1.0]])
    tri = [np.array([[0.0, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]])]
    r = exact_intersect_bits(fpm.encode(o, FP24), fpm.encode(d, FP24), *tri, FP24)
    exact_t = Fraction(fpm.decode(fpm.encode(o, FP24), FP24)[0, 2])
    assert r["hit"][0] and r["t"][0] == float(exact_t)


def test_float64_reference_agrees_with_r():
    rng = np.random.default_rng(5)
    n = 3000
    v = rng.normal(size=(n, 3, 3))
    o = rng.normal(size=(n, 3)) * 0.5
    d = rng.normal(size=(n, 3))
    f = float64_intersect(o, d, v[:, 0], v[:, 1], v[:, 2])
    r = exact_intersect(o, d, v[:, 0], v[:, 1], v[:, 2])
    assert r["hit"].sum() > 100
    assert (f["hit"] != r["hit"]).sum() <= 2
    both = f["hit"] & r["hit"]
    assert np.allclose(f["t"][both], r["t"][both], rtol=1e-9)
