"""The model's side of the unit interface: runs in, result streams and counters out.

:func:`run_runs` has the signature of the RTL driver's
(:func:`raplas_hdl.sim.unit_driver.run_runs` without the simulator): a unit configuration,
the scene's memories and a list of runs ``(bundle memory, sphere ids)``; it returns, per
run, the result stream (a structured array of
:data:`~raplas_hdl.model.intersection.RESULT_DTYPE`) and the unit's counters, bit for bit
what :func:`raplas_hdl.model.intersection.run_bundle` gives for that run alone. The pairs
of all runs go through one call of the ray-triangle model (the per-pair arithmetic does
not depend on the other pairs).
"""

from __future__ import annotations

import numpy as np

from ..model.intersection import (RESULT_DTYPE, _sphere_ids, empty_counters, enumerate_pairs,
                                  event_counters)
from ..model.memory_image import BundleMemory, SceneMemory, UnitConfig, as_run
from ..model.plane_sphere import tester_flags
from ..model.ray_triangle import intersect

__all__ = ["run_runs"]


def _masks(config: UnitConfig, scene: SceneMemory, bundle: BundleMemory, ids: np.ndarray,
           keep_all: bool):
    if keep_all:
        keep = np.ones((ids.size, config.n_planes), bool)
    else:
        keep = tester_flags(bundle.plane_n, bundle.plane_p, scene.centres[ids],
                            scene.radii[ids], config.fmt)
    return keep[:, :config.rows], keep[:, config.rows:]


def run_runs(config: UnitConfig, scene: SceneMemory, runs) -> list:
    """Run the unit's model over ``runs`` in order: each a
    :class:`~raplas_hdl.model.memory_image.Run` or a tuple ``(bundle, sphere_ids)`` or
    ``(bundle, sphere_ids, keep_all)`` (:func:`~raplas_hdl.model.memory_image.as_run`).

    Returns
    -------
    list of (stream, counters)
        Per run, as :func:`raplas_hdl.model.intersection.run_bundle` returns them.

    Raises
    ------
    ValueError
        When the scene or a bundle does not fit ``config``, or sphere IDs are invalid.
    """
    scene.check(config)
    parts = []
    for run in runs:
        bundle, ids, keep_all = as_run(run)
        bundle.check(config)
        ids = _sphere_ids(config, scene, ids)
        c = empty_counters()
        c["spheres"] = int(ids.size)
        c["plane_tests"] = int(ids.size) * config.n_planes
        if ids.size:
            rm, cm = _masks(config, scene, bundle, ids, keep_all)
            ray, tri, skipped = enumerate_pairs(config, rm, cm, scene.tri_counts[ids],
                                                scene.tri_lists[ids], bundle.enable)
        else:
            ray = tri = np.zeros(0, np.int64)
            skipped = 0
        c["pairs_skipped"] = skipped
        c["pairs_issued"] = int(ray.size)
        parts.append((bundle, ray, tri, c))
    total = sum(p[1].size for p in parts)
    if total:
        o = np.concatenate([b.ray_o[r] for b, r, _, _ in parts])
        d = np.concatenate([b.ray_d[r] for b, r, _, _ in parts])
        tri_all = np.concatenate([t for _, _, t, _ in parts])
        res = intersect(o, d, scene.v0[tri_all], scene.e1[tri_all], scene.e2[tri_all],
                        scene.n[tri_all], config.fmt, mode=config.mode,
                        margin_scale=config.margin_scale)
    out, pos = [], 0
    for _, ray, tri, c in parts:
        n = ray.size
        if n == 0:
            beats = np.zeros(1, RESULT_DTYPE)
            beats["last"] = 1
            beats["empty"] = 1
            out.append((beats, c))
            continue
        sl = slice(pos, pos + n)
        beats = np.zeros(n, RESULT_DTYPE)
        beats["ray_id"], beats["tri_id"] = ray, tri
        beats["hit"] = res["hit"][sl]
        for key in ("t", "u", "v", "det"):
            beats[key] = res[key][sl]
        beats["flags"] = res["flags"][sl]
        beats["last"][-1] = 1
        c["hits"] = int(beats["hit"].sum())
        c.update(event_counters(res["event_counts"][sl]))
        out.append((beats, c))
        pos += n
    return out
