"""Whole passes of one ray type through a backend, and the render's counters per ray type.

Every ray the renderer issues (primary, shadow, reflection, refraction, glossy, ambient
occlusion) goes through one of two functions, as arrays of bundles of one size, ``chunk``
bundles at a time (:meth:`~raplas_hdl.host.backends.Backend.batch`, ``cull``, ``trace``);
neither loops over bundles in Python:

- :func:`nearest_pass`: each ray's nearest accepted hit (``tmin``, per-ray ``tmax``, a
  triangle per bundle to ignore); one round of every bundle's surviving leaves;
- :func:`any_hit_pass`: whether each ray is blocked, in early-out rounds: round ``k``
  runs every bundle's ``k``-th batch of ``batch_spheres`` leaves; between rounds the rays
  already blocked are disabled, and a bundle whose rays are all blocked runs no further
  batch (``early_out=False``: one round of every leaf).

:class:`Tally` counts, per ray type, the rays and bundles issued, the brute-force pairs
(every issued ray against every triangle of the scene), the host's plane tests, the unit's
counters, and what early-out skipped; it also sums the hierarchy's drops per level. The
results do not depend on ``chunk``.

Nothing here imports Amaranth.
"""

from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass

import numpy as np

from ..engine.passes import round_runs, select_runs
from .backends import COUNTERS, Backend

__all__ = ["RAY_TYPES", "PassResult", "Tally", "any_hit_pass", "nearest_pass"]

#: The ray types a render issues, in the order the summary lists them.
RAY_TYPES = ("primary", "shadow", "reflection", "refraction", "glossy", "ao")

_EARLY = COUNTERS.index("pairs_skipped")


def _no_timer(_name):
    return nullcontext()


class Tally:
    """The counters of a render, per ray type (:data:`RAY_TYPES`).

    Parameters
    ----------
    n_triangles : int
        Triangles of the scene (a brute-force tracer tests every ray against each).
    levels : int
        Levels of the sphere hierarchy.
    hierarchy : bool
        Cull the hierarchy on the host (:meth:`Backend.cull`).
    record : bool
        Keep every pass's rays and answers in :attr:`passes` (:meth:`record`), for the
        exact reference (:func:`raplas_hdl.host.reference.check_passes`).
    """

    def __init__(self, n_triangles: int, levels: int, hierarchy: bool = True,
                 record: bool = False):
        self.n_triangles = int(n_triangles)
        self.hierarchy = hierarchy
        self.passes: list | None = [] if record else None
        self.kinds: dict = {}
        self.unit: dict = {}
        self.hier = {"tested": np.zeros(levels, np.int64), "dropped": np.zeros(levels, np.int64),
                     "tris_dropped": np.zeros(levels, np.int64), "leaves": 0}
        self.unguaranteed_bundles = 0

    def kind(self, kind: str) -> dict:
        """The running counts of one ray type (created on first use)."""
        if kind not in RAY_TYPES:
            raise ValueError(f"unknown ray type {kind!r} (one of {', '.join(RAY_TYPES)})")
        if kind not in self.kinds:
            self.kinds[kind] = dict.fromkeys(
                ("rays", "bundles", "brute_force_pairs", "host_plane_tests",
                 "early_out_pairs_skipped", "spheres_skipped"), 0)
            self.unit[kind] = np.zeros(len(COUNTERS), np.int64)
        return self.kinds[kind]

    def issue(self, kind: str, bundles: int, rays: int):
        """Count ``bundles`` bundles holding ``rays`` enabled rays of a type."""
        k = self.kind(kind)
        k["bundles"] += int(bundles)
        k["rays"] += int(rays)
        k["brute_force_pairs"] += int(rays) * self.n_triangles

    def cull(self, backend: Backend, batch, kind: str):
        """The hierarchy cull of a batch, counted."""
        cr = backend.cull(batch, self.hierarchy)
        for k in ("tested", "dropped", "tris_dropped"):
            self.hier[k] += getattr(cr, k)
        self.hier["leaves"] += int(cr.leaves.size)
        self.kind(kind)["host_plane_tests"] += cr.plane_tests
        self.unguaranteed_bundles += int(np.count_nonzero(batch.keep_all))
        return cr

    def record(self, kind: str, batch, enable, tmin, tmax, exclude, any_hit: bool, tri, t=None):
        """Keep a chunk of a pass when recording: the rays as the unit saw them
        (``batch.origin`` (B, 3), ``batch.directions`` (B, R, 3)), the rays traced
        (``enable`` (B, R), before any early-out), the window (``tmin``; ``tmax`` (B, R) or
        None), ``exclude`` (B,) or None, and the answer: ``tri`` (B, R), the nearest
        triangle (-1: none) or, with ``any_hit``, whether the ray is blocked; ``t`` (B, R) of
        a nearest pass."""
        if self.passes is None:
            return
        B, R = np.asarray(enable).shape
        self.passes.append({
            "kind": kind, "any_hit": bool(any_hit),
            "origin": np.array(batch.origin, np.float64),
            "directions": np.array(batch.directions, np.float64).reshape(B, R, 3),
            "enable": np.array(enable, bool), "tmin": float(tmin),
            "tmax": np.full((B, R), np.inf) if tmax is None else np.array(tmax, np.float64),
            "exclude": (np.full(B, -1, np.int64) if exclude is None
                        else np.array(exclude, np.int64)),
            "answer": np.array(tri), "t": None if t is None else np.array(t, np.float64)})

    def add_unit(self, kind: str, counters: np.ndarray):
        """The unit's counters of a trace (U, 8)."""
        self.unit[kind] += np.asarray(counters, np.int64).reshape(-1, len(COUNTERS)).sum(axis=0)

    def unit_total(self) -> dict:
        """The unit's counters summed over every ray type."""
        total = np.zeros(len(COUNTERS), np.int64)
        for v in self.unit.values():
            total += v
        return {name: int(v) for name, v in zip(COUNTERS, total)}

    def ray_types(self) -> dict:
        """Per ray type that ran: ``rays``, ``bundles``, ``pairs_issued``,
        ``brute_force_pairs``, ``pair_fraction``, ``hits``, ``plane_tests`` (host and unit),
        ``early_out_pairs_skipped``."""
        out = {}
        for kind in RAY_TYPES:
            if kind not in self.kinds:
                continue
            k, u = self.kinds[kind], dict(zip(COUNTERS, self.unit[kind].tolist()))
            bf = k["brute_force_pairs"]
            issued = int(u.get("pairs_issued", 0))
            out[kind] = {"rays": k["rays"], "bundles": k["bundles"], "pairs_issued": issued,
                         "brute_force_pairs": bf, "pair_fraction": issued / bf if bf else 0.0,
                         "hits": int(u.get("hits", 0)),
                         "plane_tests": k["host_plane_tests"] + int(u.get("plane_tests", 0)),
                         "early_out_pairs_skipped": k["early_out_pairs_skipped"]}
        return out


