"""Nearest-hit selection, shadow bundles and Phong shading."""

import numpy as np

from raplas_hdl.host.scene import AreaLight, Material
from raplas_hdl.host.shading import nearest_hits, phong, shadow_bundles


def test_nearest_hit_filters_and_ties():
    ray = np.array([0, 0, 0, 1, 1, 2, 2, 3])
    tri = np.array([5, 3, 7, 1, 2, 9, 4, 6])
    hit = np.array([1, 1, 1, 1, 1, 1, 1, 0], bool)
    t = np.array([2.0, 2.0, 1.0, 0.5, 3.0, 7.0, 6.0, 0.1])
    best, bt, idx = nearest_hits(4, ray, tri, hit, t, tmin=1.5, tmax=[10, 10, 6.5, 10])
    # ray 0: t=1 is below tmin, t=2 ties between 5 and 3 -> lowest ID 3
    # ray 1: t=0.5 below tmin -> tri 2; ray 2: 7.0 beyond tmax -> 4; ray 3: no hit
    assert best.tolist() == [3, 2, 4, -1]
    assert bt.tolist() == [2.0, 3.0, 6.0, np.inf]
    assert idx.tolist() == [1, 4, 6, -1]
    # order of the stream does not matter
    p = np.random.default_rng(0).permutation(len(ray))
    assert nearest_hits(4, ray[p], tri[p], hit[p], t[p], 1.5, [10, 10, 6.5, 10])[0].tolist() \
        == [3, 2, 4, -1]
    # exclusion of a ray's own triangle
    best, _, _ = nearest_hits(4, ray, tri, hit, t, tmin=1.5, exclude_tri=[3, -1, -1, -1])
    assert best[0] == 5
    # NaN distances never win
    best, _, _ = nearest_hits(1, [0, 0], [1, 2], [True, True], [np.nan, 4.0])
    assert best.tolist() == [2]


def test_shadow_bundles_counts():
    light = AreaLight((-1, 4, -1), (2, 0, 0), (0, 0, 2))          # faces -y
    pts = np.array([[0, 0, 0], [0, 5, 0], [0, 4, 0], [3, 0, 0], [0, 0, 0.5]], float)
    nrm = np.array([[0, 1, 0], [0, 1, 0], [0, 1, 0], [0, 1, 0], [0, -1, 0]], float)
    plan = shadow_bundles(pts, nrm, light, 3, 2, eps=1e-3)
    assert plan.point.tolist() == [0, 3]
    assert plan.behind_light == 2            # above and on the light's plane
    assert plan.facing_away == 1
    b = plan.bundles[0]
    assert b.rows == 3 and b.cols == 2
    np.testing.assert_allclose(b.origin, [0, 1e-3, 0])
    # lattice = cell centres of the light
    np.testing.assert_allclose(b.points[0, 0], [-1 + 1 / 3, 4, -0.5])
    np.testing.assert_allclose(plan.tmax[0], np.linalg.norm(b.points.reshape(-1, 3)
                                                            - b.origin, axis=1) - 1e-3)


def test_phong_terms():
    light = AreaLight((-0.5, 2, -0.5), (1, 0, 0), (0, 0, 1), (1.0, 1.0, 1.0))
    mat = Material(ambient=0.1, diffuse=0.6, specular=0.3, shininess=10)
    p = np.zeros((1, 3))
    n = np.array([[0.0, 1.0, 0.0]])
    alb = np.array([[0.5, 0.5, 0.5]])
    eye = np.array([0.0, 5.0, 0.0])                # straight above: R.V = 1
    lit = phong(p, n, alb, eye, light, mat, np.array([1.0]))
    dark = phong(p, n, alb, eye, light, mat, np.array([0.0]))
    np.testing.assert_allclose(dark, 0.1 * alb)
    np.testing.assert_allclose(lit, 0.1 * alb + 0.6 * alb + 0.3)
    half = phong(p, n, alb, eye, light, mat, np.array([0.5]))
    np.testing.assert_allclose(half, (lit + dark) / 2)
