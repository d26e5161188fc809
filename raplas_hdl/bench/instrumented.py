"""The model backend of the sweep: a render's runs counted, budgeted and sampled.

:class:`SweepBackend` is the model backend that loads out-of-domain triangles too, counts the
unit's runs, spheres and pairs per bundle size (the device figures), stops a render whose
pairs go over its budget (:class:`PairBudgetExceeded`) and keeps a uniform sample of whole
runs (:class:`RunSampler`) for the per-pair errors after the render
(:func:`raplas_hdl.bench.metrics.pair_errors`).
"""

from __future__ import annotations

import numpy as np

from ..engine.passes import BundleBatch
from ..fp import FPFormat
from ..host.backends import COUNTERS, ModelBackend
from ..model.conservative import domain
from ..model.plane_sphere import n_passes
from ..model.triangles import make_triangles
from . import cost as dev
from .plan import DEFAULT_PAIR_SAMPLE

__all__ = ["MIN_SLICE_PAIRS", "PairBudgetExceeded", "RunSampler", "SweepBackend",
           "out_of_domain"]

#: Smallest slice of a pass (upper bound of its pairs) between two checks of the budget.
MIN_SLICE_PAIRS = 1 << 20

#: Columns of the unit's counters (per run) that the sweep reads.
_SPHERES, _PAIRS = COUNTERS.index("spheres"), COUNTERS.index("pairs_issued")


class PairBudgetExceeded(RuntimeError):
    """A render issued more pairs than its budget (the sweep's backend stops it)."""

    def __init__(self, pairs: int, budget: int):
        super().__init__(f"{pairs:,} pairs issued, over the budget of {budget:,}")
        self.pairs, self.budget = pairs, budget


def _sub_batch(batch: BundleBatch, bs: np.ndarray) -> BundleBatch:
    """Bundles ``bs`` of a batch as a batch of their own, enable bits copied (the host
    clears them between early-out rounds) and the float64 rays kept (the original origins
    when the batch's geometry has them, as the sweep's backend records them)."""
    P, R = batch.n_planes, batch.n_rays
    pi = (bs[:, None] * P + np.arange(P)).ravel()
    ri = (bs[:, None] * R + np.arange(R)).ravel()
    g = batch.geometry
    return BundleBatch(batch.rows, batch.cols, batch.pn[pi], batch.pp[pi], batch.ro[bs],
                       batch.rd[ri], batch.enable[bs].copy(), batch.keep_all[bs].copy(),
                       batch.origin[bs], batch.directions[bs],
                       {"origins": (g["origins"] if "origins" in g else batch.origin)[bs],
                        "directions": g["directions"][bs]})


class RunSampler:
    """A uniform sample of whole runs of the unit, at most ``max_pairs`` pairs.

    :meth:`add` takes the runs of a traced pass with their counters; each run is kept with
    probability ``rate`` (1 at first), with its bundle as a batch of its own
    (:func:`_sub_batch`: enable bits as they were when the runs went). Whenever the sample
    holds more than ``max_pairs`` pairs the rate halves and the runs whose random key is
    over it are dropped: the sample stays a Bernoulli sample of the runs at the final rate.
    :meth:`streams` gives the sampled runs' pair streams after the render.
    """

    def __init__(self, max_pairs: int = DEFAULT_PAIR_SAMPLE, seed: int = 0):
        self.max_pairs = int(max_pairs)
        self.rate = 1.0
        self.records = []
        self._rng = np.random.default_rng(seed)

    @property
    def pairs(self) -> int:
        return int(sum(int(r["n"].sum()) for r in self.records))

    def add(self, batch, run_b, run_start, run_sph, counters):
        keys = self._rng.random(run_b.size)
        sel = np.flatnonzero(keys < self.rate)
        if sel.size == 0:
            return
        self.records.append({
            "batch": _sub_batch(batch, run_b[sel]), "k": np.arange(sel.size),
            "ids": [run_sph[run_start[u]:run_start[u + 1]].copy() for u in sel],
            "key": keys[sel], "n": counters[sel, _PAIRS].copy()})
        while self.pairs > self.max_pairs and self.rate > 1e-12:
            self.rate /= 2
            for rec in self.records:
                keep = rec["key"] < self.rate
                rec["ids"] = [x for x, k in zip(rec["ids"], keep) if k]
                for name in ("k", "key", "n"):
                    rec[name] = rec[name][keep]
            self.records = [r for r in self.records if r["k"].size]

    def streams(self, backend):
        """``(sub-batch, bundle index in it, pairs the trace counted, RunResult)`` of every
        sampled run, through ``backend.stream``."""
        for rec in self.records:
            sub = rec["batch"]
            res = backend.stream(sub, [(int(k), ids) for k, ids in zip(rec["k"], rec["ids"])])
            for k, n, r in zip(rec["k"], rec["n"], res):
                yield sub, int(k), int(n), r