@dataclass
class PassResult:
    """What a :func:`nearest_pass` found.

    Attributes
    ----------
    t : ndarray (B, R) float64
        Each ray's nearest accepted hit distance (``inf``: none).
    tri : ndarray (B, R) int64
        Its triangle (-1: none; disabled rays keep -1).
    origin : ndarray (B, 3) or None
        With ``keep_rays``: the origins as the unit saw them (float64; decoded for the model).
    directions : ndarray (B, R, 3) or None
        With ``keep_rays``: the unit directions as the unit saw them.
    """

    t: np.ndarray
    tri: np.ndarray
    origin: np.ndarray | None = None
    directions: np.ndarray | None = None


def _rows(x, lo, hi):
    return None if x is None else np.asarray(x)[lo:hi]


def nearest_pass(backend: Backend, origins, centres, col_axes, row_axes, rows: int, cols: int,
                 *, tally: Tally, kind: str, chunk: int, enable=None, tmin: float = 0.0,
                 tmax=None, exclude=None, keep_rays: bool = False, timer=None,
                 progress=None, on_chunk=None) -> PassResult:
    """The nearest hit of every ray of ``B`` bundles of ``rows`` x ``cols`` rays.

    Parameters
    ----------
    backend : Backend
        With the scene loaded.
    origins, centres, col_axes, row_axes : array_like (B, 3)
        The bundles (:func:`raplas_hdl.model.bundles.bundle_geometry`).
    rows, cols : int
    tally : Tally
        Counts the pass under ``kind``.
    kind : str
        The ray type (:data:`RAY_TYPES`).
    chunk : int
        Bundles per backend pass (the results do not depend on it).
    enable : array_like (B, rows*cols) bool, optional
        Rays to trace (default all); only enabled rays are counted.
    tmin : float
    tmax : array_like (B, rows*cols), optional
        Accepted ``t`` interval (default ``[tmin, inf]``).
    exclude : array_like (B,) int, optional
        A triangle each bundle ignores (-1: none).
    keep_rays : bool
        Return the rays as the unit saw them.
    timer : callable, optional
        ``timer(name)`` a context manager timing ``"<kind> cull"`` and ``"<kind> unit"``.
    progress : callable, optional
        Called with the number of bundles done after each chunk.
    on_chunk : callable, optional
        ``on_chunk(lo, hi, batch, t, tri)`` after each chunk (for instance to record the
        rays).

    Returns
    -------
    PassResult
    """
    timer = timer or _no_timer
    B = len(origins)
    R = rows * cols
    best_t_all = np.full((B, R), np.inf)
    best_tri_all = np.full((B, R), -1, np.int64)
    o_all = np.zeros((B, 3)) if keep_rays else None
    d_all = np.zeros((B, R, 3)) if keep_rays else None
    for lo in range(0, B, chunk):
        hi = min(lo + chunk, B)
        with timer(f"{kind} cull"):
            batch = backend.batch(origins[lo:hi], centres[lo:hi], col_axes[lo:hi],
                                  row_axes[lo:hi], rows, cols, _rows(enable, lo, hi))
            tally.issue(kind, hi - lo, int(batch.enable.sum()))
            cr = tally.cull(backend, batch, kind)
        with timer(f"{kind} unit"):
            best_t = np.full((hi - lo, R), np.inf)
            best_tri = np.full((hi - lo, R), -1, np.int64)
            ctr = backend.trace(batch, *round_runs(cr.start, cr.leaves, None, 0), best_t,
                                best_tri, tmin, _rows(tmax, lo, hi), _rows(exclude, lo, hi))
            tally.add_unit(kind, ctr)
        best_t_all[lo:hi], best_tri_all[lo:hi] = best_t, best_tri
        tally.record(kind, batch, batch.enable, tmin, _rows(tmax, lo, hi),
                     _rows(exclude, lo, hi), False, best_tri, best_t)
        if keep_rays:
            o_all[lo:hi], d_all[lo:hi] = batch.origin, batch.directions
        if on_chunk is not None:
            on_chunk(lo, hi, batch, best_t, best_tri)
        if progress is not None:
            progress(hi - lo)
    return PassResult(best_t_all, best_tri_all, o_all, d_all)


