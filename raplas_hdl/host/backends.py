"""Intersection backends behind one interface: ``float64``, ``model`` and ``rtl``.

The renderer talks to the accelerator only through :class:`Backend`, a pass at a time:

1. :meth:`Backend.load` writes a scene: triangle records and the leaf spheres of a
   :class:`~raplas_hdl.host.spheres.SphereTree` (the Sphere Memory), and keeps the inner
   nodes' spheres for the host's hierarchy test;
2. :meth:`Backend.batch` turns ``B`` bundles of one size, given as arrays (origins, screen
   centres and axes, enable bits), into a :class:`~raplas_hdl.engine.passes.BundleBatch`:
   Plane Memory and Ray Memory in the backend's arithmetic, and the *keep-all* bit of
   every bundle whose quantisation slack is over the culling budget
   (:mod:`raplas_hdl.host.culling`): neither the host nor the unit culls with it;
3. :meth:`Backend.cull` is the hierarchy cull of the whole batch, with the same arithmetic
   as the unit's plane-sphere testers;
4. :meth:`Backend.trace` runs the unit over the batch's runs and folds each ray's nearest
   accepted hit; :meth:`Backend.stream` gives the runs' pair streams instead (the unit's
   result beats with ``t, u, v`` divided on the host), for checks and analyses.

Backends:

- ``float64``: the reference with no quantisation: float64 planes and spheres,
  ``|n.C + p| <= r`` with a float64-rounding allowance, and the division-free
  Moller-Trumbore decision of ``docs/raplas.md`` evaluated in float64 on the original
  geometry (exact-inequality mode). No event flags.
- ``model``: the bit-accurate golden model of the intersection unit in any format,
  rounding and ray-triangle mode, with the radius inflation of
  :mod:`raplas_hdl.host.culling`. Its passes run in the compiled kernels of
  :mod:`raplas_hdl.engine`; its streams come from
  :func:`raplas_hdl.model.intersection.run_runs`, the model's side of the interface the RTL
  driver has (``config, scene, runs``).
- ``rtl``: the same memories run through the Verilog of the unit under cocotb (Icarus or
  Verilator) with the driver's ``run_runs``; it raises :class:`BackendUnavailable` with what
  is missing when the simulator or the unit's driver is not there.

Nothing here imports Amaranth.
"""

from __future__ import annotations

import contextlib
import importlib
import time
from dataclasses import dataclass, field

import numpy as np

from ..engine.kernels import (F64_SLACK, cull_f64, cull_model, model_args, trace_f64,
                              trace_model)
from ..engine.passes import (COUNTER_NAMES, Arithmetic, BundleBatch, EngineScene,
                             cull_pass, round_runs, trace_pass)
from ..fp.format import FP24, FPFormat, check_format
from ..model.bundles import RayBundle, bundle_geometry, encode_bundle_arrays
from ..model.modes import check_mode
from .shading import nearest_hits
from .spheres import SphereTree

__all__ = [
    "BACKENDS",
    "Backend",
    "BackendUnavailable",
    "COUNTERS",
    "Float64Backend",
    "ModelBackend",
    "RtlBackend",
    "RunResult",
    "make_backend",
]

BACKENDS = ("float64", "model", "rtl")

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


def runs_of(run_b, run_start, run_sph):
    return [(int(b), run_sph[run_start[u]:run_start[u + 1]]) for u, b in enumerate(run_b)]