class SweepBackend(ModelBackend):
    """The model backend of the sweep.

    - loads out-of-domain triangles too (:meth:`usable`);
    - counts, per bundle size, the runs, spheres and pairs of the unit's runs (the device
      figures; the warm-up pass is left out);
    - stops the render when its pairs go over ``pair_budget`` (:class:`PairBudgetExceeded`;
      the runs of a pass are traced in :meth:`slices` so that it stops near the budget);
    - records a uniform sample of whole runs (:class:`RunSampler`, at most ``sample_pairs``
      pairs) for :func:`~raplas_hdl.bench.metrics.pair_errors` after the render.
    """

    def __init__(self, fmt, mode, *, pair_budget=None, sample_pairs=DEFAULT_PAIR_SAMPLE,
                 seed=0, testers=dev.DEVICE_TESTERS):
        super().__init__(fmt, mode)
        self.out_of_domain = None
        self.pair_budget = pair_budget
        self.device_testers = testers
        self.passes = {}
        self.pairs_issued = 0
        self.sampler = RunSampler(sample_pairs, seed)
        self._warming = False
        self.on_slice.append(self._count_slice)
        self.on_pass.append(self._sample_pass)

    def usable(self, tris):
        tris = np.asarray(tris, dtype=np.float64)
        rec = make_triangles(tris, self.fmt, on_bad="skip", check_domain=False)
        self._records = (tris, rec)
        ok = np.zeros(len(tris), bool)
        ok[rec.ids] = True
        self.out_of_domain = out_of_domain(tris, self.fmt)
        return ok, dict(rec.skipped)

    def batch(self, origins, centres, col_axes, row_axes, rows, cols, enable=None):
        out = super().batch(origins, centres, col_axes, row_axes, rows, cols, enable)
        out.geometry["origins"] = np.asarray(origins, np.float64).reshape(-1, 3)
        return out

    def warm_pass(self, *args, **kwargs):
        self._warming = True
        try:
            return super().warm_pass(*args, **kwargs)
        finally:
            self._warming = False

    def slices(self, batch, run_b, run_start, run_sph):
        """With a budget, slices of about ``step`` pairs (upper bound: every ray against every
        triangle of the run's spheres) between two checks of the budget."""
        U = len(run_b)
        if self._warming or self.pair_budget is None or U == 0:
            return [0, U]
        run_start = np.asarray(run_start, np.int64)
        cs = np.concatenate([[0], np.cumsum(self.scene.tcount[run_sph])])
        ub = (cs[run_start[1:]] - cs[run_start[:-1]]) * batch.n_rays
        step = max(MIN_SLICE_PAIRS, int(self.pair_budget) // 8)
        sid = (np.cumsum(ub) - ub) // step
        return [0, *(np.flatnonzero(np.diff(sid)) + 1).tolist(), U]

    def _count_slice(self, batch, run_b, run_start, run_sph, c):
        """A slice's runs counted (not the warm-up's); over the budget, the render stops."""
        if self._warming or c.shape[0] == 0:
            return
        self._account(batch, c)
        if self.pair_budget is not None and self.pairs_issued > self.pair_budget:
            raise PairBudgetExceeded(self.pairs_issued, int(self.pair_budget))

    def _sample_pass(self, batch, run_b, run_start, run_sph, counters):
        """A whole pass's runs offered to the sampler (not the warm-up's)."""
        if self._warming or len(run_b) == 0:
            return
        self.sampler.add(batch, np.asarray(run_b, np.int64), np.asarray(run_start, np.int64),
                         np.asarray(run_sph, np.int64), counters)

    def _account(self, batch, c):
        rows, cols = batch.rows, batch.cols
        g = n_passes(rows, cols, self.device_testers)
        p = self.passes.setdefault((rows, cols), {
            "rows": rows, "cols": cols, "testers": self.device_testers, "passes": g,
            "runs": 0, "spheres": 0, "pairs": 0, "empty_runs": 0, "overlap_core": 0})
        spheres, pairs = c[:, _SPHERES], c[:, _PAIRS]
        p["runs"] += int(c.shape[0])
        p["spheres"] += int(spheres.sum())
        p["pairs"] += int(pairs.sum())
        p["empty_runs"] += int(np.count_nonzero(pairs == 0))
        p["overlap_core"] += int(np.maximum(spheres * g, pairs).sum())
        self.pairs_issued += int(pairs.sum())

    def device_passes(self, scale: float = 1.0) -> list[dict]:
        """The per-bundle-size counters (scaled by ``scale``, rounded)."""
        out = []
        for p in self.passes.values():
            q = dict(p)
            if scale != 1.0:
                for k in ("runs", "spheres", "pairs", "empty_runs", "overlap_core"):
                    q[k] = int(round(q[k] * scale))
            out.append(q)
        return out


def out_of_domain(tris: np.ndarray, fmt: FPFormat) -> np.ndarray:
    """Per triangle: a coordinate beyond the domain or an edge below its minimum (the test of
    :func:`raplas_hdl.model.triangles.make_triangles` with ``check_domain``)."""
    dom = domain(fmt)
    safe = np.where(np.isfinite(tris), tris, 0.0)
    far = (np.abs(safe) > dom.max_coord).any(axis=(1, 2))
    edges = np.stack([np.linalg.norm(safe[:, a] - safe[:, b], axis=1)
                      for a, b in ((1, 0), (2, 0), (2, 1))], axis=1)
    return far | (edges < dom.min_edge).any(axis=1)
