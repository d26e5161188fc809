"""What the ``model`` and ``rtl`` backends share: the intersection unit's host side.

:class:`UnitBackend` writes the unit's memories in a format (Triangle Memory from
:func:`raplas_hdl.model.triangles.make_triangles`, the Sphere Memory with the radius
inflation of :mod:`raplas_hdl.host.culling`), encodes the batches' Plane Memory and Ray
Memory, culls the hierarchy with the model's arithmetic, and hands the unit's runs to
:meth:`UnitBackend.run_runs`, which the model (:mod:`.model`) and the simulated Verilog
(:mod:`.rtl`) implement.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...engine.kernels import cull_model, model_args, trace_model
from ...engine.passes import Arithmetic, BundleBatch, result_beats
from ...fp import model as fpm
from ...fp.format import FP24, FPFormat, check_format
from ...model.bundles import bundle_geometry, encode_bundle_arrays
from ...model.certified import certified_constants, certified_domain
from ...model.config import UnitConfig
from ...model.conservative import margin_constants, margin_table
from ...model.memory_image import BundleMemory, SceneMemory
from ...model.reduction import inf_pattern
from ...model.triangles import make_triangles
from ..culling import CullingBudget, encode_spheres, slack_arrays
from ..modes import get_mode
from ..spheres import unit_margin
from .base import COUNTERS, Backend, RunResult

__all__ = ["UnitBackend"]


class UnitBackend(Backend):
    """The intersection unit's host side (module docstring); a subclass runs the unit.

    Parameters
    ----------
    fmt : FPFormat
        Arithmetic format and rounding.
    mode : str or RenderMode
        A render mode (:func:`raplas_hdl.host.modes.get_mode`): ``"paper"``,
        ``"conservative"``, ``"certified"`` or a registered one; it names the ray-triangle
        unit the backend runs.
    testers : int or None
        Plane-sphere testers (only changes the RTL's timing, not the results).
    margin_scale : int
        Scale of the conservative margin.
    reduce : bool
        Through the unit built with the on-chip reduction (paper or certified).

    Raises
    ------
    ValueError
        For a format, mode or reduction the unit does not have (one line).
    """

    #: The certified pass's pair kernel when not :func:`~raplas_hdl.model.certified.
    #: block_pairs` (None); the certified mode's warm-up sets it for one pass.
    certified_unit = None

    def __init__(self, fmt: FPFormat = FP24, mode: str = "conservative", testers=None,
                 margin_scale: int = 1, reduce: bool = False):
        check_format(fmt)
        render_mode = get_mode(mode)
        render_mode.check(fmt, reduce)
        self.render_mode = render_mode
        super().__init__()
        self.fmt, self.mode, self.testers = fmt, render_mode.unit_mode, testers
        self.margin_scale = margin_scale
        self.reduce = bool(reduce)
        self._configs = {}

    def describe(self):
        return (f"{self.name} {self.fmt} {self.render_mode.name}"
                + (" reduce" if self.reduce else ""))

    def config(self, rows, cols):
        """The unit configuration for a ``rows`` x ``cols`` bundle (one per size)."""
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

    def arithmetic(self):
        """The model's kernels in the backend's format and unit mode (the certified unit has
        no trace kernel of its own: :func:`raplas_hdl.engine.certified.certified_pass`)."""
        tail = model_args(self.fmt, self.mode)
        if self.mode == "certified":
            return Arithmetic("model", cull_model, None, (certified_constants(self.fmt),),
                              tail[:3], tail)
        mc = (margin_table(margin_constants(self.fmt, self.margin_scale)) if tail[3]
              else np.zeros((3, 5), np.int64))
        return Arithmetic("model", cull_model, trace_model, (mc,), tail[:3], tail)

    def window_runs(self, batch, runs, tmin=0.0, tmax=None, exclude=None, any_hit=False):
        """The runs ``(bundle index, sphere ids)`` of a batch as ``(BundleMemory, ids)`` whose
        bundles carry the host's window in the unit's format: ``tmin`` rounded up and each
        ray's ``tmax`` rounded down (+infinity stays +infinity), so the unit never accepts
        what the float64 window rejects; ``exclude`` per bundle; ``any_hit``."""
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

    def usable(self, tris):
        """Triangles that :func:`raplas_hdl.model.triangles.make_triangles` keeps (not
        non-finite, degenerate, flushed, or outside the format's domain). The certified
        mode's domain is its own (:func:`raplas_hdl.model.certified.certified_domain`: a
        bound on the coordinates, no minimum edge, its bounds cover flushes)."""
        tris = np.asarray(tris, dtype=np.float64)
        if self.mode == "certified":
            rec = make_triangles(tris, self.fmt, on_bad="skip",
                                 max_coord=certified_domain(self.fmt))
        else:
            rec = make_triangles(tris, self.fmt, on_bad="skip", check_domain=True)
        self._records = (tris, rec)
        ok = np.zeros(len(tris), bool)
        ok[rec.ids] = True
        return ok, dict(rec.skipped)

    def sphere_margin(self, tris, o_max):
        return unit_margin(tris, self.fmt, o_max, self.mode)

    def load(self, tris, tree, bound):
        rep = super().load(tris, tree, bound)
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
        P, R = batch.n_planes, batch.n_rays
        return BundleMemory(batch.pn[b * P:(b + 1) * P], batch.pp[b * P:(b + 1) * P],
                            np.broadcast_to(batch.ro[b], (R, 3)), batch.rd[b * R:(b + 1) * R],
                            batch.enable[b].copy(), keep_all=bool(batch.keep_all[b]))

    def _convert(self, out, counters) -> RunResult:
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

    def _convert_all(self, results) -> list[RunResult]:
        """:meth:`_convert` of every ``(stream, counters)`` at once: the beats of all runs
        decoded in one pass, then a view per run (a run without pairs sends one empty beat
        and nothing else)."""
        if not results:
            return []
        beats = np.concatenate([stream for stream, _ in results])
        empty = beats["empty"].astype(bool)
        sizes = np.array([stream.size for stream, _ in results], np.int64)
        starts = np.cumsum(sizes) - sizes
        first_empty = np.ones(sizes.size, bool)
        first_empty[sizes > 0] = empty[starts[sizes > 0]]
        kept = np.where(first_empty, 0, sizes)
        if int(kept.sum()) != int((~empty).sum()):
            raise ValueError("an empty result beat in a run that issued pairs")
        whole = self._convert(beats[~empty], None)
        ends = np.cumsum(kept).tolist()
        out = []
        for (stream, counters), n, hi in zip(results, kept.tolist(), ends):
            if n == 0:
                out.append(RunResult.empty(counters))
                continue
            cut = slice(hi - n, hi)
            out.append(RunResult(whole.ray_id[cut], whole.tri_id[cut], whole.hit[cut],
                                 whole.t[cut], whole.u[cut], whole.v[cut], whole.flags[cut],
                                 counters, None if whole.outcome is None
                                 else whole.outcome[cut]))
        return out

    def run_runs(self, config, runs, overlap: bool = False):
        """Runs ``(BundleMemory, sphere ids)`` of one unit configuration through the unit:
        ``(stream, counters)`` per run, as :func:`raplas_hdl.model.intersection.run_runs`
        gives them. ``overlap``: the unit may take a run's command while the run before it
        goes, as the hardware's host would; the streams are the same, but a run's counters
        are then not observable on their own: a backend may give each group of overlapped
        runs' totals on the group's last run and zeros on the others (the model's are per
        run either way). :meth:`stream` overlaps, :meth:`answers` does not (it counts the
        result beats of each run from its counters)."""
        raise NotImplementedError

    def answers(self, batch: BundleBatch, runs, tmin=0.0, tmax=None, exclude=None,
                any_hit=False):
        """The runs ``(bundle index, sphere ids)`` of a batch through the unit built with the
        on-chip reduction, each bundle carrying the host's window (:meth:`window_runs`):
        ``(counters (U, 8), ANSWER beats per run)``, counted in :attr:`beats`."""
        counters = np.zeros((len(runs), len(COUNTERS)), np.int64)
        if not runs:
            return counters, []
        cfg = self.config(batch.rows, batch.cols)
        results = self.run_runs(cfg, self.window_runs(batch, runs, tmin, tmax, exclude,
                                                      any_hit))
        counters[:] = [[c.get(n, 0) for n in COUNTERS] for _, c in results]
        answers = [a for a, _ in results]
        self.beats["result"] += result_beats(counters)
        self.beats["answer"] += sum(len(a) for a in answers)
        return counters, answers

    def stream(self, batch, runs):
        runs = list(runs)
        if not runs:
            return []
        cfg = self.config(batch.rows, batch.cols)
        results = self.run_runs(cfg, [(self.memory(batch, b), np.asarray(ids, np.int64))
                                       for b, ids in runs], overlap=True)
        return self._convert_all(results)