class Backend:
    """Common part of the backends (see the module docstring for the protocol)."""

    name = "?"
    fmt: FPFormat | None = None
    mode = "paper"

    def __init__(self):
        self.tree: SphereTree | None = None
        self.tris: np.ndarray | None = None
        self.scene: EngineScene | None = None

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
        return {}

    def warm_pass(self, origins, centres, col_axes, row_axes, rows: int, cols: int) -> float:
        """Run a throw-away pass of the given bundles (one is enough) through the cull and the
        trace of the loaded scene, so that the kernels are compiled (or loaded from numba's
        disk cache) before the real passes; returns the seconds it took."""
        t0 = time.perf_counter()
        saved = dict(getattr(self, "certified", {}))     # a throw-away pass counts nothing
        beats = dict(getattr(self, "beats", {}))
        batch = self.batch(origins, centres, col_axes, row_axes, rows, cols)
        cr = self.cull(batch)
        best_t = np.full((batch.n_bundles, batch.n_rays), np.inf)
        best_tri = np.full(best_t.shape, -1, np.int64)
        self.trace(batch, *round_runs(cr.start, cr.leaves, None, 0), best_t, best_tri, 0.0,
                   np.full(best_t.shape, np.inf), np.full(batch.n_bundles, -1, np.int64))
        if saved:
            self.certified.update(saved)
        if beats:
            self.beats.update(beats)
        return time.perf_counter() - t0

    def batch(self, origins, centres, col_axes, row_axes, rows: int, cols: int,
              enable=None) -> BundleBatch:
        """``B`` bundles of ``rows`` x ``cols`` rays from arrays (B, 3) (see
        :func:`raplas_hdl.model.bundles.bundle_geometry`); ``enable`` (B, rows*cols) bool."""
        raise NotImplementedError

    def cull(self, batch: BundleBatch, hierarchy: bool = True):
        """The hierarchy cull of a batch (:func:`raplas_hdl.engine.passes.cull_pass`)."""
        return cull_pass(self._arith(), self.scene, batch, hierarchy)

    def trace(self, batch: BundleBatch, run_b, run_start, run_sph, best_t, best_tri,
              tmin: float = 0.0, tmax=None, exclude=None, any_hit: bool = False) -> np.ndarray:
        """Runs of a batch folded into each ray's nearest hit
        (:func:`raplas_hdl.engine.passes.trace_pass`); counters (U, 8). ``any_hit``: only
        whether a ray is blocked matters (shadow rays); the certified mode then stops at the
        first hit it is sure of, the other modes fold the nearest all the same."""
        return trace_pass(self._arith(), self.scene, batch, run_b, run_start, run_sph,
                          best_t, best_tri, tmin, tmax, exclude)

    def stream(self, batch: BundleBatch, runs) -> list[RunResult]:
        """The pair stream of each run ``(bundle index, sphere ids)`` of a batch."""
        raise NotImplementedError

    def describe(self) -> str:
        return self.name

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
        arith = self._arith()
        arith.cull(batch.pn, batch.pp, batch.rows, batch.n_planes,
                   np.zeros(nodes.size, np.int64), nodes, self.scene.node_c, self.scene.node_r,
                   0, nodes.size, keep, *arith.cull_tail)
        return keep

    def run(self, batch: BundleBatch, sphere_ids) -> RunResult:
        """One run of bundle 0 of a batch: its pair stream."""
        return self.stream(batch, [(0, np.asarray(sphere_ids, np.int64))])[0]

    # -- helpers --------------------------------------------------------------------------
    def _arith(self) -> Arithmetic:
        raise NotImplementedError

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


class Float64Backend(Backend):
    """Reference backend: float64 culling and float64 Moller-Trumbore, no quantisation."""

    name = "float64"

    def load(self, tris, tree, bound):
        rep = super().load(tris, tree, bound)
        r = tree.radii * (1.0 + F64_SLACK)
        t = self.tris
        v0 = t[:, 0]
        e1, e2 = t[:, 1] - v0, t[:, 2] - v0
        nn = np.stack([e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1],
                       e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2],
                       e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]], axis=1)
        leaf = tree.leaf_node
        self.scene = self._scene_tree(tree, tree.centres, r, tree.centres[leaf], r[leaf], v0,
                                      e1, e2, nn)
        return rep

    def _arith(self):
        return Arithmetic("float64", cull_f64, trace_f64, ())

    def batch(self, origins, centres, col_axes, row_axes, rows, cols, enable=None):
        g = bundle_geometry(origins, centres, col_axes, row_axes, rows, cols)
        B = len(g["plane_p"])
        o = np.ascontiguousarray(origins, np.float64).reshape(B, 3)
        return BundleBatch(rows, cols, np.ascontiguousarray(g["plane_n"].reshape(-1, 3)),
                           np.ascontiguousarray(g["plane_p"].reshape(-1)), o,
                           np.ascontiguousarray(g["directions"].reshape(-1, 3)),
                           self._enable_array(enable, B, rows * cols), np.zeros(B, bool), o,
                           g["directions"], g)

    def _masks(self, batch, b, ids):
        """The float64 plane test of leaf spheres ``ids`` against bundle ``b``'s planes
        (S, P), the arithmetic of :func:`raplas_hdl.engine.kernels.cull_f64`."""
        P = batch.n_planes
        if batch.keep_all[b]:
            return np.ones((ids.size, P), bool)
        pn = batch.pn[b * P:(b + 1) * P]
        pp = batch.pp[b * P:(b + 1) * P]
        a = self.scene.sc[ids][:, None, :] * pn[None, :, :]
        d = a[..., 0] + a[..., 1] + a[..., 2] + pp
        slack = F64_SLACK * (np.abs(a[..., 0]) + np.abs(a[..., 1]) + np.abs(a[..., 2])
                             + np.abs(pp))
        return np.abs(d) <= self.scene.sr[ids][:, None] + slack

    def stream(self, batch, runs):
        from ..model.intersection import enumerate_pairs
        from .exact import float64_intersect

        out = []
        sc = self.scene
        for b, ids in runs:
            ids = np.asarray(ids, dtype=np.int64)
            counters = dict.fromkeys(COUNTERS, 0)
            counters["spheres"] = int(ids.size)
            counters["plane_tests"] = int(ids.size) * batch.n_planes
            if ids.size == 0:
                out.append(RunResult.empty(counters))
                continue
            keep = self._masks(batch, b, ids)
            rm, cm = keep[:, :batch.rows], keep[:, batch.rows:]
            ray, tri, skipped = enumerate_pairs(batch, rm, cm, sc.tcount[ids], sc.tlist[ids],
                                                batch.enable[b])
            counters["pairs_skipped"] = skipped
            counters["pairs_issued"] = int(ray.size)
            tv = self.tris[tri]
            r = float64_intersect(np.broadcast_to(batch.origin[b], (ray.size, 3)),
                                  batch.directions[b][ray], tv[:, 0], tv[:, 1], tv[:, 2])
            hit = np.asarray(r["hit"], bool)
            t, u, v = (np.where(hit, r[k], np.nan) for k in ("t", "u", "v"))
            counters["hits"] = int(hit.sum())
            out.append(RunResult(ray, tri, hit, t, u, v, np.zeros(ray.size, np.uint8),
                                 counters))
        return out


