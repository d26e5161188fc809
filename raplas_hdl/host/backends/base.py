"""What every backend shares: the pass protocol (:class:`Backend`), a run's result
(:class:`RunResult`) and :class:`BackendUnavailable`; the package docstring says how the
renderer drives a backend."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ...engine.passes import (COUNTER_NAMES, Arithmetic, BundleBatch, EngineScene, cull_pass,
                              round_runs)
from ...fp.format import FPFormat
from ...model.bundles import RayBundle
from ..modes import RenderMode, get_mode
from ..spheres import SphereTree

#: The unit's counters (one definition: :data:`raplas_hdl.model.config.COUNTER_NAMES`).
COUNTERS = COUNTER_NAMES


class BackendUnavailable(RuntimeError):
    """A backend cannot run here; the message says what is missing and how to get it."""


@dataclass
class RunResult:
    """The pairs one run issued, in stream order, with their outcome.

    ``t, u, v`` are ``t'/det, u'/det, v'/det`` in float64 (NaN where not a hit).
    ``outcome``: a certified unit's per pair (0 miss, 1 certain hit, 2 uncertain), else None.
    """

    ray_id: np.ndarray
    tri_id: np.ndarray
    hit: np.ndarray
    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    flags: np.ndarray
    counters: dict = field(default_factory=dict)
    outcome: np.ndarray | None = None

    @classmethod
    def empty(cls, counters=None) -> RunResult:
        z = np.zeros(0, np.int64)
        f = np.zeros(0)
        return cls(z, z.copy(), np.zeros(0, bool), f, f.copy(), f.copy(),
                   np.zeros(0, np.uint8), dict(counters or {}))


class Backend:
    """Common part of the backends (the protocol: :mod:`raplas_hdl.host.backends`)."""

    name = "?"
    fmt: FPFormat | None = None
    #: the ray-triangle unit the backend runs (:data:`raplas_hdl.model.modes.MODES`)
    mode = "paper"
    #: what the host does with the unit's runs (:mod:`raplas_hdl.host.modes`)
    render_mode: RenderMode = get_mode("paper")
    #: whether the unit is built with the on-chip reduction (one ANSWER beat per ray)
    reduce = False
    #: whether the unit's runs go through the compiled passes of :mod:`raplas_hdl.engine`
    #: (:meth:`arithmetic`); if not, the render mode folds the runs' streams (:meth:`stream`)
    runs_compiled = True

    def __init__(self):
        self.tree: SphereTree | None = None
        self.tris: np.ndarray | None = None
        self.scene: EngineScene | None = None
        #: callables ``f(batch, run_b, run_start, run_sph, tmin, tmax, exclude, any_hit)``
        #: told of every pass :meth:`trace` is given, before it runs (warm-up included)
        self.observers: list = []
        #: callables ``f(batch, run_b, run_start, run_sph, counters)`` told of each slice of
        #: a pass (:meth:`slices`) once it ran; one may raise to stop the render there
        self.on_slice: list = []
        #: callables ``f(batch, run_b, run_start, run_sph, counters)`` told of each pass
        #: once all of it ran
        self.on_pass: list = []
        #: the unit's output traffic of the passes traced since :meth:`load`: ``result``
        #: the beats of the unreduced result stream (one per issued pair, one for a run
        #: without any), and with ``reduce`` ``answer`` the ANSWER beats that left the
        #: unit instead (in ``certified`` mode ``uncertain`` of them were uncertain pairs)
        self.beats = {"result": 0, "answer": 0, "uncertain": 0}
        #: the render mode's own counts since :meth:`load` (:meth:`RenderMode.new_stats`)
        self.mode_stats = self.render_mode.new_stats()

    # -- interface ------------------------------------------------------------------------
    def usable(self, tris: np.ndarray) -> tuple[np.ndarray, dict]:
        """Which triangles this backend can load: ``(bool mask (F,), skipped counts by
        reason)``. The default keeps finite triangles of non-zero area."""
        tris = np.asarray(tris, dtype=np.float64)
        finite = np.isfinite(tris).all(axis=(1, 2))
        safe = np.where(finite[:, None, None], tris, 0.0)
        area = np.linalg.norm(np.cross(safe[:, 1] - safe[:, 0], safe[:, 2] - safe[:, 0]),
                              axis=1)
        ok = finite & (area > 0)
        return ok, {"nonfinite": int((~finite).sum()), "degenerate": int((finite & ~ok).sum())}

    def load(self, tris: np.ndarray, tree: SphereTree, bound: float) -> dict:
        """Write a scene. ``tris`` (F, 3, 3) float64 scene coordinates; ``bound`` the
        normalisation bound. Returns a report dict (counts of skipped items etc.)."""
        self.tris = np.asarray(tris, dtype=np.float64)
        self.tree = tree
        self.bound = float(bound)
        self.mode_stats = self.render_mode.new_stats()
        self.beats = dict.fromkeys(self.beats, 0)
        return {}

    def sphere_margin(self, tris: np.ndarray, o_max: float) -> np.ndarray:
        """Per triangle, what its bounding sphere's radius is widened by so that the unit's
        arithmetic cannot lose a hit (:func:`raplas_hdl.host.spheres.unit_margin`); none
        without quantisation."""
        return np.zeros(len(tris))

    def warm_pass(self, origins, centres, col_axes, row_axes, rows: int, cols: int) -> float:
        """Run a throw-away pass of the given bundles (one is enough) through the cull and the
        trace of the loaded scene, so that the kernels are compiled (or loaded from numba's
        disk cache) before the real passes; returns the seconds it took."""
        t0 = time.perf_counter()
        saved = dict(self.mode_stats)           # a throw-away pass counts nothing
        beats = dict(self.beats)

        def run():
            batch = self.batch(origins, centres, col_axes, row_axes, rows, cols)
            cr = self.cull(batch)
            best_t = np.full((batch.n_bundles, batch.n_rays), np.inf)
            best_tri = np.full(best_t.shape, -1, np.int64)
            self.trace(batch, *round_runs(cr.start, cr.leaves, None, 0), best_t, best_tri,
                       0.0, np.full(best_t.shape, np.inf),
                       np.full(batch.n_bundles, -1, np.int64))

        self.render_mode.warm(self, run)
        self.mode_stats.update(saved)
        self.beats.update(beats)
        return time.perf_counter() - t0

    def batch(self, origins, centres, col_axes, row_axes, rows: int, cols: int,
              enable=None) -> BundleBatch:
        """``B`` bundles of ``rows`` x ``cols`` rays from arrays (B, 3) (see
        :func:`raplas_hdl.model.bundles.bundle_geometry`); ``enable`` (B, rows*cols) bool."""
        raise NotImplementedError

    def cull(self, batch: BundleBatch, hierarchy: bool = True):
        """The hierarchy cull of a batch (:func:`raplas_hdl.engine.passes.cull_pass`)."""
        return cull_pass(self.arithmetic(), self.scene, batch, hierarchy)

    def trace(self, batch: BundleBatch, run_b, run_start, run_sph, best_t, best_tri,
              tmin: float = 0.0, tmax=None, exclude=None, any_hit: bool = False) -> np.ndarray:
        """Runs of a batch folded into each ray's nearest hit ``best_t, best_tri`` (B, R),
        in place, by the backend's render mode (:meth:`RenderMode.trace`); counters (U, 8).
        ``any_hit``: only whether a ray is blocked matters (shadow rays); the certified mode
        then stops at the first hit it is sure of, the other modes fold the nearest all the
        same. The :attr:`observers` are told of the pass first; the pass runs in the
        :meth:`slices` the backend cuts it into, :attr:`on_slice` told of each, then
        :attr:`on_pass` of the whole."""
        for observe in self.observers:
            observe(batch, run_b, run_start, run_sph, tmin, tmax, exclude, any_hit)
        cuts = self.slices(batch, run_b, run_start, run_sph)
        if len(cuts) <= 2:
            counters = self.render_mode.trace(self, batch, run_b, run_start, run_sph, best_t,
                                              best_tri, tmin, tmax, exclude, any_hit)
            for told in self.on_slice:
                told(batch, run_b, run_start, run_sph, counters)
        else:
            counters = np.zeros((len(run_b), len(COUNTERS)), np.int64)
            for lo, hi in zip(cuts[:-1], cuts[1:]):
                rs = run_start[lo:hi + 1]
                part = (run_b[lo:hi], rs - rs[0], run_sph[rs[0]:rs[-1]])
                counters[lo:hi] = c = self.render_mode.trace(
                    self, batch, *part, best_t, best_tri, tmin, tmax, exclude, any_hit)
                for told in self.on_slice:
                    told(batch, *part, c)
        for told in self.on_pass:
            told(batch, run_b, run_start, run_sph, counters)
        return counters

    def slices(self, batch: BundleBatch, run_b, run_start, run_sph) -> list:
        """Where :meth:`trace` cuts a pass: run indices ``[0, ..., U]`` (default: one slice,
        the whole pass)."""
        return [0, len(run_b)]

    def stream(self, batch: BundleBatch, runs) -> list[RunResult]:
        """The pair stream of each run ``(bundle index, sphere ids)`` of a batch."""
        raise NotImplementedError

    def describe(self) -> str:
        return self.name

    def check_settings(self, settings) -> None:
        """Raise ``ValueError`` (one line) when the render's settings ask for what this
        backend cannot do; :func:`~raplas_hdl.host.render.render` calls it before any work.
        Every setting is fine by default (a board is one build: :mod:`.board`)."""

    def report(self, stats: dict) -> None:
        """Add the render mode's figures and, with the on-chip reduction, the unit's output
        beats to a finished render's ``stats``."""
        self.render_mode.report(self, stats)
        if self.reduce:
            stats["output_beats"] = dict(self.beats)

    # -- one bundle at a time (tests and exploration) ---------------------------------------
    def prepare(self, bundle: RayBundle, enable=None) -> BundleBatch:
        """A batch of one :class:`~raplas_hdl.model.bundles.RayBundle`."""
        en = None if enable is None else self._enable(bundle, enable)[None]
        return self.batch(bundle.origin[None], bundle.centre[None], bundle.col_axis[None],
                          bundle.row_axis[None], bundle.rows, bundle.cols, en)

    def touched(self, batch: BundleBatch, nodes) -> np.ndarray:
        """The host's hierarchy test of nodes against bundle 0 of a batch (bool array)."""
        nodes = np.asarray(nodes, np.int64)
        keep = np.empty(nodes.size, np.bool_)
        arith = self.arithmetic()
        arith.cull(batch.pn, batch.pp, batch.rows, batch.n_planes,
                   np.zeros(nodes.size, np.int64), nodes, self.scene.node_c, self.scene.node_r,
                   0, nodes.size, keep, *arith.cull_tail)
        return keep

    def run(self, batch: BundleBatch, sphere_ids) -> RunResult:
        """One run of bundle 0 of a batch: its pair stream."""
        return self.stream(batch, [(0, np.asarray(sphere_ids, np.int64))])[0]

    def arithmetic(self) -> Arithmetic:
        """The compiled kernels and constants of the backend's arithmetic (the cull's, and
        the trace's where :attr:`runs_compiled`)."""
        raise NotImplementedError

    # -- helpers --------------------------------------------------------------------------

    def _enable(self, bundle, enable):
        if enable is None:
            return np.ones(bundle.n_rays, dtype=bool)
        en = np.asarray(enable, dtype=bool).reshape(-1)
        if en.shape != (bundle.n_rays,):
            raise ValueError(f"enable must have {bundle.n_rays} entries, not {en.size}")
        return en.copy()

    @staticmethod
    def _enable_array(enable, b, r):
        if enable is None:
            return np.ones((b, r), bool)
        en = np.ascontiguousarray(enable, dtype=bool)
        if en.shape != (b, r):
            raise ValueError(f"enable must have shape ({b}, {r}), not {en.shape}")
        return en.copy()

    def _scene_tree(self, tree, node_c, node_r, sc, sr, v0, e1, e2, nn):
        lists = tree.leaf_tris
        return EngineScene(
            node_c=np.ascontiguousarray(node_c), node_r=np.ascontiguousarray(node_r),
            child_start=tree.child_start.astype(np.int64),
            child_index=tree.child_index.astype(np.int64),
            node_leaf=tree.node_leaf.astype(np.int64), depth=tree.depth.astype(np.int64),
            node_tris=tree.node_tris.astype(np.int64), sc=np.ascontiguousarray(sc),
            sr=np.ascontiguousarray(sr), tcount=(lists >= 0).sum(axis=1).astype(np.int64),
            tlist=np.ascontiguousarray(np.where(lists >= 0, lists, 0), np.int64),
            v0=np.ascontiguousarray(v0), e1=np.ascontiguousarray(e1),
            e2=np.ascontiguousarray(e2), nn=np.ascontiguousarray(nn), levels=tree.levels)

