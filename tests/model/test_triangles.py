"""Triangle records (:mod:`raplas_hdl.model.triangles`) against Fraction arithmetic."""

from fractions import Fraction

import numpy as np
import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.fp import model as fpm
from raplas_hdl.model.conservative import domain
from raplas_hdl.model.triangles import exact_edges, make_triangles


def _fr(x):
    return [Fraction(float(v)) for v in x]


def _fcross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


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
