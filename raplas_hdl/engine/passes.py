"""Whole passes: a batch of bundles through the hierarchy cull and the unit's runs.

The renderer hands the engine one *pass* at a time (all primary tiles; all shadow
bundles; each early-out round) as arrays, never a bundle at a time:

1. :class:`BundleBatch`: ``B`` bundles of one size, their planes and rays in the arithmetic
   of the backend (bit patterns for the model, float64 for the reference), enable bits, and
   the *keep-all* bit of bundles whose quantisation slack is over the culling budget;
2. :func:`cull_pass`: the sphere hierarchy, level by level for the whole batch (one
   compiled call per level over every (bundle, node) candidate); a keep-all bundle is not
   culled at all: it gets every leaf;
3. :func:`trace_pass`: runs (a bundle and a list of leaf spheres, in order) through the
   unit's plane tests, pair enumeration and ray-triangle tests, reduced to each ray's
   nearest accepted hit, with the unit's counters per run.

The kernels (:mod:`raplas_hdl.engine.kernels`) take ranges of candidates or runs and are
spread over the cores by :func:`raplas_hdl.parallel.run_chunks`; the results are the
same whatever the thread count. Nothing here imports Amaranth or the host.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.config import COUNTER_NAMES
from ..parallel import run_chunks
from .kernels import N_COUNTERS

__all__ = ["Arithmetic", "BundleBatch", "EngineScene", "CullResult", "cull_pass",
           "trace_pass", "round_runs", "select_runs", "runs_of", "result_beats",
           "stream_beats", "COUNTER_NAMES"]


@dataclass
class Arithmetic:
    """The kernels and constants of one backend's arithmetic.

    Attributes
    ----------
    name : str
        ``"float64"`` or ``"model"``.
    cull, trace : callables
        The compiled kernels (:mod:`raplas_hdl.engine.kernels`).
    extra : tuple
        Extra arguments of ``trace`` before ``tmin`` (the model's margin table).
    cull_tail, trace_tail : tuple
        Trailing arguments of ``cull`` and ``trace`` (the model's format, rounding and mode).
    """

    name: str
    cull: object
    trace: object
    extra: tuple = ()
    cull_tail: tuple = ()
    trace_tail: tuple = ()


@dataclass
class EngineScene:
    """What the engine reads of a loaded scene (the unit's memories and the hierarchy).

    Attributes
    ----------
    node_c, node_r : ndarray
        Every hierarchy node's sphere in the backend's arithmetic (inflated radii for the
        model), for the host's cull.
    child_start, child_index, node_leaf, depth, node_tris : ndarray
        The hierarchy (:class:`raplas_hdl.host.spheres.SphereTree`).
    sc, sr : ndarray
        Leaf spheres as Sphere Memory holds them.
    tcount, tlist : ndarray
        Triangle count and list of each leaf sphere.
    v0, e1, e2, nn : ndarray (F, 3)
        Triangle Memory.
    levels : int
    """

    node_c: np.ndarray
    node_r: np.ndarray
    child_start: np.ndarray
    child_index: np.ndarray
    node_leaf: np.ndarray
    depth: np.ndarray
    node_tris: np.ndarray
    sc: np.ndarray
    sr: np.ndarray
    tcount: np.ndarray
    tlist: np.ndarray
    v0: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    nn: np.ndarray
    levels: int

    @property
    def n_leaves(self) -> int:
        return len(self.tcount)


@dataclass
class BundleBatch:
    """``B`` bundles of one size as one pass sees them.

    Attributes
    ----------
    rows, cols : int
    pn : ndarray (B*P, 3), pp : ndarray (B*P,)
        Planes in the backend's arithmetic; bundle ``b``'s plane ``k`` is row ``b*P + k``.
    ro : ndarray (B, 3), rd : ndarray (B*R, 3)
        Ray origins and directions in the backend's arithmetic.
    enable : ndarray (B, R) bool
        Enable bits (the host clears them between early-out rounds).
    keep_all : ndarray (B,) bool
        Bundles over the culling budget: neither the host nor the unit culls with them.
    origin : ndarray (B, 3), directions : ndarray (B, R, 3)
        The rays as the unit sees them, float64 (decoded for the model).
    geometry : dict
        The float64 bundle geometry (:func:`raplas_hdl.model.bundles.bundle_geometry`).
    """

    rows: int
    cols: int
    pn: np.ndarray
    pp: np.ndarray
    ro: np.ndarray
    rd: np.ndarray
    enable: np.ndarray
    keep_all: np.ndarray
    origin: np.ndarray
    directions: np.ndarray
    geometry: dict = field(default_factory=dict)

    @property
    def n_bundles(self) -> int:
        return len(self.enable)

    @property
    def n_planes(self) -> int:
        return self.rows + self.cols

    @property
    def n_rays(self) -> int:
        return self.rows * self.cols


@dataclass
class CullResult:
    """Leaves of every bundle of a pass, with what the cull did.

    Attributes
    ----------
    start : ndarray (B+1,) int64
        Bundle ``b``'s leaves are ``leaves[start[b]:start[b+1]]``, ascending (Sphere Memory
        order).
    leaves : ndarray int64
    tested, dropped, tris_dropped : ndarray (levels,) int64
        Hierarchy nodes tested and dropped per level, and the triangles below the dropped.
    plane_tests : int
        Host plane tests (every tested node against every plane of its bundle).
    """

    start: np.ndarray
    leaves: np.ndarray
    tested: np.ndarray
    dropped: np.ndarray
    tris_dropped: np.ndarray
    plane_tests: int


def _children(scene: EngineScene, b: np.ndarray, nodes: np.ndarray):
    """(bundle, child) for every child of every (bundle, node)."""
    lo = scene.child_start[nodes]
    n = scene.child_start[nodes + 1] - lo
    total = int(n.sum())
    first = np.cumsum(n) - n
    k = np.arange(total, dtype=np.int64) - np.repeat(first, n)
    return np.repeat(b, n), scene.child_index[np.repeat(lo, n) + k]


def cull_pass(arith: Arithmetic, scene: EngineScene, batch: BundleBatch,
              hierarchy: bool = True) -> CullResult:
    """The hierarchy cull of every bundle of ``batch`` (module docstring)."""
    B, L = batch.n_bundles, scene.levels
    tested = np.zeros(L, np.int64)
    dropped = np.zeros(L, np.int64)
    tris_dropped = np.zeros(L, np.int64)
    n_leaves = scene.n_leaves
    culls = np.ones(B, bool) if hierarchy else np.zeros(B, bool)
    culls &= ~np.asarray(batch.keep_all, bool)
    out_b = [np.repeat(np.flatnonzero(~culls), n_leaves)]
    out_l = [np.tile(np.arange(n_leaves, dtype=np.int64), int((~culls).sum()))]
    b = np.flatnonzero(culls).astype(np.int64)
    nodes = np.zeros(b.size, np.int64)
    plane_tests = 0
    while b.size:
        leaf = scene.node_leaf[nodes] >= 0
        out_b.append(b[leaf])
        out_l.append(scene.node_leaf[nodes[leaf]])
        b, nodes = b[~leaf], nodes[~leaf]
        if not b.size:
            break
        keep = np.empty(b.size, np.bool_)
        run_chunks(b.size, lambda lo, hi, b=b, nodes=nodes, keep=keep: arith.cull(
            batch.pn, batch.pp, batch.rows, batch.n_planes, b, nodes, scene.node_c,
            scene.node_r, lo, hi, keep, *arith.cull_tail), min_chunk=2048)
        lvl = scene.depth[nodes]
        tested += np.bincount(lvl, minlength=L)[:L]
        dropped += np.bincount(lvl[~keep], minlength=L)[:L]
        tris_dropped += np.bincount(lvl[~keep], weights=scene.node_tris[nodes[~keep]],
                                    minlength=L)[:L].astype(np.int64)
        plane_tests += int(b.size) * batch.n_planes
        b, nodes = _children(scene, b[keep], nodes[keep])
    all_b = np.concatenate(out_b).astype(np.int64)
    all_l = np.concatenate(out_l).astype(np.int64)
    order = np.lexsort((all_l, all_b))
    start = np.zeros(B + 1, np.int64)
    np.cumsum(np.bincount(all_b, minlength=B), out=start[1:])
    return CullResult(start, all_l[order], tested, dropped, tris_dropped, plane_tests)


def round_runs(start: np.ndarray, leaves: np.ndarray, batch_size: int | None, rnd: int):
    """Round ``rnd`` of the early-out schedule: bundle ``b`` runs its leaves
    ``rnd*batch_size .. (rnd+1)*batch_size - 1`` (``None``: all of them in round 0).

    Returns
    -------
    run_b, run_start, run_sph : ndarray
        The runs of the round (bundles that still have leaves), as :func:`trace_pass` takes
        them.
    """
    n = np.diff(start)
    if batch_size is None:
        lo = start[:-1] if rnd == 0 else start[1:]
        hi = start[1:]
    else:
        lo = np.minimum(start[:-1] + rnd * batch_size, start[1:])
        hi = np.minimum(lo + batch_size, start[1:])
    live = np.flatnonzero((hi > lo) & (n > 0))
    lo, hi = lo[live], hi[live]
    cnt = hi - lo
    run_start = np.zeros(live.size + 1, np.int64)
    np.cumsum(cnt, out=run_start[1:])
    k = np.arange(int(run_start[-1]), dtype=np.int64) - np.repeat(run_start[:-1], cnt)
    return live.astype(np.int64), run_start, leaves[np.repeat(lo, cnt) + k]


def select_runs(run_b, run_start, run_sph, keep):
    """The runs of ``(run_b, run_start, run_sph)`` where ``keep`` (bool per run) is set."""
    keep = np.asarray(keep, bool)
    cnt = np.diff(run_start)[keep]
    start = np.zeros(cnt.size + 1, np.int64)
    np.cumsum(cnt, out=start[1:])
    sel = np.repeat(keep, np.diff(run_start))
    return np.asarray(run_b)[keep], start, np.asarray(run_sph)[sel]


def runs_of(run_b, run_start, run_sph) -> list:
    """The runs of ``(run_b, run_start, run_sph)`` as a list of ``(bundle index, sphere
    ids)``."""
    return [(int(b), run_sph[run_start[u]:run_start[u + 1]]) for u, b in enumerate(run_b)]


def result_beats(counters) -> int:
    """Beats of the unreduced result stream of runs with these counters (U, 8): one per
    issued pair, one (empty) for a run that issued none."""
    pairs = np.asarray(counters)[:, COUNTER_NAMES.index("pairs_issued")]
    return int(np.maximum(pairs, 1).sum())


def stream_beats(results) -> int:
    """Beats of the runs' result streams themselves (``RunResult`` each): the count
    :func:`result_beats` gives from per-run counters, which an overlapped round of the unit
    does not have."""
    return sum(max(res.ray_id.size, 1) for res in results)


def pass_arguments(scene: EngineScene, batch: BundleBatch, run_b, run_start, run_sph,
                   tmin: float, tmax, exclude):
    """The arguments the trace kernels share: ``(head, run_b, work, tail)``, ``head`` the
    batch, the runs and the scene's memories, ``tail`` ``(tmin, tmax, exclude)`` with
    their defaults, ``work`` the cumulative cost of the runs (spheres times triangles) to
    balance the ranges by."""
    B = batch.n_bundles
    run_b = np.ascontiguousarray(run_b, np.int64)
    run_start = np.ascontiguousarray(run_start, np.int64)
    run_sph = np.ascontiguousarray(run_sph, np.int64)
    if np.unique(run_b).size != run_b.size:
        raise ValueError("a pass runs each bundle at most once")
    if tmax is None:
        tmax = np.full((B, batch.n_rays), np.inf)
    if exclude is None:
        exclude = np.full(B, -1, np.int64)
    work = np.concatenate([[0], np.cumsum(scene.tcount[run_sph] + 1)])[run_start]
    head = (batch.pn, batch.pp, batch.ro, batch.rd, batch.enable, batch.keep_all, batch.rows,
            batch.cols, run_b, run_start, run_sph, scene.sc, scene.sr, scene.tcount,
            scene.tlist, scene.v0, scene.e1, scene.e2, scene.nn)
    tail = (float(tmin), np.ascontiguousarray(tmax, np.float64),
            np.ascontiguousarray(exclude, np.int64))
    return head, run_b, work, tail


def trace_pass(arith: Arithmetic, scene: EngineScene, batch: BundleBatch, run_b, run_start,
               run_sph, best_t: np.ndarray, best_tri: np.ndarray, tmin: float = 0.0,
               tmax: np.ndarray | None = None, exclude: np.ndarray | None = None) -> np.ndarray:
    """Runs of a pass through the unit, folded into each ray's nearest accepted hit.

    Parameters
    ----------
    run_b, run_start, run_sph : ndarray
        Run ``u`` tests spheres ``run_sph[run_start[u]:run_start[u+1]]`` against bundle
        ``run_b[u]``; each bundle at most once.
    best_t, best_tri : ndarray (B, R)
        Each ray's nearest hit so far (``inf`` and -1 for none); updated in place.
    tmin : float
    tmax : ndarray (B, R), optional
        Accepted interval of ``t`` (default ``[tmin, inf]``).
    exclude : ndarray (B,) int, optional
        A triangle each bundle ignores (-1: none).

    Returns
    -------
    counters : ndarray (U, 8) int64
        Per run, in :data:`COUNTER_NAMES` order.
    """
    head, run_b, work, tail = pass_arguments(scene, batch, run_b, run_start, run_sph, tmin,
                                             tmax, exclude)
    counters = np.zeros((run_b.size, N_COUNTERS), np.int64)
    args = (*head, *arith.extra, *tail)
    run_chunks(run_b.size, lambda lo, hi: arith.trace(*args, lo, hi, best_t, best_tri,
                                                      counters, *arith.trace_tail),
               min_chunk=16, weights=work)
    return counters
