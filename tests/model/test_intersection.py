"""The intersection unit's transaction-level model against a plain per-pair loop.

Culled runs and keep-all runs (the run command's ``keep_all`` bit: every plane keeps every
sphere, for a bundle over the culling budget)."""

import numpy as np
import pytest

from raplas_hdl.fp import FP16, FP24
from raplas_hdl.model.intersection import RESULT_DTYPE, run_bundle
from raplas_hdl.host.culling import CullingBudget, bundle_slack
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.memory_image import (REGIONS, BundleMemory, Run, SceneMemory, as_run,
                                           bundle_writes, run_list_writes, scene_writes,
                                           write_address)
from raplas_hdl.model.plane_sphere import tester_flags as plane_flags
from raplas_hdl.model.ray_triangle import intersect
from raplas_hdl.sim.drive.unit_driver import random_bundle, random_scene


def ref_run(config, scene, bundle, ids, keep_all=False):
    """One pair at a time, straight from the definition of the stream."""
    beats = []
    skipped = 0
    events = np.zeros(3, np.int64)
    keep = plane_flags(bundle.plane_n, bundle.plane_p, scene.centres, scene.radii, config.fmt)
    if keep_all:
        keep = np.ones_like(keep)
    for s in ids:
        for i in range(config.rows):
            if not keep[s, i]:
                continue
            for j in range(config.cols):
                if not keep[s, config.rows + j]:
                    continue
                ray = i * config.cols + j
                for k in range(int(scene.tri_counts[s])):
                    tri = int(scene.tri_lists[s, k])
                    if not bundle.enable[ray]:
                        skipped += 1
                        continue
                    r = intersect(bundle.ray_o[ray:ray + 1], bundle.ray_d[ray:ray + 1],
                                  scene.v0[tri:tri + 1], scene.e1[tri:tri + 1],
                                  scene.e2[tri:tri + 1], scene.n[tri:tri + 1], config.fmt,
                                  mode=config.mode)
                    events += r["event_counts"][0]
                    beats.append((ray, tri, int(r["hit"][0]), int(r["t"][0]), int(r["u"][0]),
                                  int(r["v"][0]), int(r["det"][0]), int(r["flags"][0]), 0, 0))
    if not beats:
        beats.append((0,) * 8 + (1, 1))
    else:
        beats[-1] = beats[-1][:8] + (1, 0)
    return np.array(beats, RESULT_DTYPE), skipped, events


def check_run(config, scene, bundle, ids=None, keep_all=False):
    out, ctr = run_bundle(config, scene, bundle, ids, keep_all=keep_all)
    ids_ = np.arange(scene.n_spheres) if ids is None else np.asarray(ids)
    ref, skipped, events = ref_run(config, scene, bundle, ids_, keep_all)
    assert out.dtype == RESULT_DTYPE
    assert np.array_equal(out, ref)
    real = out[out["empty"] == 0]
    assert ctr == {"spheres": len(ids_), "plane_tests": len(ids_) * config.n_planes,
                   "pairs_issued": len(real), "pairs_skipped": skipped,
                   "hits": int(real["hit"].sum()),
                   "overflow": int(events[0]), "underflow": int(events[1]),
                   "invalid": int(events[2])}
    # an operation count is at least the number of pairs whose OR flag is set
    for bit, name in ((1, "overflow"), (2, "underflow"), (4, "invalid")):
        assert ctr[name] >= np.count_nonzero(real["flags"] & bit)
    assert out["last"].sum() == 1 and out["last"][-1] == 1
    return out, ctr


CFG = UnitConfig(rows=3, cols=5, tris_per_sphere=4, max_triangles=128, max_spheres=64)


@pytest.fixture(scope="module")
def scene():
    return random_scene(CFG, 60, seed=3, empty_spheres=2)


def test_model_matches_loop_all_spheres(scene):
    out, ctr = check_run(CFG, scene, random_bundle(CFG, seed=1, disable=0.3, spread=0.3))
    assert ctr["pairs_issued"] > 20 and ctr["pairs_skipped"] > 0


