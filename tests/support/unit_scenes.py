"""Scenes and run lists shared by the intersection-unit tests (RTL against the model)."""

import numpy as np

from raplas_hdl.fp import model as fpm
from raplas_hdl.model.intersection import run_bundle
from raplas_hdl.model.memory_image import BundleMemory, Run, as_run
from raplas_hdl.sim.drive.unit_driver import random_bundle, random_scene


def aimed_bundle(config, scene, seed, disable=0.0, spread=0.12):
    """A bundle aimed at one of the scene's spheres (so that it has hits)."""
    rng = np.random.default_rng(seed)
    s = int(rng.integers(0, scene.n_spheres))
    target = fpm.decode(scene.centres[s], config.fmt)
    return random_bundle(config, seed=seed, disable=disable, spread=spread, target=target)


def with_enable(bundle, enable):
    return BundleMemory(bundle.plane_n, bundle.plane_p, bundle.ray_o, bundle.ray_d, enable)


def extreme_directions(config, bundle):
    """The bundle with its planes but ray directions that make the ray-triangle
    operations raise every event, several times per pair: every third ray scaled up by
    ``2**emax`` (overflow), the next scaled down by ``2**(4 - emax)`` (underflow), the
    next with x and y infinite (invalid: infinities cancelling or times zero)."""
    f = config.fmt
    d = fpm.decode(bundle.ray_d, f)
    k = np.arange(config.n_rays) % 3
    d[k == 0] *= 2.0 ** f.emax
    d[k == 1] *= 2.0 ** (4 - f.emax)
    d[k == 2, :2] = np.inf
    return BundleMemory(bundle.plane_n, bundle.plane_p, bundle.ray_o, fpm.encode(d, f),
                        bundle.enable)


def assert_operation_events(ref):
    """The model's runs raise every event, and count operations, not pairs: each event
    counter is above the number of pairs whose ORed flags have the event."""
    for bit, name in ((1, "overflow"), (2, "underflow"), (4, "invalid")):
        ops = sum(ctr[name] for _, ctr in ref)
        pairs = sum(int(np.count_nonzero(out["flags"][out["empty"] == 0] & bit))
                    for out, _ in ref)
        assert 0 < pairs < ops, f"{name}: {ops} operations in {pairs} pairs"


def scene_and_runs(config, n_tris, seed=0, size=1.2, extent=4.0):
    """A scene and a list of runs that covers every feature of the unit.

    Runs: all spheres (range); another bundle (the other bank) with a sphere list with
    repeats; the same bundle with more rays disabled (enable bits rewritten only); an
    empty list; a *keep-all* run (nothing culled) of a few spheres with a quarter of the
    rays disabled; a range whose rays are all disabled (an empty run that skips pairs); and
    the first bundle's planes again, with extreme ray directions (arithmetic events,
    :func:`extreme_directions`).
    """
    rng = np.random.default_rng(seed)
    scene = random_scene(config, n_tris, seed=seed, size=size, extent=extent, empty_spheres=2)
    s = scene.n_spheres
    a = aimed_bundle(config, scene, seed + 1, disable=0.2)
    b = aimed_bundle(config, scene, seed + 2)
    b2 = with_enable(b, b.enable & (rng.random(config.n_rays) < 0.5))
    c = aimed_bundle(config, scene, seed + 3)
    off = with_enable(c, np.zeros(config.n_rays, bool))
    ids = rng.integers(0, s, max(4, s // 2))
    keep = with_enable(c, rng.random(config.n_rays) >= 0.25)
    runs = [(a, None), (b, ids), (b2, np.arange(s // 3, s)), (c, np.zeros(0, np.int64)),
            Run(keep, rng.permutation(s)[:min(s, 6)], keep_all=True),
            (off, np.arange(0, s)), (extreme_directions(config, a), np.arange(1, s // 2))]
    return scene, runs


def model_runs(config, scene, runs):
    return [run_bundle(config, scene, b, None if ids is None else np.asarray(ids),
                       keep_all=keep_all) for b, ids, keep_all in map(as_run, runs)]


def assert_keep_all(config, scene, runs, ref):
    """Every keep-all run issued every enabled ray against every triangle of its spheres
    (and skipped those of the disabled rays), where the culled run would have issued
    fewer pairs."""
    kept = [(run, r) for run, r in zip(map(as_run, runs), ref) if run.keep_all]
    assert kept, "no keep-all run"
    for run, (out, ctr) in kept:
        ids = np.arange(scene.n_spheres) if run.sphere_ids is None else run.sphere_ids
        tris = int(scene.tri_counts[np.asarray(ids)].sum())
        enabled = int(run.bundle.enable.sum())
        assert ctr["pairs_issued"] == enabled * tris
        assert ctr["pairs_skipped"] == (config.n_rays - enabled) * tris
        assert ctr["plane_tests"] == len(ids) * config.n_planes
        culled = run_bundle(config, scene, run.bundle, np.asarray(ids))[1]
        assert culled["pairs_issued"] < ctr["pairs_issued"], "the keep-all run culls nothing"


def check_against_model(config, scene, runs, results, *, overlap=False):
    """Every run's stream equal to the model's; counters per run (or summed, overlap)."""
    ref = model_runs(config, scene, runs)
    for k, ((stream, ctr), (rstream, rctr)) in enumerate(zip(results, ref)):
        assert stream.dtype == rstream.dtype
        assert len(stream) == len(rstream), f"run {k}: {len(stream)} beats, model " \
                                            f"{len(rstream)}"
        bad = np.nonzero(stream != rstream)[0]
        assert bad.size == 0, f"run {k}: beat {bad[0]} differs: {stream[bad[0]]} against " \
                              f"the model's {rstream[bad[0]]}"
        if not overlap:
            assert {n: ctr[n] for n in rctr} == rctr, f"run {k}: counters {ctr} != {rctr}"
            assert ctr["cycles"] > 0
    if overlap:
        total = {n: sum(r[1][n] for r in ref) for n in ref[0][1]}
        ctr = results[-1][1]
        assert {n: ctr[n] for n in total} == total
    return ref
