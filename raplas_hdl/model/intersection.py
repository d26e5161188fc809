"""Transaction-level golden model of the whole intersection unit.

It produces the result stream of :class:`raplas_hdl.rtl.intersection.IntersectionUnit`
bit for bit, and the same counters (all but ``cycles``), for one *run*: a start command
that names the spheres to test against the bundle in the memories. It is also the ``model``
backend of the host, called once per run, so it works on whole arrays (NumPy, and the numba
kernels behind the plane-sphere and ray-triangle models); no Amaranth.

Order of the result stream (the unit's, by construction):

1. spheres in the order of the run (``sphere_ids``, default every sphere in memory order);
2. for each sphere, the rays (i, j) whose row plane i and column plane j both flag it,
   rows ascending, then columns ascending; in a *keep-all* run (the command's ``keep_all``
   bit) every plane flags every sphere, so every ray of the bundle is taken;
3. for each such ray, if its enable bit is set, the sphere's triangles in list order; a
   disabled ray issues no pair (its pairs are counted as skipped).

Every pair issued gives one result beat. The last beat of the run has ``last`` set; a run
that issues no pair gives exactly one beat with ``last`` and ``empty`` set and every other
field zero.

In ``certified`` mode (``UnitConfig(mode="certified")``) each beat also carries the pair's
``outcome`` (:data:`~raplas_hdl.model.records.RESULT_CERTIFIED`: 0 miss, 1 certain hit, 2
uncertain, from :func:`raplas_hdl.model.certified.intersect_certified` with the bound
variant the RTL builds, :data:`UNIT_BOUND_VARIANT`); ``hit`` (and the ``hits`` counter) is
``outcome == 1``; and ``tight`` (:func:`raplas_hdl.model.ordering.tight_flags`: a certain hit
whose ``t'`` and ``det`` the unit knows to ``2**-tight_bits``, the ones its reduction folds).
"""

from __future__ import annotations

import numpy as np

from .config import COUNTER_NAMES, UnitConfig
from .memory_image import BundleMemory, Run, SceneMemory, as_run
from .ordering import tight_flags
from .plane_sphere import tester_flags
from .ray_triangle import EVENTS, intersect
from .records import RESULT, result_record
from .reduction import reduce_run

__all__ = ["RESULT_DTYPE", "UNIT_BOUND_VARIANT", "result_dtype", "run_bundle", "run_runs",
           "enumerate_pairs", "empty_counters", "event_counters"]

#: One beat of the unit's result stream: the dtype of the record
#: :data:`raplas_hdl.model.records.RESULT` (``RESULT.bind(config)`` packs and unpacks beats).
RESULT_DTYPE = RESULT.dtype()


#: The certified bound variant of the unit's ray-triangle units (the one the RTL builds,
#: ``raplas_hdl.rtl.certified_bound.RTL_VARIANTS``; a key of
#: :data:`raplas_hdl.model.certified.VARIANTS`).
UNIT_BOUND_VARIANT = "exp"


def result_dtype(config) -> np.dtype:
    """The dtype of ``config``'s result stream: :data:`RESULT_DTYPE`, with ``outcome`` in
    ``certified`` mode (:func:`~raplas_hdl.model.records.result_record`)."""
    return result_record(config).dtype()


def empty_counters() -> dict:
    """Counters at zero, keyed by :data:`~raplas_hdl.model.config.COUNTER_NAMES`."""
    return {name: 0 for name in COUNTER_NAMES}


def _sphere_ids(config, scene, sphere_ids):
    if sphere_ids is None:
        return np.arange(scene.n_spheres, dtype=np.int64)
    ids = np.asarray(sphere_ids)
    if ids.size == 0 and ids.ndim == 1:
        ids = ids.astype(np.int64)
    if ids.dtype.kind not in "ui" or ids.ndim != 1:
        raise ValueError("sphere_ids must be a 1-D integer array")
    ids = ids.astype(np.int64)
    if ids.size > config.max_spheres:
        raise ValueError(f"a run names at most max_spheres={config.max_spheres} spheres")
    if ids.size and (ids.min() < 0 or ids.max() >= scene.n_spheres):
        raise ValueError("sphere_ids names a sphere that is not in the scene")
    return ids