def test_model_matches_loop_list_with_repeats(scene):
    rng = np.random.default_rng(5)
    ids = rng.integers(0, scene.n_spheres, 40)
    check_run(CFG, scene, random_bundle(CFG, seed=2, spread=0.3), ids)


def test_model_hits_present():
    cfg = UnitConfig(rows=4, cols=4, tris_per_sphere=8, max_triangles=512, max_spheres=256)
    sc = random_scene(cfg, 400, seed=7, size=1.5)
    hits = 0
    for seed in range(3):
        out, ctr = check_run(cfg, sc, random_bundle(cfg, seed=seed, spread=0.2))
        hits += ctr["hits"]
    assert hits > 0


def test_model_empty_run(scene):
    out, ctr = check_run(CFG, scene, random_bundle(CFG, seed=1), np.zeros(0, np.int64))
    assert len(out) == 1 and out["empty"][0] == 1 and ctr["spheres"] == 0
    # all rays disabled: pairs are skipped, the run is empty
    b = random_bundle(CFG, seed=1, disable=1.0, spread=0.3)
    out, ctr = check_run(CFG, scene, b)
    assert len(out) == 1 and out["empty"][0] == 1 and ctr["pairs_skipped"] > 0


def test_model_keep_all_over_budget(scene):
    """A bundle over the culling budget (its origin beyond ``o_max``) run with ``keep_all``:
    the masks are all ones, so the stream is every enabled ray (ascending) against every
    triangle of every sphere of the run (list order), whatever the planes say; the counters
    count as usual."""
    budget = CullingBudget(CFG.fmt, o_max=8.0)
    b = random_bundle(CFG, seed=6, disable=0.3, spread=0.2, origin=np.array([0.5, 0.0, -40.0]))
    slack = bundle_slack(b.plane_n, b.plane_p, b.ray_o[0], b.ray_d, CFG.rows, CFG.cols, CFG.fmt)
    assert not budget.admits(slack), "the bundle must be over budget"
    rng = np.random.default_rng(8)
    ids = rng.integers(0, scene.n_spheres, 12)         # a list with repeats
    out, ctr = check_run(CFG, scene, b, ids, keep_all=True)
    want = [(ray, int(scene.tri_lists[s, k])) for s in ids for ray in range(CFG.n_rays)
            if b.enable[ray] for k in range(int(scene.tri_counts[s]))]
    assert list(zip(out["ray_id"].tolist(), out["tri_id"].tolist())) == want
    tris = int(scene.tri_counts[ids].sum())
    disabled = int(np.count_nonzero(~b.enable))
    assert 0 < disabled < CFG.n_rays
    assert ctr["spheres"] == 12 and ctr["plane_tests"] == 12 * CFG.n_planes
    assert ctr["pairs_issued"] == (CFG.n_rays - disabled) * tris
    assert ctr["pairs_skipped"] == disabled * tris
    # a bundle marked keep_all runs the same without the argument
    marked = BundleMemory(b.plane_n, b.plane_p, b.ray_o, b.ray_d, b.enable, keep_all=True)
    out2, ctr2 = run_bundle(CFG, scene, marked, ids)
    assert np.array_equal(out2, out) and ctr2 == ctr
    # the same run culled keeps fewer pairs: the bit is what lets them through
    _, culled = run_bundle(CFG, scene, b, ids)
    assert culled["pairs_issued"] < ctr["pairs_issued"]
    assert {k: culled[k] for k in ("spheres", "plane_tests")} == \
        {k: ctr[k] for k in ("spheres", "plane_tests")}


def test_model_keep_all_empty_runs(scene):
    b = random_bundle(CFG, seed=1, spread=0.3)
    out, ctr = check_run(CFG, scene, b, np.zeros(0, np.int64), keep_all=True)
    assert len(out) == 1 and out["empty"][0] == 1 and ctr["plane_tests"] == 0
    off = BundleMemory(b.plane_n, b.plane_p, b.ray_o, b.ray_d, np.zeros(CFG.n_rays, bool))
    out, ctr = check_run(CFG, scene, off, keep_all=True)
    assert len(out) == 1 and out["empty"][0] == 1
    assert ctr["pairs_skipped"] == CFG.n_rays * int(scene.tri_counts.sum())


