"""The references R (exact, :mod:`raplas_hdl.host.exact`) and float64, against Fraction
arithmetic."""

from fractions import Fraction

import numpy as np

from raplas_hdl.fp import FP24
from raplas_hdl.fp import model as fpm
from raplas_hdl.host.exact import exact_intersect, exact_intersect_bits, float64_intersect


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
