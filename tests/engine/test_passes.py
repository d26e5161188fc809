"""The engine's whole passes against the per-run model and the per-bundle cull.

- :func:`raplas_hdl.model.intersection.run_runs` (the model's side of the driver interface)
  gives :func:`~raplas_hdl.model.intersection.run_bundle`'s streams and counters run by run
  (one call of the ray-triangle model for all runs);
- :func:`~raplas_hdl.engine.passes.cull_pass` gives :func:`~raplas_hdl.host.spheres.cull_tree`'s
  leaves and statistics bundle by bundle;
- the compiled trace (nearest hit per ray and counters) equals the pair stream of the same
  runs folded by :func:`~raplas_hdl.host.shading.nearest_hits`, for the model (paper; the
  conservative mode's hits, a superset of R's, resolved exactly) and float64, with ``tmin``/``tmax``/excluded triangles, whatever the thread
  count;
- an over-budget bundle carries the keep-all bit: nothing culls it;
- a render does not depend on the thread count or the pass size.
"""

import numba
import numpy as np
import pytest

from raplas_hdl.engine.passes import round_runs, select_runs
from raplas_hdl.fp import FP24, FP32
from raplas_hdl.host.backends import make_backend
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene
from raplas_hdl.host.shading import nearest_hits
from raplas_hdl.host.spheres import build_sphere_tree, cull_tree
from raplas_hdl.model.intersection import run_bundle, run_runs

BACKENDS = [("model", FP24, "paper"), ("model", FP24.with_rounding("chop"), "conservative"),
            ("model", FP32.with_rounding("rne"), "paper"), ("float64", None, None)]


def _loaded(kind, fmt, mode, n=60, tps=4, fanout=4):
    scene = get_scene("soup", n=n)
    be = make_backend(kind, fmt, mode=mode) if fmt else make_backend(kind)
    tris = scene.triangles
    ok, _ = be.usable(tris)
    ids = np.flatnonzero(ok)
    tree = build_sphere_tree(tris[ids], tps, fanout)
    tree.leaf_tris = np.where(tree.leaf_tris >= 0, ids[tree.leaf_tris.clip(0)], -1)
    be.load(tris, tree, 8.0)
    return be, tree


def _bundles(rng, k, rows=3, cols=5):
    o = rng.uniform(-1, 1, (k, 3)) + [0, 0, 5]
    c = rng.uniform(-0.3, 0.3, (k, 3))
    a = np.tile([1.2, 0, 0], (k, 1)) + rng.uniform(-0.1, 0.1, (k, 3))
    b = np.tile([0, 1.2, 0], (k, 1)) + rng.uniform(-0.1, 0.1, (k, 3))
    return o, c, a, b, rows, cols


def test_run_runs_equals_run_bundle():
    be, tree = _loaded("model", FP24.with_rounding("chop"), "conservative", n=40)
    rng = np.random.default_rng(3)
    batch = be.batch(*_bundles(rng, 6), enable=rng.random((6, 15)) < 0.8)
    runs = []
    for b in range(6):
        ids = np.sort(rng.choice(tree.n_leaves, size=int(rng.integers(0, tree.n_leaves)),
                                 replace=False))
        runs.append((be.memory(batch, b), ids))
    cfg = be.config(3, 5)
    got = run_runs(cfg, be.scene_memory, runs)
    for (mem, ids), (stream, counters) in zip(runs, got):
        out, ref = run_bundle(cfg, be.scene_memory, mem, ids)
        assert counters == ref
        np.testing.assert_array_equal(stream, out)