def test_runs():
    b = random_bundle(CFG, seed=0)
    assert as_run((b, None)) == Run(b, None, False)
    assert as_run((b, [1, 2], 1)).keep_all is True
    assert as_run(Run(b, keep_all=True)) == (b, None, True)
    marked = BundleMemory(b.plane_n, b.plane_p, b.ray_o, b.ray_d, b.enable, keep_all=True)
    assert as_run((marked, None)).keep_all is True          # the bundle's mark
    assert as_run(Run(marked, [1], False)).keep_all is True
    with pytest.raises(ValueError, match="a run is"):
        as_run((b,))
    with pytest.raises(ValueError, match="BundleMemory"):
        as_run(("bundle", None))


def test_model_conservative_and_fp16():
    cfg = UnitConfig(fmt=FP16, rows=2, cols=3, tris_per_sphere=3, max_triangles=64,
                     max_spheres=64, mode="conservative")
    sc = random_scene(cfg, 40, seed=11)
    check_run(cfg, sc, random_bundle(cfg, seed=4, spread=0.4))


@pytest.mark.parametrize("kw, word", [
    ({"rows": 0}, "rows"), ({"cols": 65}, "cols"), ({"testers": 0}, "testers"),
    ({"tris_per_sphere": 0}, "tris_per_sphere"), ({"max_triangles": 0}, "max_triangles"),
    ({"max_spheres": 1.5}, "max_spheres"), ({"mode": "exact"}, "mode"),
    ({"fifo_depth": 1}, "fifo_depth"), ({"fmt": "FP24"}, "fmt"),
    ({"margin_scale": 0}, "margin_scale")])
def test_config_errors(kw, word):
    with pytest.raises(ValueError, match=word):
        UnitConfig(**kw)


def test_memory_errors(scene):
    small = UnitConfig(rows=3, cols=5, tris_per_sphere=2, max_triangles=128, max_spheres=64)
    with pytest.raises(ValueError, match="tris_per_sphere"):
        scene.check(small)
    with pytest.raises(ValueError, match="max_triangles"):
        scene.check(UnitConfig(rows=3, cols=5, tris_per_sphere=4, max_triangles=8))
    with pytest.raises(ValueError, match="triangle ID"):
        SceneMemory(scene.v0[:2], scene.e1[:2], scene.e2[:2], scene.n[:2], scene.centres,
                    scene.radii, scene.tri_lists, scene.tri_counts)
    b = random_bundle(CFG, seed=0)
    with pytest.raises(ValueError, match="rows\\*cols"):
        BundleMemory(b.plane_n, b.plane_p, b.ray_o[:4], b.ray_d[:4]).check(CFG)
    with pytest.raises(ValueError, match="sphere_ids"):
        run_bundle(CFG, scene, b, [scene.n_spheres])
    with pytest.raises(ValueError, match="wider"):
        BundleMemory(b.plane_n, b.plane_p, b.ray_o, b.ray_d | (1 << 30)).check(CFG)


def test_address_map(scene):
    assert write_address("ray", 5, 6, bank=1) == (4 << 28) | (1 << 27) | (5 << 4) | 6
    a, d = scene_writes(CFG, scene)
    region = a >> 28
    assert np.count_nonzero(region == REGIONS["tri"]) == 12 * scene.n_triangles
    assert np.count_nonzero(region == REGIONS["sphere"]) == 5 * scene.n_spheres
    assert np.count_nonzero(region == REGIONS["tlist"]) == int(scene.tri_counts.sum())
    b = random_bundle(CFG, seed=0)
    a, d = bundle_writes(CFG, b, 1)
    assert np.all((a >> 27) & 1 == 1) and a.size == 4 * CFG.n_planes + 7 * CFG.n_rays
    a, d = run_list_writes(CFG, [3, 1], 0)
    assert list(d) == [3, 1] and list(a & 0xF) == [0, 0]
    with pytest.raises(ValueError, match="bank"):
        write_address("ray", 0, 0, bank=2)
    assert FP24.width == 24