class ModelBackend(Backend):
    """The bit-accurate golden model of the intersection unit.

    Parameters
    ----------
    fmt : FPFormat
        Arithmetic format and rounding.
    mode : str
        Ray-triangle mode: ``"paper"`` or ``"conservative"``.
    testers : int or None
        Plane-sphere testers (only changes the RTL's timing, not the results).
    margin_scale : int
        Scale of the conservative margin.
    """

    name = "model"

    def __init__(self, fmt: FPFormat = FP24, mode: str = "conservative", testers=None,
                 margin_scale: int = 1, reduce: bool = False):
        super().__init__()
        check_format(fmt)
        check_mode(mode)
        if mode == "certified":
            from ..model.certified import check_certified_format

            check_certified_format(fmt)
        if reduce:
            _check_reduce(fmt, mode)
        self.fmt, self.mode, self.testers, self.margin_scale = fmt, mode, testers, margin_scale
        self.reduce = bool(reduce)
        #: the unit's output traffic of the passes traced since :meth:`load`: ``result``
        #: the beats of the unreduced result stream (one per issued pair, one for a run
        #: without any), and with ``reduce`` ``answer`` the ANSWER beats that left the
        #: unit instead (in ``certified`` mode ``uncertain`` of them were uncertain pairs)
        self.beats = {"result": 0, "answer": 0, "uncertain": 0}
        self._configs = {}
        #: certified mode's work: the unit's certified hits and uncertain pairs, pairs
        #: through the float64 filter, pairs it left pending, pairs evaluated exactly and
        #: the seconds that took
        self.certified = dict.fromkeys(("certified_hits", "uncertain", "filtered", "pending",
                                        "exact", "exact_s"), 0)

    def describe(self):
        return f"{self.name} {self.fmt} {self.mode}" + (" reduce" if self.reduce else "")

    def config(self, rows, cols):
        """The unit configuration for a ``rows`` x ``cols`` bundle (one per size)."""
        from ..model.config import UnitConfig

        key = (rows, cols)
        if key not in self._configs:
            # Memory depths are rounded up to powers of two (at least 256 triangles and 64
            # spheres) so that scenes of similar size share one RTL build.
            def depth(n, least):
                return max(least, 1 << max(0, int(n) - 1).bit_length())
            self._configs[key] = UnitConfig(
                fmt=self.fmt, rows=rows, cols=cols, testers=self.testers,
                tris_per_sphere=self.tree.tris_per_sphere,
                max_triangles=depth(len(self.tris), 256),
                max_spheres=depth(self.tree.n_leaves, 64),
                mode=self.mode, margin_scale=self.margin_scale, reduce=self.reduce)
        return self._configs[key]

    def _arith(self):
        from ..model.conservative import margin_constants, margin_table

        tail = model_args(self.fmt, self.mode)
        if self.mode == "certified":
            from ..model.certified import certified_constants

            return Arithmetic("model", cull_model, None, (certified_constants(self.fmt),),
                              tail[:3], tail)
        mc = (margin_table(margin_constants(self.fmt, self.margin_scale)) if tail[3]
              else np.zeros((3, 5), np.int64))
        return Arithmetic("model", cull_model, trace_model, (mc,), tail[:3], tail)

    def trace(self, batch, run_b, run_start, run_sph, best_t, best_tri, tmin=0.0, tmax=None,
              exclude=None, any_hit=False):
        """As :meth:`Backend.trace`; in ``certified`` mode the unit's outcomes, the float64
        filter and the exact resolution of what it leaves
        (:func:`raplas_hdl.engine.certified.certified_pass`,
        :func:`raplas_hdl.host.resolve.resolve_pending`) give R's answer per ray, and
        :attr:`certified` counts the work. In ``conservative`` mode the unit's hits are a
        superset of R's (false hits in a band around each triangle,
        docs/conservative-mode.md): each goes through the same filter and resolution as an
        uncertain pair (its misses are final), so the render is R's too. With ``reduce``
        (paper or certified) the unit's answers (:meth:`_trace_reduced`)."""
        if self.reduce:
            return self._trace_reduced(batch, run_b, run_start, run_sph, best_t, best_tri,
                                       tmin, tmax, exclude, any_hit)
        if self.mode not in ("certified", "conservative"):
            ctr = super().trace(batch, run_b, run_start, run_sph, best_t, best_tri, tmin,
                                tmax, exclude, any_hit)
            self.beats["result"] += _result_beats(ctr)
            return ctr
        from ..engine.certified import CERT_COUNTERS, certified_pass

        if not any_hit and (best_tri[np.asarray(run_b, np.int64)] >= 0).any():
            raise ValueError("a certified nearest-hit pass starts from rays without a hit")
        lo = np.where(best_tri >= 0, best_t, np.inf)
        hi = lo.copy()
        cons = self.mode == "conservative"
        if cons:
            from ..engine.certified import conservative_pairs
        ctr, pending = certified_pass(self._arith(), self.scene, batch, run_b, run_start,
                                      run_sph, self.tris, lo, hi, best_tri, tmin, tmax,
                                      exclude, any_hit, unit=conservative_pairs if cons else None)
        self._resolve_pending(batch, pending, lo, hi, best_t, best_tri, tmin, tmax, exclude,
                              any_hit)
        st = self.certified
        st["certified_hits"] += int(ctr[:, COUNTERS.index("hits")].sum())
        for k, name in enumerate(CERT_COUNTERS):
            st[name] += int(ctr[:, len(COUNTERS) + k].sum())
        if cons:            # every hit of the conservative unit is an "uncertain" pair
            ctr[:, COUNTERS.index("hits")] = ctr[:, len(COUNTERS)]
        self.beats["result"] += _result_beats(ctr[:, :len(COUNTERS)])
        return ctr[:, :len(COUNTERS)]

    def _resolve_pending(self, batch, pending, lo, hi, best_t, best_tri, tmin, tmax, exclude,
                         any_hit):
        """The exact resolution of the pending pairs (:func:`raplas_hdl.host.resolve.
        resolve_pending`), counted in :attr:`certified` (``exact``, ``exact_s``)."""
        from .resolve import resolve_pending

        t0 = time.perf_counter()
        exact = resolve_pending(pending, batch.origin, batch.directions, self.tris, lo, hi,
                                best_tri, best_t, tmin, tmax, exclude, any_hit)
        self.certified["exact_s"] += time.perf_counter() - t0
        self.certified["exact"] += exact

    def window_runs(self, batch, runs, tmin=0.0, tmax=None, exclude=None, any_hit=False):
        """The runs ``(bundle index, sphere ids)`` of a batch as ``(BundleMemory, ids)`` whose
        bundles carry the host's window in the unit's format: ``tmin`` rounded up and each
        ray's ``tmax`` rounded down (+infinity stays +infinity), so the unit never accepts
        what the float64 window rejects; ``exclude`` per bundle; ``any_hit``."""
        from dataclasses import replace

        from ..fp import model as fpm
        from ..model.reduction import inf_pattern

        fmt, R = self.fmt, batch.n_rays
        lo = int(fpm.encode(np.array([float(tmin)]), fmt, direction="up")[0])
        hi = None
        if tmax is not None:
            tm = np.asarray(tmax, np.float64)
            tm = np.broadcast_to(tm[:, None] if tm.ndim == 1 else tm, (batch.n_bundles, R))
            fin = np.isfinite(tm)
            hi = np.full(tm.shape, inf_pattern(fmt), np.uint32)
            hi[fin] = fpm.encode(tm[fin], fmt, direction="down")
        ex = None if exclude is None else np.asarray(exclude, np.int64)
        out = []
        for b, ids in runs:
            mem = replace(self.memory(batch, b), tmin=lo, any_hit=bool(any_hit),
                          tmax=None if hi is None else hi[b],
                          exclude=-1 if ex is None else int(ex[b]))
            out.append((mem, np.asarray(ids, np.int64)))
        return out

    def _trace_reduced(self, batch, run_b, run_start, run_sph, best_t, best_tri, tmin, tmax,
                       exclude, any_hit):
        """:meth:`trace` through the unit built with the on-chip reduction: the window goes
        with each bundle (:meth:`window_runs`), one ANSWER beat per ray leaves the unit, and
        the host folds only those (no per-pair work on the host). A certified unit also
        sends its uncertain pairs: the host resolves its answers and those pairs as the
        certified render resolves the unit's hits and uncertain pairs
        (:meth:`_resolve_outcomes`)."""
        from ..fp import model as fpm

        runs = runs_of(run_b, run_start, run_sph)
        counters = np.zeros((len(runs), len(COUNTERS)), np.int64)
        if not runs:
            return counters
        cfg = self.config(batch.rows, batch.cols)
        results = self._run_runs(cfg, self.window_runs(batch, runs, tmin, tmax, exclude,
                                                       any_hit))
        counters[:] = [[c.get(n, 0) for n in COUNTERS] for _, c in results]
        answers = [a for a, _ in results]
        self.beats["result"] += _result_beats(counters)
        self.beats["answer"] += sum(len(a) for a in answers)
        keep = [k for k, a in enumerate(answers) if not a["empty"].all()]
        if self.mode == "certified":
            beats = [answers[k][~answers[k]["empty"].astype(bool)] for k in keep]
            self.beats["uncertain"] += sum(int((a["outcome"] == 2).sum()) for a in beats)
            self.certified["certified_hits"] += int(counters[:, COUNTERS.index("hits")].sum())
            self._resolve_outcomes(batch, [(runs[k][0], a["ray_id"], a["tri_id"], a["outcome"])
                                           for k, a in zip(keep, beats)],
                                   best_t, best_tri, tmin, tmax, exclude, any_hit)
            return counters
        if not keep:
            return counters
        ans = np.concatenate([answers[k] for k in keep])
        b = np.repeat(np.asarray([runs[k][0] for k in keep], np.int64),
                      [len(answers[k]) for k in keep])
        ray, tri = ans["ray_id"].astype(np.int64), ans["tri_id"].astype(np.int64)
        tf, df = fpm.decode(np.stack([ans["t"], ans["det"]]), self.fmt)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = tf * (1.0 / df)         # as the compiled passes compute it
        # a bundle's rays may answer in several runs of the pass: the nearest, ties to the
        # lower triangle ID, then against what the rays had before
        order = np.lexsort((tri, t, b * batch.n_rays + ray))
        key = (b * batch.n_rays + ray)[order]
        first = np.ones(order.size, bool)
        first[1:] = key[1:] != key[:-1]
        sel = order[first]
        bs, rs, ts, trs = b[sel], ray[sel], t[sel], tri[sel]
        cur_t, cur_tri = best_t[bs, rs], best_tri[bs, rs]
        better = (ts < cur_t) | ((ts == cur_t) & (trs < cur_tri))
        best_t[bs[better], rs[better]] = ts[better]
        best_tri[bs[better], rs[better]] = trs[better]
        return counters

    def _resolve_outcomes(self, batch, pairs, best_t, best_tri, tmin, tmax, exclude, any_hit):
        """R's answer per ray from pairs of known outcome, in stream order: ``pairs`` is a
        list of ``(bundle, ray_ids, tri_ids, outcomes)`` (0 miss, 1 certain hit, 2
        uncertain). Misses are final; the others go through R's float64 filter, the fold
        and the exact resolution of what it leaves
        (:func:`raplas_hdl.engine.certified.fold_outcomes`,
        :func:`raplas_hdl.host.resolve.resolve_pending`), as in the certified pass."""
        from ..engine.certified import fold_outcomes

        if not pairs:
            return
        R = batch.n_rays
        lanes = np.concatenate([np.stack([np.full(len(ray), b), ray, b * R + ray, tri, out])
                                for b, ray, tri, out in
                                ((b, np.asarray(r, np.int64), np.asarray(t, np.int64),
                                  np.asarray(o, np.int64)) for b, r, t, o in pairs)],
                               axis=1).astype(np.int64)
        lo = np.where(best_tri >= 0, best_t, np.inf)
        hi = lo.copy()
        pending = fold_outcomes(lanes, lanes[4], batch, self.tris, lo, hi, best_tri, tmin,
                                tmax, exclude, any_hit)
        self._resolve_pending(batch, pending, lo, hi, best_t, best_tri, tmin, tmax, exclude,
                              any_hit)
        st = self.certified
        st["pending"] += len(pending)
        st["uncertain"] += int((lanes[4] == 2).sum())
        st["filtered"] += int((lanes[4] != 0).sum())

    def usable(self, tris):
        """Triangles that :func:`raplas_hdl.host.triangles.make_triangles` keeps (not
        non-finite, degenerate, flushed, or outside the format's domain). The certified
        mode's domain is its own (:func:`raplas_hdl.model.certified.certified_domain`: a
        bound on the coordinates, no minimum edge, its bounds cover flushes)."""
        from .triangles import make_triangles

        tris = np.asarray(tris, dtype=np.float64)
        if self.mode == "certified":
            from ..model.certified import certified_domain

            rec = make_triangles(tris, self.fmt, on_bad="skip",
                                 max_coord=certified_domain(self.fmt))
        else:
            rec = make_triangles(tris, self.fmt, on_bad="skip", check_domain=True)
        self._records = (tris, rec)
        ok = np.zeros(len(tris), bool)
        ok[rec.ids] = True
        return ok, dict(rec.skipped)

    def load(self, tris, tree, bound):
        from ..model.memory_image import SceneMemory
        from .culling import CullingBudget, encode_spheres

        rep = super().load(tris, tree, bound)
        self.certified = dict.fromkeys(self.certified, 0)
        self.beats = dict.fromkeys(self.beats, 0)
        cached = getattr(self, "_records", None)
        if cached is None or cached[0] is not tris and not np.array_equal(cached[0], tris):
            self.usable(tris)
        rec = self._records[1]
        # Triangle Memory is indexed by the scene's triangle ID; rows of skipped
        # triangles stay zero and no sphere lists them.
        v0, e1, e2, n = (np.zeros((len(self.tris), 3), np.uint32) for _ in range(4))
        v0[rec.ids], e1[rec.ids], e2[rec.ids], n[rec.ids] = (rec.v0_bits, rec.e1_bits,
                                                             rec.e2_bits, rec.n_bits)
        self.budget = CullingBudget(self.fmt, o_max=2.0 * self.bound)
        self._centres, _, self._radii, ok = encode_spheres(tree.centres, tree.radii,
                                                           self.budget)
        rep["spheres_out_of_domain"] = int(np.count_nonzero(~ok[tree.leaf_node]))
        leaf = tree.leaf_node
        lists = tree.leaf_tris
        counts = (lists >= 0).sum(axis=1)
        self.scene_memory = SceneMemory(v0, e1, e2, n, self._centres[leaf], self._radii[leaf],
                                        np.where(lists >= 0, lists, 0).astype(np.uint32),
                                        counts.astype(np.uint32))
        sm = self.scene_memory
        self.scene = self._scene_tree(tree, self._centres, self._radii, sm.centres, sm.radii,
                                      sm.v0, sm.e1, sm.e2, sm.n)
        self._configs = {}
        return rep

    def batch(self, origins, centres, col_axes, row_axes, rows, cols, enable=None):
        from ..fp import model as fpm
        from .culling import slack_arrays

        fmt = self.fmt
        g = bundle_geometry(origins, centres, col_axes, row_axes, rows, cols)
        B = len(g["plane_p"])
        n, p, o, d = encode_bundle_arrays(np.asarray(origins, np.float64).reshape(B, 3),
                                          g["plane_n"], g["directions"], fmt)
        keep_all = np.zeros(B, bool)
        if fmt.man_bits <= 25 and B:
            keep_all = ~self.budget.admits_arrays(slack_arrays(n, p, o, d, rows, cols, fmt))
        return BundleBatch(rows, cols, np.ascontiguousarray(n.reshape(-1, 3)),
                           np.ascontiguousarray(p.reshape(-1)), np.ascontiguousarray(o),
                           np.ascontiguousarray(d.reshape(-1, 3)),
                           self._enable_array(enable, B, rows * cols), keep_all,
                           fpm.decode(o, fmt), fpm.decode(d, fmt), g)

    def memory(self, batch: BundleBatch, b: int):
        """Plane Memory and Ray Memory of bundle ``b`` of a batch (a
        :class:`~raplas_hdl.model.memory_image.BundleMemory`, keep-all bit included)."""
        from ..model.memory_image import BundleMemory

        P, R = batch.n_planes, batch.n_rays
        return BundleMemory(batch.pn[b * P:(b + 1) * P], batch.pp[b * P:(b + 1) * P],
                            np.broadcast_to(batch.ro[b], (R, 3)), batch.rd[b * R:(b + 1) * R],
                            batch.enable[b].copy(), keep_all=bool(batch.keep_all[b]))

    def _convert(self, out, counters) -> RunResult:
        from ..fp import model as fpm

        if out.size == 1 and out["empty"][0]:
            return RunResult.empty(counters)
        hit = out["hit"].astype(bool)
        outcome = out["outcome"].astype(np.int64) if "outcome" in out.dtype.names else None
        tuvd = fpm.decode(np.stack([out["t"], out["u"], out["v"], out["det"]]), self.fmt)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(hit, 1.0 / np.where(hit, tuvd[3], 1.0), np.nan)
            t, u, v = tuvd[0] * inv, tuvd[1] * inv, tuvd[2] * inv
        return RunResult(out["ray_id"].astype(np.int64), out["tri_id"].astype(np.int64), hit,
                         t, u, v, out["flags"].astype(np.uint8), counters, outcome)

    def _run_runs(self, config, runs):
        from ..model.intersection import run_runs

        return run_runs(config, self.scene_memory, runs)

    def stream(self, batch, runs):
        runs = list(runs)
        if not runs:
            return []
        cfg = self.config(batch.rows, batch.cols)
        results = self._run_runs(cfg, [(self.memory(batch, b), np.asarray(ids, np.int64))
                                       for b, ids in runs])
        return [self._convert(stream, counters) for stream, counters in results]


