"""The certified render: R's answer on every pixel, through the float64 filter and the exact
resolution of what it leaves (issue 13, items 2 and 3)."""

from __future__ import annotations

import numpy as np
import pytest

from raplas_hdl.engine.exact_filter import HIT, MISS, UNDECIDED, filter_pair
from raplas_hdl.fp import FP16, FP24
from raplas_hdl.host.backends import ModelBackend
from raplas_hdl.host.exact import exact_t
from raplas_hdl.host.reference import compare_reference, exact_reference
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene
from tests.support.render import RAW_CONSERVATIVE


def _filter(o, d, tri):
    return np.array([filter_pair(*o[i], *d[i], *tri[i, 0], *tri[i, 1], *tri[i, 2])
                     for i in range(len(o))])


def _pairs(n, rng):
    """Random pairs, half of them aimed at a vertex, an edge point or the centroid."""
    tri = rng.normal(size=(n, 3, 3)) * rng.choice([1e-3, 1.0, 50.0], size=(n, 1, 1))
    o = rng.normal(size=(n, 3)) * 8.0
    w = rng.random((n, 3))
    w[: n // 4] = np.eye(3)[rng.integers(0, 3, n // 4)]              # vertices
    w[n // 4: n // 2, 0] = 0.0                                       # the edge V1-V2
    w /= w.sum(axis=1, keepdims=True)
    target = np.einsum("ij,ijk->ik", w, tri)
    return o, target - o, tri


def test_filter_agrees_with_exact_arithmetic():
    rng = np.random.default_rng(7)
    o, d, tri = _pairs(4000, rng)
    # grazing and parallel rays: directions in the triangle's plane
    n = np.cross(tri[:500, 1] - tri[:500, 0], tri[:500, 2] - tri[:500, 0])
    d[:500] -= (np.einsum("ij,ij->i", d[:500], n) / np.einsum("ij,ij->i", n, n))[:, None] * n
    f = _filter(o, d, tri)
    hit, t = exact_t(o, d, tri[:, 0], tri[:, 1], tri[:, 2])
    st = f[:, 0].astype(int)
    assert ((st == HIT) <= hit).all(), "a filter hit that R misses"
    assert ((st == MISS) <= ~hit).all(), "a filter miss that R hits"
    for i in np.flatnonzero(st == HIT):
        assert f[i, 1] <= t[i] <= f[i, 2], (i, f[i], float(t[i]))
        assert f[i, 2] - f[i, 1] <= 1e-9 * abs(float(t[i])) + 1e-300
    # rays through vertices and edges are the undecided ones, and they are few otherwise
    undecided = st == UNDECIDED
    assert undecided[:2000].mean() > 0.2
    assert undecided[2000:].mean() < 0.01


SMALL = RenderSettings(width=16, height=16, rows=4, cols=4, shadow_rows=2, shadow_cols=2,
                       progress=False, record_rays=True)


@pytest.mark.parametrize("name,fmt", [("cornell", FP24), ("soup", FP24), ("soup", FP16),
                                      ("terrain", FP24)])
def test_certified_render_equals_exact_reference(name, fmt):
    scene = get_scene(name)
    backend = ModelBackend(fmt, mode="certified")
    result = render(scene, backend, SMALL)
    ref = exact_reference(result, scene.triangles, "exact")
    assert compare_reference(result, ref) == {"pixels": 256, "tri_id_differ": 0,
                                              "visibility_differ": 0}
    cert = result.stats["certified"]
    assert cert["uncertain"] + cert["certified_hits"] <= result.stats["pairs_issued"]
    assert cert["filtered"] > 0
    # the unit decides most pairs itself: a unit calling everything uncertain fails here
    assert cert["uncertain_fraction"] < 0.2


def test_reference_sees_the_errors_of_the_other_modes():
    """Negative control: the comparison fails for a render that is not R's (the conservative
    unit's hits folded unchecked pick widened neighbours on the soup), so the equality above
    can fail."""
    scene = get_scene("soup")
    result = render(scene, ModelBackend(FP24, mode=RAW_CONSERVATIVE), SMALL)
    ref = exact_reference(result, scene.triangles, "exact")
    assert compare_reference(result, ref)["tri_id_differ"] > 0


@pytest.mark.parametrize("method", ["filtered", "tree"])
def test_fast_references_equal_exact_reference(method):
    scene = get_scene("soup")
    result = render(scene, ModelBackend(FP24, mode="conservative"), SMALL)
    a = exact_reference(result, scene.triangles, "exact")
    b = exact_reference(result, scene.triangles, method)
    assert (a["tri_id"] == b["tri_id"]).all()
    assert np.array_equal(a["visibility"], b["visibility"], equal_nan=True)


def test_pending_pairs_are_resolved_exactly():
    """A ray through the shared edge of two triangles: the filter cannot decide either pair,
    the exact resolution picks the lower ID at equal t."""
    from raplas_hdl.engine.passes import round_runs
    from raplas_hdl.host.spheres import build_sphere_tree

    tris = np.array([[[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, 1.0, 0.0]],
                     [[1.0, 1.0, 0.0], [-1.0, 1.0, 0.0], [1.0, -1.0, 0.0]]])
    tris = np.concatenate([tris[::-1], tris + [0.0, 0.0, 1.0]])       # IDs 0,1 at z=0
    backend = ModelBackend(FP24, mode="certified")
    tree = build_sphere_tree(tris, 4, 2, np.zeros(len(tris)))
    backend.load(tris, tree, 4.0)
    batch = backend.batch(np.array([[0.0, 0.0, -4.0]]), np.array([[0.0, 0.0, 0.0]]),
                          np.array([[0.5, 0.0, 0.0]]), np.array([[0.0, 0.5, 0.0]]), 1, 1)
    cr = backend.cull(batch)
    best_t = np.full((1, 1), np.inf)
    best_tri = np.full((1, 1), -1, np.int64)
    backend.trace(batch, *round_runs(cr.start, cr.leaves, None, 0), best_t, best_tri)
    assert best_tri[0, 0] == 0
    assert np.isclose(best_t[0, 0] * np.linalg.norm(batch.directions[0, 0]), 4.0)
    assert backend.mode_stats["exact"] >= 2


def test_certified_renders_fp16_where_the_paper_domain_ends():
    """terrain's triangles are outside FP16's domain for paper and conservative mode (edges
    under the minimum); the certified mode has no minimum edge and still gives R's image."""
    scene = get_scene("terrain")
    with pytest.raises(ValueError, match="no usable triangle"):
        render(scene, ModelBackend(FP16, mode="paper"), SMALL)
    result = render(scene, ModelBackend(FP16, mode="certified"), SMALL)
    assert result.stats["skipped_triangles"]["out_of_domain"] == 0
    ref = exact_reference(result, scene.triangles, "tree")
    assert compare_reference(result, ref) == {"pixels": 256, "tri_id_differ": 0,
                                              "visibility_differ": 0}


@pytest.mark.parametrize("name,fmt", [("cornell", FP24), ("soup", FP16)])
def test_certified_t_is_rs_correctly_rounded(name, fmt):
    """Every primary hit's ``t`` is R's exact ``t'/det`` rounded to the nearest float64
    (not a point of the float64 filter's interval)."""
    scene = get_scene(name)
    result = render(scene, ModelBackend(fmt, mode="certified"), SMALL)
    rays = result.rays
    yx = rays["primary_yx"]
    tid = result.tri_id[yx[:, 0], yx[:, 1]]
    hit = tid >= 0
    assert hit.sum() > 50
    tri = scene.triangles[tid[hit]]
    r_hit, t = exact_t(rays["primary_o"][hit], rays["primary_d"][hit], tri[:, 0], tri[:, 1],
                       tri[:, 2])
    assert r_hit.all()
    got = result.t[yx[hit, 0], yx[hit, 1]]
    want = np.array([float(x) for x in t])
    assert np.array_equal(got, want), np.flatnonzero(got != want)[:5]


SECONDARY = RenderSettings(width=20, height=20, rows=4, cols=4, shadow_rows=2, shadow_cols=2,
                           progress=False, record_rays=True, depth=2, glossy_rows=2,
                           glossy_cols=2, ao_rows=2, ao_cols=2, ao_angle=60.0,
                           ao_distance=0.25)


@pytest.mark.parametrize("reduce", [False, True], ids=["unreduced", "reduce"])
def test_certified_secondary_rays_equal_exact_reference(reduce):
    """Every ray type of the showcase (primary, shadow, reflection, refraction, glossy,
    ambient occlusion), ray by ray: R's nearest triangle and its correctly rounded ``t``,
    or R's blocked state; through the model and through the model of the unit with the
    on-chip reduction."""
    from raplas_hdl.host.reference import check_passes

    scene = get_scene("showcase")
    result = render(scene, ModelBackend(FP24, mode="certified", reduce=reduce), SECONDARY)
    got = check_passes(result, scene.triangles, "tree")
    assert {"primary", "shadow", "reflection", "refraction", "glossy", "ao"} <= set(got)
    for kind, row in got.items():
        assert row["rays"] > 0, kind
        assert row["differ"] == 0 and row["t_differ"] == 0, (kind, row)


def test_check_passes_sees_the_errors_of_the_other_modes():
    """Negative control of the check above: the conservative unit's hits folded unchecked
    (on the soup) differ from R on some rays."""
    from raplas_hdl.host.reference import check_passes

    scene = get_scene("soup")
    result = render(scene, ModelBackend(FP24, mode=RAW_CONSERVATIVE), SMALL)
    got = check_passes(result, scene.triangles, "exact")
    assert sum(row["differ"] for row in got.values()) > 0