def any_hit_pass(backend: Backend, origins, centres, col_axes, row_axes, rows: int, cols: int,
                 *, tally: Tally, kind: str, chunk: int, tmin: float, tmax, exclude,
                 early_out: bool = True, batch_spheres: int = 32, timer=None, progress=None,
                 on_chunk=None) -> np.ndarray:
    """Which rays of ``B`` bundles are blocked: some accepted hit with
    ``tmin <= t <= tmax`` on a triangle other than the bundle's ``exclude``.

    Parameters are those of :func:`nearest_pass` (``tmax`` (B, rows*cols) and ``exclude``
    (B,) are required here), plus ``early_out`` (disable blocked rays between rounds of
    ``batch_spheres`` leaves; a bundle whose rays are all blocked runs no further round).
    ``on_chunk(lo, hi, batch, blocked)`` is called after each chunk.

    Returns
    -------
    ndarray (B, rows*cols) bool
    """
    timer = timer or _no_timer
    B = len(origins)
    R = rows * cols
    blocked = np.zeros((B, R), bool)
    step = batch_spheres if early_out else None
    counts = tally.kind(kind)
    for lo in range(0, B, chunk):
        hi = min(lo + chunk, B)
        k = hi - lo
        with timer(f"{kind} cull"):
            batch = backend.batch(origins[lo:hi], centres[lo:hi], col_axes[lo:hi],
                                  row_axes[lo:hi], rows, cols)
            tally.issue(kind, k, k * R)
            cr = tally.cull(backend, batch, kind)
            own = np.asarray(exclude)[lo:hi]
            hi_t = np.asarray(tmax)[lo:hi]
            traced = batch.enable.copy() if tally.passes is not None else None
            best_t = np.full((k, R), np.inf)
            best_tri = np.full((k, R), -1, np.int64)
        rnd = 0
        while True:
            with timer(f"{kind} cull"):
                run_b, run_start, run_sph = round_runs(cr.start, cr.leaves, step, rnd)
                if not run_b.size:
                    break
                live = batch.enable[run_b].any(axis=1)
                counts["spheres_skipped"] += int(np.diff(run_start)[~live].sum())
                run_b, run_start, run_sph = select_runs(run_b, run_start, run_sph, live)
            with timer(f"{kind} unit"):
                ctr = backend.trace(batch, run_b, run_start, run_sph, best_t, best_tri, tmin,
                                    hi_t, own, any_hit=True)
                tally.add_unit(kind, ctr)
                counts["early_out_pairs_skipped"] += int(ctr[:, _EARLY].sum())
            if early_out:
                batch.enable &= ~(best_tri >= 0)
            rnd += 1
        blocked[lo:hi] = best_tri >= 0
        tally.record(kind, batch, traced, tmin, hi_t, own, True, blocked[lo:hi])
        if on_chunk is not None:
            on_chunk(lo, hi, batch, blocked[lo:hi])
        if progress is not None:
            progress(k)
    return blocked
