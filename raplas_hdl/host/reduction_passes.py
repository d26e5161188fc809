"""Real render passes as unit runs with their windows, for the reduction's tests and bench.

:func:`recorded_runs` renders a scene through the model backend and keeps every pass the
renderer hands the unit (primary and shadow, each early-out round), with the host's
acceptance window in the unit's format (``tmin`` rounded up, ``tmax`` rounded down: the
unit never accepts what the float64 window rejects). :func:`host_choice` is the host's
choice on a run's unreduced stream (:func:`raplas_hdl.host.shading.nearest_hits`, the
window decoded from the patterns the unit holds): what the reduced answers must equal.
:func:`resolve_streams` is the certified host's answer for a pass from a certified unit's
streams, reduced (answers and uncertain pairs) or not (every pair's outcome): the two must
agree.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..engine.passes import runs_of
from ..fp import FP24
from ..fp import model as fpm
from ..model.memory_image import Run
from .backends import ModelBackend
from .modes import resolve_outcomes
from .render import render
from .scenes import get_scene
from .shading import nearest_hits

__all__ = ["RecordedPass", "recorded_runs", "pass_runs", "host_choice", "resolve_streams"]


@dataclass
class RecordedPass:
    """One call of ``Backend.trace``: the batch (enable bits as they were), its runs and the
    window in float64."""

    batch: object
    enable: np.ndarray
    runs: list
    tmin: float
    tmax: np.ndarray | None
    exclude: np.ndarray | None
    any_hit: bool


def recorded_runs(scene_name: str, settings, fmt=None, mode: str = "paper", **scene_options):
    """Render ``scene_name`` through the model backend; return ``(backend, passes)``, every
    pass the renderer traced (the warm-up's included) as a :class:`RecordedPass`."""
    passes = []

    def record(batch, run_b, run_start, run_sph, tmin, tmax, exclude, any_hit):
        passes.append(RecordedPass(
            batch, batch.enable.copy(), runs_of(run_b, run_start, run_sph), float(tmin),
            None if tmax is None else np.array(tmax, np.float64),
            None if exclude is None else np.array(exclude, np.int64), bool(any_hit)))

    backend = ModelBackend(fmt or FP24, mode)
    backend.observers.append(record)
    render(get_scene(scene_name, **scene_options), backend, settings)
    return backend, passes


def pass_runs(backend, rec: RecordedPass, config):
    """The runs of a recorded pass as ``Run`` objects whose bundles carry the window as
    patterns of ``config.fmt``."""
    fmt = config.fmt
    saved = rec.batch.enable
    rec.batch.enable = rec.enable
    try:
        out = []
        tmin = int(fpm.encode(np.array([rec.tmin]), fmt, direction="up")[0])
        for b, ids in rec.runs:
            mem = backend.memory(rec.batch, b)
            tmax = None
            if rec.tmax is not None:
                tmax = fpm.encode(np.asarray(rec.tmax[b], np.float64), fmt, direction="down")
            ex = -1 if rec.exclude is None else int(rec.exclude[b])
            mem = replace(mem, tmin=tmin, tmax=tmax, exclude=ex, any_hit=rec.any_hit)
            out.append(Run(mem, np.asarray(ids, np.int64)))
        return out
    finally:
        rec.batch.enable = saved


def host_choice(config, beats, bundle):
    """The host's nearest hit per ray on a run's unreduced ``beats``: ``(tri, index)`` of
    :func:`~raplas_hdl.host.shading.nearest_hits` with ``t = t' * (1/det)`` in float64 as
    the model backend computes it, the window decoded from the bundle's patterns."""
    R = config.n_rays
    if beats["empty"].any():
        return np.full(R, -1, np.int64), np.full(R, -1, np.int64)
    fmt = config.fmt
    hit = beats["hit"].astype(bool)
    t_, det = fpm.decode(beats["t"], fmt), fpm.decode(beats["det"], fmt)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(hit, 1.0 / np.where(hit, det, 1.0), np.nan)
        t = t_ * inv
    lo = float(fpm.decode(np.array([bundle.tmin], np.uint32), fmt)[0])
    hi = fpm.decode(bundle.window_tmax(config), fmt)
    tri, _, idx = nearest_hits(R, beats["ray_id"], beats["tri_id"], hit, t, lo, hi,
                               None if bundle.exclude < 0 else bundle.exclude)
    return tri, idx


def resolve_streams(backend, rec: RecordedPass, streams):
    """R's answer per ray of a recorded pass from a certified unit's output, as the reduced
    certified render resolves it (:func:`raplas_hdl.host.modes.resolve_outcomes`: misses
    final, the rest through the float64 filter and exact arithmetic), starting from rays
    without a hit.

    Parameters
    ----------
    backend : ModelBackend
        The recording backend (its triangles).
    rec : RecordedPass
    streams : list of structured arrays
        Per run of ``rec``, the unit's beats with ``outcome``: unreduced (``RESULT_CERTIFIED``)
        or reduced (``ANSWER_CERTIFIED``); ``empty`` beats are skipped.

    Returns
    -------
    best_tri, best_t : (bundles, rays) arrays
    """
    B, R = rec.batch.n_bundles, rec.batch.n_rays
    best_t = np.full((B, R), np.inf)
    best_tri = np.full((B, R), -1, np.int64)
    pairs = []
    for (b, _), beats in zip(rec.runs, streams):
        beats = beats[~beats["empty"].astype(bool)]
        pairs.append((b, beats["ray_id"], beats["tri_id"], beats["outcome"]))
    resolve_outcomes(backend, rec.batch, pairs, best_t, best_tri, rec.tmin, rec.tmax,
                     rec.exclude, rec.any_hit)
    return best_tri, best_t
