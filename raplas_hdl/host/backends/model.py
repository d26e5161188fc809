"""The ``model`` backend: the bit-accurate golden model of the intersection unit, its passes
in the compiled kernels of :mod:`raplas_hdl.engine`."""

from __future__ import annotations

import time

import numpy as np

from ...engine.kernels import cull_model, model_args, trace_model
from ...engine.passes import Arithmetic, BundleBatch
from ...fp.format import FP24, FPFormat, check_format
from ...model.bundles import bundle_geometry, encode_bundle_arrays
from ...model.modes import check_mode
from .base import COUNTERS, Backend, RunResult, result_beats, runs_of


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
            from ...model.certified import check_certified_format

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
        from ...model.config import UnitConfig

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
        from ...model.conservative import margin_constants, margin_table

        tail = model_args(self.fmt, self.mode)
        if self.mode == "certified":
            from ...model.certified import certified_constants

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
            self.beats["result"] += result_beats(ctr)
            return ctr
        from ...engine.certified import CERT_COUNTERS, certified_pass

        if not any_hit and (best_tri[np.asarray(run_b, np.int64)] >= 0).any():
            raise ValueError("a certified nearest-hit pass starts from rays without a hit")
        lo = np.where(best_tri >= 0, best_t, np.inf)
        hi = lo.copy()
        cons = self.mode == "conservative"
        if cons:
            from ...engine.certified import conservative_pairs
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
        self.beats["result"] += result_beats(ctr[:, :len(COUNTERS)])
        return ctr[:, :len(COUNTERS)]

    def _resolve_pending(self, batch, pending, lo, hi, best_t, best_tri, tmin, tmax, exclude,
                         any_hit):
        """The exact resolution of the pending pairs (:func:`raplas_hdl.host.resolve.
        resolve_pending`), counted in :attr:`certified` (``exact``, ``exact_s``)."""
        from ..resolve import resolve_pending

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

        from ...fp import model as fpm
        from ...model.reduction import inf_pattern

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
        from ...fp import model as fpm

        runs = runs_of(run_b, run_start, run_sph)
        counters = np.zeros((len(runs), len(COUNTERS)), np.int64)
        if not runs:
            return counters
        cfg = self.config(batch.rows, batch.cols)
        results = self._run_runs(cfg, self.window_runs(batch, runs, tmin, tmax, exclude,
                                                       any_hit))
        counters[:] = [[c.get(n, 0) for n in COUNTERS] for _, c in results]
        answers = [a for a, _ in results]
        self.beats["result"] += result_beats(counters)
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
        from ...engine.certified import fold_outcomes

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
        from ..triangles import make_triangles

        tris = np.asarray(tris, dtype=np.float64)
        if self.mode == "certified":
            from ...model.certified import certified_domain

            rec = make_triangles(tris, self.fmt, on_bad="skip",
                                 max_coord=certified_domain(self.fmt))
        else:
            rec = make_triangles(tris, self.fmt, on_bad="skip", check_domain=True)
        self._records = (tris, rec)
        ok = np.zeros(len(tris), bool)
        ok[rec.ids] = True
        return ok, dict(rec.skipped)

    def load(self, tris, tree, bound):
        from ...model.memory_image import SceneMemory
        from ..culling import CullingBudget, encode_spheres

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
        from ...fp import model as fpm
        from ..culling import slack_arrays

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
        from ...model.memory_image import BundleMemory

        P, R = batch.n_planes, batch.n_rays
        return BundleMemory(batch.pn[b * P:(b + 1) * P], batch.pp[b * P:(b + 1) * P],
                            np.broadcast_to(batch.ro[b], (R, 3)), batch.rd[b * R:(b + 1) * R],
                            batch.enable[b].copy(), keep_all=bool(batch.keep_all[b]))

    def _convert(self, out, counters) -> RunResult:
        from ...fp import model as fpm

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
        from ...model.intersection import run_runs

        return run_runs(config, self.scene_memory, runs)

    def stream(self, batch, runs):
        runs = list(runs)
        if not runs:
            return []
        cfg = self.config(batch.rows, batch.cols)
        results = self._run_runs(cfg, [(self.memory(batch, b), np.asarray(ids, np.int64))
                                       for b, ids in runs])
        return [self._convert(stream, counters) for stream, counters in results]


def _check_reduce(fmt, mode):
    """Raise ``ValueError`` (one line) unless a backend can render through the on-chip
    reduction in ``fmt`` and ``mode`` (paper or certified)."""
    from ...model.reduction import check_reduce_format

    if mode == "conservative":
        raise ValueError(f"the on-chip reduction has no {mode} mode (its hits must reach the "
                         f"host to be resolved): use --mode paper or certified, or no "
                         f"--reduce")
    check_reduce_format(fmt)