def enumerate_pairs(config: UnitConfig, row_mask, col_mask, tri_counts, tri_lists, enable):
    """Pairs a run issues, in stream order, from the spheres' plane masks.

    Parameters
    ----------
    row_mask : (S, rows) bool
    col_mask : (S, cols) bool
    tri_counts : (S,) int
        Triangles of each sphere of the run.
    tri_lists : (S, L) uint32
        Their triangle IDs.
    enable : (rows*cols,) bool

    Returns
    -------
    ray_ids, tri_ids : int64 arrays
        The issued pairs in order.
    skipped : int
        Pairs not issued because their ray is disabled.
    """
    rows, cols = config.rows, config.cols
    s_n = row_mask.shape[0]
    ray_parts, tri_parts = [], []
    skipped = 0
    chunk = max(1, (1 << 22) // max(1, rows * cols))
    for lo in range(0, s_n, chunk):
        hi = min(s_n, lo + chunk)
        both = row_mask[lo:hi, :, None] & col_mask[lo:hi, None, :]   # (s, rows, cols)
        s_idx, ray = np.nonzero(both.reshape(hi - lo, rows * cols))  # s-major, ray ascending
        s_idx = s_idx + lo
        cnt = tri_counts[s_idx].astype(np.int64)
        en = enable[ray]
        skipped += int(cnt[~en].sum())
        s_idx, ray, cnt = s_idx[en], ray[en], cnt[en]
        total = int(cnt.sum())
        rep_s = np.repeat(s_idx, cnt)
        rep_r = np.repeat(ray, cnt)
        starts = np.cumsum(cnt) - cnt
        k = np.arange(total, dtype=np.int64) - np.repeat(starts, cnt)
        ray_parts.append(rep_r.astype(np.int64))
        tri_parts.append(tri_lists[rep_s, k].astype(np.int64))
    if not ray_parts:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), skipped
    return np.concatenate(ray_parts), np.concatenate(tri_parts), skipped


def run_bundle(config: UnitConfig, scene: SceneMemory, bundle: BundleMemory,
               sphere_ids=None, *, keep_all: bool = False):
    """Run the unit once: the spheres ``sphere_ids`` against the bundle.

    Parameters
    ----------
    config : UnitConfig
    scene : SceneMemory
    bundle : BundleMemory
    sphere_ids : 1-D integer array, optional
        Spheres of the run, in order (default: all, in memory order). Repeats are allowed
        and give repeated pairs, as in the unit.
    keep_all : bool
        The run command's ``keep_all`` bit: no sphere is culled (every row and column mask
        is all ones), so every enabled ray meets every triangle of every sphere of the run.
        For a bundle over the culling budget (``raplas_hdl.host.culling``: the host must not
        cull with it, and the unit's testers would cull with the same ``r'``). The counters
        count as usual (``plane_tests`` too: the testers still test). A bundle marked
        :attr:`~raplas_hdl.model.memory_image.BundleMemory.keep_all` runs so whatever this
        argument says.

    Returns
    -------
    results : numpy structured array of :func:`result_dtype`
        The result stream, one element per beat (with ``outcome`` in ``certified`` mode).
    counters : dict
        ``spheres``, ``plane_tests`` (``rows + cols`` per sphere), ``pairs_issued``,
        ``pairs_skipped`` (pairs of disabled rays), ``hits``, and ``overflow``,
        ``underflow``, ``invalid``: the number of ray-triangle operations that raised that
        event, summed over the issued pairs (the result stream's ``flags`` is the OR of a
        pair's events; these count its operations).

    Raises
    ------
    ValueError
        When the scene or the bundle does not fit ``config``, or ``sphere_ids`` is invalid.
    """
    return run_runs(config, scene, [Run(bundle, sphere_ids, keep_all)])[0]