class RtlBackend(ModelBackend):
    """The Verilog of the intersection unit, simulated (Icarus or Verilator).

    The host side (memories, hierarchy test, pair order) is the model backend's. The runs go
    through live simulations of the unit (:class:`raplas_hdl.sim.unit_harness.UnitSession`):
    one per unit configuration a render needs (the primary and the shadow bundle sizes),
    started on first use with the scene loaded once, then fed one round of runs per
    :meth:`stream` call; the simulator builds are cached on disk across renders. A new
    scene (:meth:`load`) or :meth:`close` ends the sessions. With waveforms asked for
    (``WAVES=1``, ``render --waves``) the runs go through the per-cycle cocotb driver
    (:func:`raplas_hdl.sim.unit_driver.run_runs`, one simulation per round) instead.

    Raises
    ------
    BackendUnavailable
        At construction, when the simulator, or the unit's driver, is missing.
    """

    name = "rtl"
    DRIVER = "raplas_hdl.sim.unit_harness"

    def __init__(self, fmt: FPFormat = FP24, mode: str = "conservative", testers=None,
                 margin_scale: int = 1, sim: str = "icarus", reduce: bool = False):
        super().__init__(fmt, mode, testers, margin_scale, reduce)
        try:
            from raplas_hdl.sim.runner import SimulatorNotFound, require_simulator
        except ImportError as exc:
            raise BackendUnavailable(
                f"the rtl backend needs the raplas_hdl.sim package: {exc}") from exc
        try:
            require_simulator(sim)
        except SimulatorNotFound as exc:
            raise BackendUnavailable(str(exc)) from exc
        except ValueError as exc:
            raise BackendUnavailable(f"unknown simulator {sim!r}: {exc}") from exc
        try:
            self._driver = importlib.import_module(self.DRIVER)
        except ImportError as exc:
            raise BackendUnavailable(
                f"the rtl backend needs the intersection unit's driver "
                f"({self.DRIVER.replace('.', '/')}.py with UnitSession), which is not "
                f"available: {exc}") from exc
        if not hasattr(self._driver, "UnitSession"):
            raise BackendUnavailable(f"{self.DRIVER} has no UnitSession; the rtl backend "
                                     f"cannot drive the unit")
        self.sim = sim
        self._sessions = {}
        #: per configuration: clock cycles, scene-load cycles and seconds, rounds, and
        #: ``rounds_s`` (wall seconds in the rounds: sending jobs, simulating, decoding)
        self.session_stats = {}
        #: a directory to record each session's op stream in (``<rows>x<cols>.ops``; the
        #: benchmark replays them without a host), or None
        self.record_dir = None

    def describe(self):
        return (f"{self.name} ({self.sim}) {self.fmt} {self.mode}"
                + (" reduce" if self.reduce else ""))

    def load(self, tris, tree, bound):
        self.close()
        return super().load(tris, tree, bound)

    def session(self, config):
        """The live simulation of ``config`` (started, and the scene loaded, on first use)."""
        s = self._sessions.get(config)
        if s is None:
            from pathlib import Path

            record = None
            if self.record_dir is not None:
                Path(self.record_dir).mkdir(parents=True, exist_ok=True)
                record = Path(self.record_dir) / f"{config.rows}x{config.cols}.ops"
            s = self._sessions[config] = self._driver.UnitSession(self.sim, config,
                                                                   self.scene_memory,
                                                                   record=record)
            self.session_stats[config] = {"cycles": s.cycles, "load_cycles": s.load_cycles,
                                          "load_s": s.load_s, "rounds": s.rounds,
                                          "rounds_s": 0.0}
        return s

    def _run_runs(self, config, runs):
        import os

        if os.environ.get("WAVES", "") not in ("", "0"):
            # waveforms (render --waves): the per-cycle cocotb driver, which records them
            from raplas_hdl.sim.unit_driver import run_runs

            return run_runs(self.sim, config, self.scene_memory, runs)
        s = self.session(config)
        t0 = time.perf_counter()
        out = s.run(runs)
        st = self.session_stats[config]
        st.update(cycles=s.cycles, rounds=s.rounds)
        st["rounds_s"] += time.perf_counter() - t0
        return out

    def close(self):
        """End every live simulation (a later run starts a new one)."""
        sessions, self._sessions = self._sessions, {}
        for s in sessions.values():
            s.close()

    def __del__(self):
        with contextlib.suppress(Exception):   # interpreter shutdown
            self.close()

    def warm_pass(self, *args, **kwargs) -> float:
        """Nothing to compile on the host side (the simulator builds on first use)."""
        return 0.0

    def trace(self, batch, run_b, run_start, run_sph, best_t, best_tri, tmin=0.0, tmax=None,
              exclude=None, any_hit=False):
        """The runs through the simulated unit (one round of the configuration's live
        simulation), each run's stream folded into the nearest hits on the host; with
        ``reduce`` the unit's answers (:meth:`ModelBackend._trace_reduced`)."""
        if self.reduce:
            return self._trace_reduced(batch, run_b, run_start, run_sph, best_t, best_tri,
                                       tmin, tmax, exclude, any_hit)
        runs = runs_of(run_b, run_start, run_sph)
        counters = np.zeros((len(runs), len(COUNTERS)), np.int64)
        R = batch.n_rays
        if runs and self.mode in ("conservative", "certified"):
            # conservative: the unit's hits are a superset of R's; certified: its hits and
            # uncertain pairs. Either way the model's filter and exact resolution
            # (ModelBackend.trace) on the stream, in stream order
            pairs = []
            for k, ((b, _), res) in enumerate(zip(runs, self.stream(batch, runs))):
                counters[k] = [res.counters.get(n, 0) for n in COUNTERS]
                out = (np.where(res.hit, 2, 0) if res.outcome is None else res.outcome)
                pairs.append((b, res.ray_id, res.tri_id, out))
            saved = dict(self.certified)
            self._resolve_outcomes(batch, pairs, best_t, best_tri, tmin, tmax, exclude,
                                   any_hit)
            if self.mode == "certified":
                self.certified["certified_hits"] += int(
                    counters[:, COUNTERS.index("hits")].sum())
            else:
                self.certified = saved
        elif runs:
            for k, ((b, _), res) in enumerate(zip(runs, self.stream(batch, runs))):
                counters[k] = [res.counters.get(n, 0) for n in COUNTERS]
                hi = np.inf if tmax is None else np.asarray(tmax)[b]
                ex = None if exclude is None else int(np.asarray(exclude)[b])
                tri, t, _ = nearest_hits(R, res.ray_id, res.tri_id, res.hit, res.t, tmin, hi,
                                         ex)
                better = (tri >= 0) & ((t < best_t[b]) | ((t == best_t[b])
                                                          & (tri < best_tri[b])))
                best_t[b] = np.where(better, t, best_t[b])
                best_tri[b] = np.where(better, tri, best_tri[b])
        self.beats["result"] += _result_beats(counters)
        return counters