@pytest.mark.parametrize("kind, fmt, mode", BACKENDS)
def test_cull_pass_equals_cull_tree(kind, fmt, mode):
    be, tree = _loaded(kind, fmt, mode)
    arrs = _bundles(np.random.default_rng(5), 12)
    batch = be.batch(*arrs)
    cr = be.cull(batch)
    tested = np.zeros_like(cr.tested)
    for b in range(12):
        one = be.batch(*[x[b:b + 1] for x in arrs[:4]], 3, 5)
        leaves, st = cull_tree(tree, lambda nodes, one=one: be.touched(one, nodes))
        np.testing.assert_array_equal(cr.leaves[cr.start[b]:cr.start[b + 1]], leaves)
        tested += st.tested
    np.testing.assert_array_equal(cr.tested, tested)
    assert cr.plane_tests == int(tested.sum()) * batch.n_planes


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("kind, fmt, mode", BACKENDS)
def test_trace_equals_stream(kind, fmt, mode, threads):
    be, _ = _loaded(kind, fmt, mode)
    rng = np.random.default_rng(7)
    k = 10
    batch = be.batch(*_bundles(rng, k), enable=rng.random((k, 15)) < 0.85)
    cr = be.cull(batch)
    run_b, run_start, run_sph = round_runs(cr.start, cr.leaves, 3, 0)
    run_b, run_start, run_sph = select_runs(run_b, run_start, run_sph, run_b % 3 != 1)
    tmax = rng.uniform(3, 8, (k, 15))
    exclude = rng.integers(-1, 60, k)
    best_t = np.full((k, 15), np.inf)
    best_tri = np.full((k, 15), -1, np.int64)
    old = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        ctr = be.trace(batch, run_b, run_start, run_sph, best_t, best_tri, 0.5, tmax, exclude)
    finally:
        numba.set_num_threads(old)
    runs = [(int(b), run_sph[run_start[u]:run_start[u + 1]]) for u, b in enumerate(run_b)]
    streams = be.stream(batch, runs)
    want_t = np.full((k, 15), np.inf)
    want_tri = np.full((k, 15), -1, np.int64)
    for u, ((b, _), res) in enumerate(zip(runs, streams)):
        assert dict(zip(res.counters, ctr[u].tolist())) == res.counters
        tri, t, _ = nearest_hits(15, res.ray_id, res.tri_id, res.hit, res.t, 0.5, tmax[b],
                                 exclude[b])
        want_t[b], want_tri[b] = t, tri
    assert sum(r.counters["pairs_issued"] for r in streams) > 100
    if mode == "conservative":
        # the unit's hits are a superset of R's: the trace resolves them to R's nearest
        from raplas_hdl.host.resolve import resolve_pending

        want_t[:], want_tri[:] = np.inf, -1
        pending = np.concatenate([np.stack([np.full(int(r.hit.sum()), b), r.ray_id[r.hit],
                                            r.tri_id[r.hit]], 1)
                                  for (b, _), r in zip(runs, streams)])
        lo = np.full((k, 15), np.inf)
        resolve_pending(pending, batch.origin, batch.directions, be.tris, lo, lo.copy(),
                        want_tri, want_t, 0.5, tmax, exclude)
        np.testing.assert_array_equal(best_tri, want_tri)
        np.testing.assert_allclose(best_t, want_t, rtol=1e-12)
        return
    np.testing.assert_array_equal(best_tri, want_tri)
    np.testing.assert_array_equal(best_t, want_t)


@pytest.mark.parametrize("kind, fmt, mode", BACKENDS[:2])
def test_over_budget_bundle_is_never_culled(kind, fmt, mode):
    """A bundle whose origin is beyond the budget's o_max gets the keep-all bit: the host
    sends every leaf and the unit keeps every sphere, so every enabled ray meets every
    triangle of every run."""
    be, tree = _loaded(kind, fmt, mode)
    rng = np.random.default_rng(11)
    o, c, a, b, rows, cols = _bundles(rng, 3)
    o[1] = [0.0, 0.0, 40.0]               # |O| > o_max = 2 * bound = 16
    o[0], c[0] = [8.0, 0.0, 0.0], [8.0, 0.0, -1.0]   # bundle 0 passes beside the scene
    batch = be.batch(o, c, a, b, rows, cols)
    assert batch.keep_all.tolist() == [False, True, False]
    cr = be.cull(batch)
    np.testing.assert_array_equal(cr.leaves[cr.start[1]:cr.start[2]], np.arange(tree.n_leaves))
    assert cr.start[1] - cr.start[0] < tree.n_leaves        # bundle 0 is culled
    run_b, run_start, run_sph = round_runs(cr.start, cr.leaves, None, 0)
    best_t = np.full((3, 15), np.inf)
    best_tri = np.full((3, 15), -1, np.int64)
    ctr = be.trace(batch, run_b, run_start, run_sph, best_t, best_tri)
    n_tris = int(be.scene.tcount.sum())
    assert ctr[1, 2] == 15 * n_tris                         # pairs issued: all of them
    assert ctr[1, 1] == tree.n_leaves * (rows + cols)       # plane tests still counted
    # the unit's own side: the bundle's run carries the keep-all bit to the model (and RTL)
    res = be.stream(batch, [(1, np.arange(tree.n_leaves))])[0]
    assert res.counters["pairs_issued"] == 15 * n_tris
    if kind == "model":
        assert be.memory(batch, 1).keep_all and not be.memory(batch, 0).keep_all


def _render(kind, fmt, mode, **kw):
    scene = get_scene("spheres", subdivisions=1, floor_subdiv=2)
    st = RenderSettings(width=24, height=20, rows=4, cols=4, shadow_rows=2, shadow_cols=3,
                        batch_spheres=3, progress=False, **kw)
    be = make_backend(kind, fmt, mode=mode) if fmt else make_backend(kind)
    return render(scene, be, st)


@pytest.mark.parametrize("kind, fmt, mode", [BACKENDS[0], BACKENDS[3]])
def test_render_independent_of_threads_and_pass_size(kind, fmt, mode):
    a = _render(kind, fmt, mode, threads=1, chunk=4096)
    b = _render(kind, fmt, mode, threads=2, chunk=7)
    for name in ("image", "tri_id", "t", "visibility"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    for key in ("unit", "hierarchy", "pairs_issued", "plane_tests", "early_out_pairs_skipped",
                "shadow_spheres_skipped"):
        assert a.stats[key] == b.stats[key], key
    assert a.stats["pairs_issued"] > 0 and a.stats["shadow_bundles"] > 0