def run_runs(config: UnitConfig, scene: SceneMemory, runs) -> list:
    """Run the unit over ``runs`` in order: the model's side of the interface the RTL driver
    has (:func:`raplas_hdl.sim.drive.unit_driver.run_runs`, without the simulator).

    Parameters
    ----------
    config : UnitConfig
    scene : SceneMemory
    runs : iterable
        Each a :class:`~raplas_hdl.model.memory_image.Run`, ``(bundle, sphere_ids)`` or
        ``(bundle, sphere_ids, keep_all)`` (:func:`~raplas_hdl.model.memory_image.as_run`).

    Returns
    -------
    list of (results, counters)
        Per run, as :func:`run_bundle` describes them. The pairs of all runs go through one
        call of the ray-triangle model (a pair's arithmetic does not depend on the others).
        With ``config.reduce`` the results are the run's answers (``answer_dtype`` of
        :mod:`raplas_hdl.model.reduction`: one beat per ray with an answer; in ``certified``
        mode the run's uncertain pairs first) and the counters
        are those of the unreduced run (no early-out: the unit's ``pairs_issued``, ``hits``
        and event counters of an any-hit run are at most these).

    Raises
    ------
    ValueError
        When the scene or a bundle does not fit ``config``, or sphere IDs are invalid.
    """
    scene.check(config)
    certified = config.mode == "certified"
    parts = []
    for run in runs:
        bundle, ids, keep_all = as_run(run)
        bundle.check(config)
        ids = _sphere_ids(config, scene, ids)
        c = empty_counters()
        c["spheres"] = int(ids.size)
        c["plane_tests"] = int(ids.size) * config.n_planes
        if ids.size:
            if keep_all:
                keep = np.ones((ids.size, config.n_planes), bool)
            else:
                keep = tester_flags(bundle.plane_n, bundle.plane_p, scene.centres[ids],
                                    scene.radii[ids], config.fmt)
            ray, tri, skipped = enumerate_pairs(config, keep[:, :config.rows],
                                                keep[:, config.rows:], scene.tri_counts[ids],
                                                scene.tri_lists[ids], bundle.enable)
        else:
            ray = tri = np.zeros(0, np.int64)
            skipped = 0
        c["pairs_skipped"] = skipped
        c["pairs_issued"] = int(ray.size)
        parts.append((bundle, ray, tri, c))
    if sum(p[1].size for p in parts):
        o = np.concatenate([b.ray_o[r] for b, r, _, _ in parts])
        d = np.concatenate([b.ray_d[r] for b, r, _, _ in parts])
        tri_all = np.concatenate([t for _, _, t, _ in parts])
        res = intersect(o, d, scene.v0[tri_all], scene.e1[tri_all], scene.e2[tri_all],
                        scene.n[tri_all], config.fmt, mode=config.mode,
                        margin_scale=config.margin_scale,
                        bound_variant=UNIT_BOUND_VARIANT if certified else None)
        if certified:
            res["tight"] = tight_flags((o, d, scene.v0[tri_all], scene.e1[tri_all],
                                        scene.e2[tri_all], scene.n[tri_all]), res["outcome"],
                                       config.fmt, config.margin_scale, UNIT_BOUND_VARIANT)
    out, pos = [], 0
    dtype = result_dtype(config)
    for _, ray, tri, c in parts:
        n = ray.size
        if n == 0:
            beats = np.zeros(1, dtype)
            beats["last"] = 1
            beats["empty"] = 1
            out.append((beats, c))
            continue
        sl = slice(pos, pos + n)
        beats = np.zeros(n, dtype)
        beats["ray_id"], beats["tri_id"] = ray, tri
        beats["hit"] = res["hit"][sl]
        if certified:
            beats["outcome"] = res["outcome"][sl]
            beats["tight"] = res["tight"][sl]
        for key in ("t", "u", "v", "det"):
            beats[key] = res[key][sl]
        beats["flags"] = res["flags"][sl]
        beats["last"][-1] = 1
        c["hits"] = int(beats["hit"].sum())
        c.update(event_counters(res["event_counts"][sl]))
        out.append((beats, c))
        pos += n
    if config.reduce:
        out = [(reduce_run(config, beats, p[0]), c) for (beats, c), p in zip(out, parts)]
    return out


def event_counters(event_counts) -> dict:
    """The ``overflow``, ``underflow``, ``invalid`` counters from the ray-triangle model's
    per-pair ``event_counts`` (n, 3): operations with each event, summed over the pairs."""
    totals = np.asarray(event_counts, dtype=np.int64).reshape(-1, 3).sum(axis=0)
    return {name: int(v) for name, v in zip(EVENTS, totals)}