def _check_reduce(fmt, mode):
    """Raise ``ValueError`` (one line) unless a backend can render through the on-chip
    reduction in ``fmt`` and ``mode`` (paper or certified)."""
    from ..model.reduction import check_reduce_format

    if mode == "conservative":
        raise ValueError(f"the on-chip reduction has no {mode} mode (its hits must reach the "
                         f"host to be resolved): use --mode paper or certified, or no "
                         f"--reduce")
    check_reduce_format(fmt)


def _result_beats(counters) -> int:
    """Beats of the unreduced result stream of runs with these counters (U, 8): one per
    issued pair, one (empty) for a run that issued none."""
    pairs = np.asarray(counters)[:, COUNTERS.index("pairs_issued")]
    return int(np.maximum(pairs, 1).sum())


def make_backend(name: str, fmt: FPFormat = FP24, mode: str = "conservative",
                 sim: str = "icarus", testers=None, reduce: bool = False) -> Backend:
    """A backend by name (``float64``, ``model``, ``rtl``); ``reduce``: through the unit
    built with the on-chip reduction (model and rtl).

    Raises
    ------
    ValueError
        For an unknown name, or ``reduce`` where it does not apply.
    BackendUnavailable
        For ``rtl`` when the simulator or the unit's driver is missing.
    """
    if name == "float64":
        if reduce:
            raise ValueError("the float64 backend has no unit to reduce on: use --backend "
                             "model or rtl with --reduce")
        return Float64Backend()
    if name == "model":
        return ModelBackend(fmt, mode, testers, reduce=reduce)
    if name == "rtl":
        return RtlBackend(fmt, mode, testers, sim=sim, reduce=reduce)
    raise ValueError(f"unknown backend {name!r}: use one of {', '.join(BACKENDS)}")
