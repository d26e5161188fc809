"""The benchmark sweep: which points run, and what is measured at each.

Axes: formats (FP16, FP20, FP24, FP32 and any extra), roundings (rtz, rne, chop), ray-triangle
modes (paper, conservative), scenes (the procedural ones, and the meshes shipped with the
package, :data:`raplas_hdl.host.meshes.MESH_DIR`), bundle sizes, backends (``float64``,
``model``; ``rtl`` on one tiny point on request). The full product is too large for one
machine, so the points form three grids:

``main``     every format x rounding x mode on every procedural scene at the main bundle
             size (the grid of the Pareto fronts);
``meshes``   every format x mode on every mesh file, first rounding, main bundle size (the
             conservative mode at FP16 and FP20 on a 70k-triangle mesh issues nearly the
             brute-force pairs: such points come out *capped*, below);
``bundles``  every format on every procedural scene at the other bundle sizes, first rounding,
             first mode;

plus a ``float64`` reference point per scene, bundle size and bound, an ``rtl`` point when
asked (a 24-triangle soup at 16x16, no shadows, against the model: slow), and with
``probe_cap`` a ``cap`` point (the first main point under a tiny cap, which must come out
capped: ``--quick`` has one).

Each scene is normalised into its format's domain (:func:`domain_bound`: the largest power
of two inside :func:`raplas_hdl.model.conservative.domain`, at most :data:`BOUND_CAP`); the
float64 reference is rendered at the same bound. The model backend of the sweep loads every
triangle the record builder accepts, also those outside the domain (the host's
``check_domain`` drop would hide the error the format makes there); such triangles are
counted and every pair with one of them is an *out-of-domain pair*, left out of the t errors.

**Cap.** A point may issue at most ``max_pairs`` pairs. When the brute-force bound of the
render (every ray against every triangle) is above it, a pre-pass renders the point at
1/:data:`PREPASS_DIVISOR` of the image side under the cap scaled down by the pixel ratio;
its pairs scaled up by the pixel ratio are the point's estimate. A point whose estimate is
over the cap (or whose pre-pass, or render, goes over its budget: the sweep's backend counts
the pairs as the unit's runs go and stops the render there) is not rendered to the end: it
is reported with ``capped`` set, its reason, and the figures of the pre-pass scaled up
(estimates, or lower bounds when a budget stopped it).

Per point (see :data:`MODEL_METRICS`): wall and CPU time of the render and per stage,
throughput (rays per second over the whole render, pairs per second over the unit's stages),
the device figures (:mod:`.cost`: the cycles of the device unit for the frame from the unit's
counters, the units that fit on one XC4VSX35, the frame time at the board clock, the result
link's traffic: one ``RESULT`` beat per issued pair), and errors:

- against float64, per pair: the sweep's backend records a uniform sample of the unit's runs
  as the render traces them (whole runs, at most ``pair_sample`` pairs: the sampling rate
  halves whenever the sample outgrows it); after the render (outside the timings) it streams
  those runs' pairs (:meth:`~raplas_hdl.host.backends.Backend.stream`) and evaluates each in
  float64 on the original geometry (:func:`raplas_hdl.host.exact.float64_intersect`);
  median and 99th percentile of ``|t - t64| / |t64|`` over the in-domain pairs both hit, and
  the in-domain pairs whose hit bit differs (counts scaled from the sample to the issued
  pairs);
- against float64, per pixel: PSNR of the 8-bit images, fraction of pixels whose nearest
  triangle differs (all pixels, and pixels whose triangles are all in the domain);
- against R (:mod:`raplas_hdl.verify.stress`): false hits, false misses, edge leaks and the
  relative error of t on the seeded stress families, computed once per format, rounding and
  mode (R is exact and slow) and attached to every point of that configuration.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from ..engine.passes import BundleBatch
from ..fp import ROUNDINGS, FPFormat, parse_format
from ..host.backends import COUNTERS, BackendUnavailable, ModelBackend, make_backend
from ..host.exact import float64_intersect
from ..host.render import RenderSettings, compare, render
from ..host.meshes import MESH_DIR, MESH_SUFFIXES
from ..host.scenes import SCENES, get_scene
from ..model.modes import MODES
from ..host.triangles import make_triangles
from ..model.conservative import domain
from ..model.plane_sphere import n_passes
from ..model.records import RESULT
from . import cost as dev

__all__ = ["BOUND_CAP", "MODEL_METRICS", "REFERENCE_METRICS", "CAPPED_METRICS", "MODES",
           "BenchSpec", "PairBudgetExceeded", "RunSampler", "quick_spec", "full_spec",
           "domain_bound",
           "find_meshes", "plan", "stress_metrics", "run_sweep", "missing_metrics",
           "device_figures", "DEFAULT_MESH_DIR", "DEFAULT_MAX_PAIRS", "DEFAULT_PAIR_SAMPLE",
           "PREPASS_DIVISOR", "RUN_KEYS", "results_of"]

#: Largest normalisation bound used (beyond it only the host's float64 shading changes).
BOUND_CAP = 256.0
#: The meshes shipped with the package.
DEFAULT_MESH_DIR = Path(MESH_DIR)
#: Pairs a point may issue (2 % of the brute-force pairs of a 70k-triangle mesh at 256x256
#: with 3x3 shadows; 1-15 minutes of the model on one core, by format and mode).
DEFAULT_MAX_PAIRS = 500_000_000
#: Pairs of the per-pair error sample of a point.
DEFAULT_PAIR_SAMPLE = 200_000
#: The pre-pass renders 1/PREPASS_DIVISOR of the image side.
PREPASS_DIVISOR = 4
#: Smallest slice of a pass (upper bound of its pairs) between two checks of the budget.
MIN_SLICE_PAIRS = 1 << 20

#: Columns of the unit's counters (per run) that the sweep reads.
_SPHERES, _PAIRS = COUNTERS.index("spheres"), COUNTERS.index("pairs_issued")

STAGES = ("spheres", "load", "compile", "primary cull", "primary unit", "shading",
          "shadow cull", "shadow unit", "image")

#: Device and link figures of a point.
DEVICE_METRICS = ("device_cycles", "device_cycles_overlap", "device_units", "device_frame_s",
                  "device_fps", "link_beat_bits", "link_bits", "link_bits_per_s")
#: Metrics every model (or rtl) point must have (none may be None or NaN).
MODEL_METRICS = (
    "t_total", "cpu_total", *(f"t_{s.replace(' ', '_')}" for s in STAGES), "rays",
    "pairs_issued", "rays_per_s", "pairs_per_s",
    "psnr", "tri_differs", "tri_differs_in_domain", "hit_differs",
    "t_rel_median", "t_rel_p99", "t_pairs", "pair_hit_differs", "pairs_out_of_domain",
    "pairs_out_of_domain_frac", "pairs_sampled", "tris_out_of_domain", "unguaranteed_bundles",
    "overflow", "underflow", "invalid",
    "r_pairs", "r_in_domain", "r_false_hits", "r_false_misses", "r_edge_rays", "r_leaks",
    "r_t_rel_median", "r_t_rel_p99",
    "hw_dsp48", "hw_luts", "hw_ffs", "hw_slices", "hw_cost",
    *DEVICE_METRICS, "max_pairs", "capped",
)
#: Metrics a capped point must have (it was not rendered to the end).
CAPPED_METRICS = ("t_total", "cpu_total", "pairs_issued", "max_pairs", "capped",
                  "capped_reason", "r_pairs", "r_false_hits", "r_false_misses", "r_leaks",
                  "hw_dsp48", "hw_slices", "hw_cost", *DEVICE_METRICS)
#: Metrics of a float64 reference point.
REFERENCE_METRICS = ("t_total", "cpu_total", *(f"t_{s.replace(' ', '_')}" for s in STAGES),
                     "rays", "pairs_issued", "rays_per_s", "pairs_per_s")


@dataclass
class BenchSpec:
    """What one ``raplas-hdl bench`` run sweeps.

    Attributes
    ----------
    formats : list of str
        Format names without rounding (``FP16``, ``e6m17``...).
    roundings, modes : list of str
    scenes : list of str
        Procedural scene names.
    mesh_dir : str or None
        Directory of mesh files (None: no meshes).
    bundles : list of (int, int)
        Bundle sizes; the first is the main one.
    size, mesh_size : (int, int)
        Image size of procedural and mesh scenes.
    shadow : (int, int)
        Light lattice of shadow bundles (0, 0: no shadows).
    rtl : str or None
        Simulator for the tiny rtl point (None: none).
    per_family, seed : int
        Stress families for the R metrics.
    repeats : int
        Renders per point; the timings are the fastest run's.
    max_pairs : int
        Pairs a point may issue (the cap, module docstring).
    probe_cap : int or None
        Add a ``cap`` point: the first main point under this cap (it must come out capped).
    pair_sample : int
        Pairs of the per-pair error sample of a point.
    threads : int
        Threads of the compiled passes (1: the timings are per core).
    quick : bool
    """

    formats: list = field(default_factory=lambda: ["FP16", "FP20", "FP24", "FP32"])
    roundings: list = field(default_factory=lambda: list(ROUNDINGS))
    modes: list = field(default_factory=lambda: list(MODES))
    scenes: list = field(default_factory=lambda: list(SCENES))
    mesh_dir: str | None = str(DEFAULT_MESH_DIR)
    bundles: list = field(default_factory=lambda: [(8, 8), (4, 4), (16, 16)])
    size: tuple = (128, 128)
    mesh_size: tuple = (256, 256)
    shadow: tuple = (3, 3)
    rtl: str | None = None
    per_family: int = 2000
    seed: int = 0
    repeats: int = 1
    max_pairs: int = DEFAULT_MAX_PAIRS
    probe_cap: int | None = None
    pair_sample: int = DEFAULT_PAIR_SAMPLE
    threads: int = 1
    quick: bool = False

    def __post_init__(self):
        for f in self.formats:
            parse_format(f)
        for r in self.roundings:
            if r not in ROUNDINGS:
                raise ValueError(f"unknown rounding {r!r}: use {', '.join(ROUNDINGS)}")
        for m in self.modes:
            if m not in MODES:
                raise ValueError(f"unknown mode {m!r}: use {', '.join(MODES)}")
        for s in self.scenes:
            if s not in SCENES:
                raise ValueError(f"unknown procedural scene {s!r}: use {', '.join(SCENES)}")
        if not (self.formats and self.roundings and self.modes and self.bundles):
            raise ValueError("formats, roundings, modes and bundles must not be empty")
        if self.repeats < 1 or self.per_family < 1:
            raise ValueError("repeats and per_family must be at least 1")
        if self.max_pairs < 1 or self.pair_sample < 1 or self.threads < 1:
            raise ValueError("max_pairs, pair_sample and threads must be at least 1")
        if self.probe_cap is not None and self.probe_cap < 1:
            raise ValueError("probe_cap must be at least 1")


def quick_spec(**overrides) -> BenchSpec:
    """``--quick``: FP16, FP24, FP32; rtz; paper; cornell and spheres; 8x8; 32x32 with 2x2
    shadows; no meshes; a ``cap`` point under a cap of 1000 pairs."""
    kw = dict(formats=["FP16", "FP24", "FP32"], roundings=["rtz"], modes=["paper"],
              scenes=["cornell", "spheres"], mesh_dir=None, bundles=[(8, 8)], size=(32, 32),
              mesh_size=(32, 32), shadow=(2, 2), per_family=300, probe_cap=1000,
              quick=True)
    kw.update(overrides)
    return BenchSpec(**kw)


def full_spec(**overrides) -> BenchSpec:
    """The default campaign (see :class:`BenchSpec` defaults)."""
    return BenchSpec(**overrides)


def domain_bound(fmt: FPFormat) -> float:
    """Normalisation bound of a scene for ``fmt``: ``min(2**P, BOUND_CAP)``."""
    return float(min(domain(fmt).max_coord, BOUND_CAP))


def find_meshes(mesh_dir) -> tuple[list[str], str | None]:
    """Mesh files of ``mesh_dir`` (sorted) and a note when there are none."""
    if mesh_dir is None:
        return [], "meshes not requested"
    p = Path(mesh_dir)
    if not p.is_dir():
        return [], f"mesh directory {p} not found: mesh scenes skipped"
    files = sorted(str(f) for f in p.iterdir() if f.suffix.lower() in MESH_SUFFIXES)
    return files, (None if files else f"no mesh files in {p}: mesh scenes skipped")


def _fmt(name: str, rounding: str) -> FPFormat:
    return parse_format(name, rounding) if "/" not in name else parse_format(name)


def plan(spec: BenchSpec, meshes) -> list[dict]:
    """The model points of the grids (see the module docstring), in run order."""
    main = spec.bundles[0]
    pts = []

    def add(grid, f, r, m, scene, b, cap=spec.max_pairs):
        pts.append({"grid": grid, "format": f, "rounding": r, "mode": m, "scene": scene,
                    "bundle": b, "max_pairs": int(cap)})

    for f in spec.formats:
        for r in spec.roundings:
            for m in spec.modes:
                for s in spec.scenes:
                    add("main", f, r, m, s, main)
    for f in spec.formats:
        for m in spec.modes:
            for s in meshes:
                add("meshes", f, spec.roundings[0], m, s, main)
    for b in spec.bundles[1:]:
        for f in spec.formats:
            for s in spec.scenes:
                add("bundles", f, spec.roundings[0], spec.modes[0], s, b)
    if spec.probe_cap is not None:
        first = spec.scenes[0] if spec.scenes else (meshes[0] if meshes else None)
        if first is not None:
            add("cap", spec.formats[0], spec.roundings[0], spec.modes[0], first, main,
                spec.probe_cap)
    return pts


# -- the model backend of the sweep --------------------------------------------------------

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


class _SweepModel(ModelBackend):
    """The model backend of the sweep.

    - loads out-of-domain triangles too (:meth:`usable`);
    - counts, per bundle size, the runs, spheres and pairs of the unit's runs (the device
      figures; the warm-up pass is left out);
    - stops the render when its pairs go over ``pair_budget`` (:class:`PairBudgetExceeded`;
      the runs of a pass are traced in slices so that it stops near the budget);
    - records a uniform sample of whole runs (:class:`RunSampler`, at most ``sample_pairs``
      pairs) for :func:`_pair_errors` after the render.
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

    def usable(self, tris):
        tris = np.asarray(tris, dtype=np.float64)
        rec = make_triangles(tris, self.fmt, on_bad="skip", check_domain=False)
        self._records = (tris, rec)
        ok = np.zeros(len(tris), bool)
        ok[rec.ids] = True
        self.out_of_domain = _out_of_domain(tris, self.fmt)
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

    def trace(self, batch, run_b, run_start, run_sph, best_t, best_tri, tmin=0.0, tmax=None,
              exclude=None, any_hit=False):
        if self._warming:
            return super().trace(batch, run_b, run_start, run_sph, best_t, best_tri, tmin,
                                 tmax, exclude, any_hit)
        run_b = np.ascontiguousarray(run_b, np.int64)
        run_start = np.ascontiguousarray(run_start, np.int64)
        run_sph = np.ascontiguousarray(run_sph, np.int64)
        U = run_b.size
        counters = np.zeros((U, len(COUNTERS)), np.int64)
        if U == 0:
            return counters
        cut = [0, U]
        if self.pair_budget is not None:
            # slices of about ``step`` pairs (upper bound: every ray against every triangle
            # of the run's spheres) between two checks of the budget
            cs = np.concatenate([[0], np.cumsum(self.scene.tcount[run_sph])])
            ub = (cs[run_start[1:]] - cs[run_start[:-1]]) * batch.n_rays
            step = max(MIN_SLICE_PAIRS, int(self.pair_budget) // 8)
            sid = (np.cumsum(ub) - ub) // step
            cut = [0, *(np.flatnonzero(np.diff(sid)) + 1).tolist(), U]
        for lo, hi in zip(cut[:-1], cut[1:]):
            rs = run_start[lo:hi + 1]
            c = super().trace(batch, run_b[lo:hi], rs - rs[0], run_sph[rs[0]:rs[-1]], best_t,
                              best_tri, tmin, tmax, exclude, any_hit)
            counters[lo:hi] = c
            self._account(batch, c)
            if self.pair_budget is not None and self.pairs_issued > self.pair_budget:
                raise PairBudgetExceeded(self.pairs_issued, int(self.pair_budget))
        self.sampler.add(batch, run_b, run_start, run_sph, counters)
        return counters

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


def _out_of_domain(tris: np.ndarray, fmt: FPFormat) -> np.ndarray:
    """Per triangle: a coordinate beyond the domain or an edge below its minimum (the test of
    :func:`raplas_hdl.host.triangles.make_triangles` with ``check_domain``)."""
    dom = domain(fmt)
    safe = np.where(np.isfinite(tris), tris, 0.0)
    far = (np.abs(safe) > dom.max_coord).any(axis=(1, 2))
    edges = np.stack([np.linalg.norm(safe[:, a] - safe[:, b], axis=1)
                      for a, b in ((1, 0), (2, 0), (2, 1))], axis=1)
    return far | (edges < dom.min_edge).any(axis=1)


def _quantiles(rel: np.ndarray) -> tuple[float, float]:
    if rel.size == 0:
        return math.nan, math.nan
    return float(np.median(rel)), float(np.quantile(rel, 0.99))


def _pair_errors(backend: _SweepModel, tris: np.ndarray) -> dict:
    """Errors of the sampled runs' pairs against float64 on the same pairs (original
    geometry); counts scaled from the sample to the pairs the backend issued."""
    ood = backend.out_of_domain
    total = int(backend.pairs_issued)
    ray, tri, hit, t, o, d = [], [], [], [], [], []
    mismatch = 0
    for sub, k, n, r in backend.sampler.streams(backend):
        mismatch += int(r.ray_id.size != n)
        if not r.ray_id.size:
            continue
        ray.append(r.ray_id)
        tri.append(r.tri_id)
        hit.append(r.hit)
        t.append(r.t)
        o.append(np.broadcast_to(sub.geometry["origins"][k], (r.ray_id.size, 3)))
        d.append(sub.geometry["directions"][k][r.ray_id])
    out = {"pairs_total": total, "pairs_sampled": 0, "pair_sample_frac": 0.0,
           "sample_stream_mismatch": mismatch}
    if not ray:
        out.update(t_rel_median=math.nan, t_rel_p99=math.nan, t_pairs=0, pair_hit_differs=0,
                   pairs_out_of_domain=0, in_domain_pairs=0, pairs_out_of_domain_frac=0.0)
        return out
    tri, hit, t = np.concatenate(tri), np.concatenate(hit), np.concatenate(t)
    o, d = np.concatenate(o), np.concatenate(d)
    tv = tris[tri]
    ref = float64_intersect(o, d, tv[:, 0], tv[:, 1], tv[:, 2])
    ind = ~ood[tri]
    t64 = ref["t"]
    both = ind & hit & ref["hit"] & np.isfinite(t) & np.isfinite(t64) & (t64 != 0)
    rel = np.abs(t[both] - t64[both]) / np.abs(t64[both])
    med, p99 = _quantiles(rel)
    n = int(tri.size)
    scale = total / n if total else 1.0
    out.update(t_rel_median=med, t_rel_p99=p99, t_pairs=int(both.sum()),
               pair_hit_differs=int(round((ind & (hit != ref["hit"])).sum() * scale)),
               pairs_out_of_domain=int(round((~ind).sum() * scale)),
               in_domain_pairs=int(round(ind.sum() * scale)),
               pairs_out_of_domain_frac=float((~ind).mean()),
               pairs_sampled=n, pair_sample_frac=n / total if total else 0.0)
    return out


def _pixel_errors(res, ref, ood) -> dict:
    c = compare(res, ref)
    a, b = res.tri_id, ref.tri_id
    ok_a = (a < 0) | ~ood[a.clip(0)]
    ok_b = (b < 0) | ~ood[b.clip(0)]
    sel = ok_a & ok_b
    return {"psnr": c["psnr"], "max_abs": c["max_abs"], "tri_differs": c["tri_differs"],
            "hit_differs": c["hit_differs"],
            "tri_differs_in_domain": float(np.mean(a[sel] != b[sel])) if sel.any() else math.nan,
            "pixels_in_domain": float(np.mean(sel))}


def _timed_render(scene, make, settings, repeats):
    """The fastest of ``repeats`` renders: ``(backend, result, wall, cpu)``."""
    best = None
    for _ in range(repeats):
        backend = make()
        t0, c0 = time.perf_counter(), time.process_time()
        res = render(scene, backend, settings)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        if best is None or wall < best[2]:
            best = (backend, res, wall, cpu)
    return best


def _run_figures(res, wall, cpu) -> dict:
    st, tm = res.stats, res.timings
    out = {"t_total": wall, "cpu_total": cpu}
    for s in STAGES:
        out[f"t_{s.replace(' ', '_')}"] = float(tm.get(s, 0.0))
    unit_t = tm.get("primary unit", 0.0) + tm.get("shadow unit", 0.0)
    out.update(rays=int(st["rays"]), bundles=int(st["bundles"]),
               pairs_issued=int(st["pairs_issued"]),
               brute_force_pairs=int(st["brute_force_pairs"]),
               pair_fraction=float(st["pair_fraction"]),
               rays_per_s=st["rays"] / wall if wall > 0 else math.nan,
               pairs_per_s=st["pairs_issued"] / unit_t if unit_t > 0 else math.nan,
               hits=int(st["hits"]), triangles=int(st["triangles"]),
               unit_spheres=int(st["unit"].get("spheres", 0)),
               unit_plane_tests=int(st["unit"].get("plane_tests", 0)),
               host_plane_tests=int(st["host_plane_tests"]),
               unguaranteed_bundles=int(st["unguaranteed_bundles"]),
               **{k: int(v) for k, v in st["events"].items()})
    return out


def _link_layout(backend: _SweepModel):
    """The result record bound to the unit configuration of the point's largest bundle."""
    rows, cols = max(backend.passes, key=lambda rc: (rc[0] * rc[1], rc)) if backend.passes \
        else (1, 1)
    return RESULT.bind(backend.config(rows, cols))


def _device_counts(backend: _SweepModel, mode: str, scale: float = 1.0) -> dict:
    """The device figures that do not need the resources: cycles and link bits."""
    passes = backend.device_passes(scale)
    pairs = sum(p["pairs"] for p in passes)
    lay = _link_layout(backend)
    return {"device_passes": passes, "device_runs": sum(p["runs"] for p in passes),
            "device_cycles": dev.device_cycles(passes, mode),
            "device_cycles_overlap": dev.device_cycles(passes, mode, overlap=True),
            "device_pairs": pairs, "link_beat_bits": int(lay.size),
            "link_params": dict(lay.params), "link_bits": int(pairs * lay.size),
            "link_empty_beats": sum(p["empty_runs"] for p in passes)}


def device_figures(point: dict, unit: dict | None, clock_mhz: float) -> dict:
    """Frame time and link rate of a point from its cycles and the device unit (``unit``:
    :func:`raplas_hdl.bench.cost.device_unit`; None or an error: NaN figures)."""
    if not unit or "error" in unit or point.get("device_cycles") is None:
        return {"device_units": math.nan, "device_basis": None, "device_frame_s": math.nan,
                "device_fps": math.nan, "link_bits_per_s": math.nan,
                "device_clock_mhz": clock_mhz}
    units = int(unit["units"])
    hz = clock_mhz * 1e6
    frame = point["device_cycles"] / units / hz if units else math.inf
    fps = 1.0 / frame if frame > 0 and math.isfinite(frame) else 0.0
    return {"device_units": units, "device_basis": unit["basis"], "device_frame_s": frame,
            "device_frame_s_overlap": (point["device_cycles_overlap"] / units / hz
                                       if units else math.inf),
            "device_unit_s": point["device_cycles"] / hz, "device_fps": fps,
            "link_bits_per_s": point["link_bits"] * fps, "device_clock_mhz": clock_mhz}


# -- R: the stress families ----------------------------------------------------------------

def stress_metrics(fmt: FPFormat, modes, per_family: int, seed: int) -> dict:
    """Pooled counts of the model against R on the seeded stress families, per mode.

    Returns
    -------
    dict
        mode -> ``r_pairs``, ``r_in_domain``, ``r_hits``, ``r_false_hits``,
        ``r_false_misses``, ``r_edge_rays``, ``r_leaks``, ``r_t_rel_median``,
        ``r_t_rel_p99`` (in-domain pairs both hit), ``r_seconds``.
    """
    from ..fp.model import decode
    from ..verify import stress
    from ..model.ray_triangle import intersect

    t0 = time.perf_counter()
    cases = stress.generate(fmt, per_family, seed)
    enc = stress.reference(cases, fmt)
    t_ref = time.perf_counter() - t0
    out = {}
    for mode in modes:
        t1 = time.perf_counter()
        pooled = stress.pooled(stress.evaluate(cases, enc, mode))
        k = enc.kept
        res = intersect(enc.o_bits[k], enc.d_bits[k], enc.v0_bits, enc.e1_bits, enc.e2_bits,
                        enc.n_bits, fmt, mode=mode)
        hit = np.zeros(len(cases), bool)
        hit[k] = res["hit"]
        t = np.full(len(cases), np.nan)
        with np.errstate(divide="ignore", invalid="ignore"):
            t[k] = decode(res["t"], fmt) / decode(res["det"], fmt)
        both = (enc.in_domain & hit & enc.r_hit & np.isfinite(t) & np.isfinite(enc.r_t)
                & (enc.r_t != 0))
        med, p99 = _quantiles(np.abs(t[both] - enc.r_t[both]) / np.abs(enc.r_t[both]))
        out[mode] = {"r_pairs": pooled["pairs"], "r_in_domain": int(enc.in_domain.sum()),
                     "r_hits": pooled["r_hits"], "r_false_hits": pooled["false_hits"],
                     "r_false_misses": pooled["false_misses"],
                     "r_edge_rays": pooled["edge_rays"], "r_leaks": pooled["leaks"],
                     "r_t_rel_median": med, "r_t_rel_p99": p99, "r_t_pairs": int(both.sum()),
                     "r_seconds": t_ref + time.perf_counter() - t1}
    return out


# -- the sweep -----------------------------------------------------------------------------

def _label(fmt: FPFormat) -> str:
    return str(fmt).split("/")[0]


def _scene_name(spec: str) -> str:
    return os.path.splitext(os.path.basename(spec))[0] if spec not in SCENES else spec


def missing_metrics(point: dict) -> list[str]:
    """The required metrics of ``point`` that are absent, None or NaN."""
    if point.get("backend") == "float64":
        need = REFERENCE_METRICS
    elif point.get("capped"):
        need = CAPPED_METRICS
    else:
        need = MODEL_METRICS
    bad = []
    for k in need:
        v = point.get(k)
        if v is None or (isinstance(v, float) and math.isnan(v)) or v == "nan":
            bad.append(k)
    return bad


def _measure_point(p, fmt, scene, settings, spec, ref) -> dict:
    """Render one model point under its cap (module docstring) and measure it."""
    cap = int(p["max_pairs"])
    mode = p["mode"]
    W, H = settings.width, settings.height
    rays_max = W * H * (1 + settings.shadow_rows * settings.shadow_cols)
    out = {"max_pairs": cap, "capped": False, "capped_reason": "",
           "brute_force_bound": int(rays_max * scene.n_triangles)}
    pre, pre_ratio, t_pre, c_pre = None, 1.0, 0.0, 0.0

    def model(budget):
        return _SweepModel(fmt, mode, pair_budget=budget, sample_pairs=spec.pair_sample,
                           seed=spec.seed)

    if out["brute_force_bound"] > cap:
        w, h = -(-W // PREPASS_DIVISOR), -(-H // PREPASS_DIVISOR)
        pre_ratio = (W * H) / (w * h)
        pre = model(max(1, int(cap / pre_ratio)))
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            render(scene, pre, replace(settings, width=w, height=h))
            estimate = int(pre.pairs_issued * pre_ratio)
            out.update(pairs_estimate=estimate, prepass_size=f"{w}x{h}")
            if estimate > cap:
                out.update(capped=True, capped_reason=f"pre-pass estimate {estimate:,} pairs "
                                                      f"over the cap")
        except PairBudgetExceeded as exc:
            out.update(capped=True, prepass_size=f"{w}x{h}",
                       capped_reason=f"pre-pass {w}x{h} over its budget of {exc.budget:,} "
                                     f"pairs: lower bounds")
        t_pre, c_pre = time.perf_counter() - t0, time.process_time() - c0
        out.update(prepass_seconds=t_pre)
    res, src, src_scale = None, pre, pre_ratio
    if not out["capped"]:
        made = []

        def make():
            made.append(model(cap))
            return made[-1]

        t0, c0 = time.perf_counter(), time.process_time()
        try:
            backend, res, wall, cpu = _timed_render(scene, make, settings, spec.repeats)
        except PairBudgetExceeded as exc:
            src, src_scale = made[-1], 1.0
            out.update(capped=True, capped_reason=f"render over the cap at {exc.pairs:,} "
                                                  "pairs: lower bounds",
                       t_total=t_pre + time.perf_counter() - t0,
                       cpu_total=c_pre + time.process_time() - c0)
    if res is not None:
        out.update(_run_figures(res, wall, cpu))
        out["tris_out_of_domain"] = int(backend.out_of_domain.sum())
        out.update(_pixel_errors(res, ref, backend.out_of_domain))
        out.update(_pair_errors(backend, scene.triangles))
        out.update(_device_counts(backend, mode))
        return out
    # capped: the pre-pass's figures scaled to the point's size (estimates, or lower bounds
    # when a budget stopped it), or those of the render that went over the cap
    out.setdefault("t_total", t_pre)
    out.setdefault("cpu_total", c_pre)
    if src is not None and src.passes:
        out["figures_from"] = "pre-pass, scaled" if src is pre else "render, up to the cap"
        out.update(_device_counts(src, mode, src_scale))
        out["pairs_issued"] = out["device_pairs"]
        errs = _pair_errors(src, scene.triangles)
        for k in ("pair_hit_differs", "pairs_out_of_domain", "in_domain_pairs"):
            errs[k] = int(round(errs[k] * src_scale))
        out.update({k: v for k, v in errs.items() if k != "pairs_total"})
        out["tris_out_of_domain"] = int(src.out_of_domain.sum())
    else:
        out["figures_from"] = "none"
        out["pairs_issued"] = cap
    return out


def _model_row(p, fmt, settings, bound, spec, fig) -> dict:
    return {"grid": p["grid"], "backend": "model", "format": _label(fmt),
            "rounding": fmt.rounding, "mode": p["mode"], "scene": _scene_name(p["scene"]),
            "bundle": f"{p['bundle'][0]}x{p['bundle'][1]}",
            "size": f"{settings.width}x{settings.height}", "bound": bound,
            "shadow": f"{spec.shadow[0]}x{spec.shadow[1]}", **fig}


def _point_line(k, n, p, fmt, row) -> str:
    head = (f"[{k + 1:3d}/{n}] {p['grid']:7s} {_label(fmt)}/{fmt.rounding:4s} "
            f"{p['mode']:12s} {row['scene']:18s} {row['bundle']:>5s}: ")
    if row["capped"]:
        return head + f"CAPPED ({row['capped_reason']}), {row['t_total']:.2f} s"
    return (head + f"{row['t_total']:6.2f} s (CPU {row['cpu_total']:.2f})  "
            f"{row['pairs_issued'] / 1e6:7.2f} M pairs  device "
            f"{row['device_cycles'] / 1e6:8.2f} M cycles  t_rel "
            f"{row['t_rel_median']:.2e}  pixels {100 * row['tri_differs']:.2f} %  "
            f"PSNR {row['psnr']:.1f}")


#: What this process has warmed (numba compile or cache load, outside the timings).
_WARMED: set = set()


def _ensure_warm(spec: BenchSpec, fmt: FPFormat | None = None, mode: str | None = None):
    key = (tuple(map(tuple, spec.bundles)), tuple(spec.shadow), spec.threads)
    if fmt is None:
        if key not in _WARMED:
            _warm_up(spec)
            _WARMED.add(key)
    elif key + (str(fmt), mode) not in _WARMED:
        _warm_model(fmt, mode, spec)
        _WARMED.add(key + (str(fmt), mode))


def _settings_for(spec: BenchSpec, name, bundle, bound) -> RenderSettings:
    w, h = spec.mesh_size if name not in SCENES else spec.size
    return RenderSettings(w, h, bundle[0], bundle[1], spec.shadow[0], spec.shadow[1],
                          bound=bound, progress=False, threads=spec.threads)


def _run_group(spec: BenchSpec, name: str, bundle, bound: float, points, n_points: int,
               say=None) -> dict:
    """The float64 reference of ``(scene, bundle, bound)`` and the model points that use
    it, in order: one task of the sweep (it runs wherever the executor puts it).

    ``points`` holds ``(k, point)`` with ``k`` the point's index in the plan.

    Returns
    -------
    dict
        ``reference`` (its row, or None when the scene failed), ``error`` (why it failed),
        ``points``: ``(k, row or None, note or None)``, ``lines`` (progress), ``cpu_s``.
    """
    c0 = time.process_time()
    lines = []

    def tell(line):
        lines.append(line)
        if say:
            say(line)

    out = {"reference": None, "error": None, "points": [], "lines": lines}
    _ensure_warm(spec)
    settings = _settings_for(spec, name, bundle, bound)
    try:
        scene = get_scene(name, bound=bound)
        _, ref, wall, cpu = _timed_render(scene, lambda: make_backend("float64"), settings,
                                          spec.repeats)
    except (ValueError, FileNotFoundError) as exc:
        out["error"] = str(exc)
        out["cpu_s"] = time.process_time() - c0
        return out
    out["reference"] = {"grid": "reference", "backend": "float64", "format": "float64",
                        "rounding": "-", "mode": "-", "scene": _scene_name(name),
                        "bundle": f"{bundle[0]}x{bundle[1]}", "size": ref.stats["size"],
                        "bound": bound, **_run_figures(ref, wall, cpu)}
    tell(f"float64      {_scene_name(name):18s} {out['reference']['bundle']:>5s} bound "
         f"{bound:g}: {wall:6.2f} s (CPU {cpu:.2f} s)")
    for k, p in points:
        fmt = _fmt(p["format"], p["rounding"])
        _ensure_warm(spec, fmt, p["mode"])
        try:
            fig = _measure_point(p, fmt, scene, settings, spec, ref)
        except ValueError as exc:
            out["points"].append((k, None, f"point {_label(fmt)}/{fmt.rounding} {p['mode']} "
                                           f"{name} skipped: {exc}"))
            continue
        row = _model_row(p, fmt, settings, bound, spec, fig)
        out["points"].append((k, row, None))
        tell(_point_line(k, n_points, p, fmt, row))
    out["cpu_s"] = time.process_time() - c0
    return out


def _sweep_task(task):
    """A task of the sweep on an executor: ``("stress", spec, f, r)`` or ``("group", spec,
    name, bundle, bound, points, n_points)``."""
    c0 = time.process_time()
    if task[0] == "stress":
        _, spec, f, r = task
        return {"stress": stress_metrics(_fmt(f, r), spec.modes, spec.per_family, spec.seed),
                "cpu_s": time.process_time() - c0}
    return _run_group(*task[1:])


def _stress_line(key, metrics) -> str:
    return f"stress vs R  {key}: " + ", ".join(
        f"{m}: FH {v['r_false_hits']} FM {v['r_false_misses']} leaks {v['r_leaks']}"
        for m, v in metrics.items())


def run_sweep(spec: BenchSpec, progress=print, cost_thread: bool = True,
              executor=None) -> dict:
    """Run every point of ``spec`` and return the results (see :mod:`.report`).

    The hardware costs and synthesis checks (:mod:`.cost`) run in a background thread while
    the renders run (Yosys is a subprocess: on a cold cache it takes the other core).

    The work is cut into tasks: the R metrics of each format and rounding, and each
    ``(scene, bundle size, bound)`` group (its float64 reference, then its model points in
    plan order). Without ``executor`` they run here, one after the other; with one
    (:mod:`raplas_hdl.cluster`: a process pool or a Dask cluster) they run there and this
    process puts the rows back in plan order: the results are the same, only the timings
    differ (and each point's timings are those of the worker that rendered it).

    Returns
    -------
    dict
        ``spec``, ``points`` (one flat dict per point), ``stress`` (R metrics per format,
        rounding and mode), ``costs`` (per format and rounding, with the ``device`` unit),
        ``device`` (the device model's constants), ``synth_checks``, ``notes``, ``rtl`` (or
        None), ``wall_seconds``, ``cpu_seconds`` (this process and the executor's tasks),
        ``started``, ``load_average``, ``executor``.
    """
    from concurrent.futures import ThreadPoolExecutor
    from datetime import datetime, timezone

    from ..fp import FP24

    say = progress or (lambda *_: None)
    t_start, c_start = time.perf_counter(), time.process_time()
    started = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    notes = []
    meshes, note = find_meshes(spec.mesh_dir)
    if note and spec.mesh_dir is not None:
        notes.append(note)
    points = plan(spec, meshes)
    fmts = {(f, r): _fmt(f, r) for f in spec.formats for r in spec.roundings}

    def costs_job():
        out = {}
        for (f, r), fmt in fmts.items():
            key = f"{_label(fmt)}/{r}"
            try:
                out[key] = dev.format_cost(fmt, allow_json=spec.quick)
            except (RuntimeError, LookupError, OSError) as exc:
                out[key] = {"error": str(exc)}
                continue
            try:
                ref = (out[key] if _label(fmt) == "FP24" else
                       dev.format_cost(FP24.with_rounding(r), allow_json=True))
                out[key]["device"] = dev.device_unit(fmt, out[key], fp24_cost=ref)
            except (RuntimeError, LookupError, OSError) as exc:
                out[key]["device"] = {"error": str(exc)}
        checks = dev.synth_checks(spec.roundings[0], full=not spec.quick)
        return out, checks

    pool = ThreadPoolExecutor(max_workers=1)
    fut = pool.submit(costs_job) if cost_thread else None

    # the groups: points sharing a scene, bundle size and bound (so a float64 reference)
    groups = {}
    for k, p in enumerate(points):
        key = (p["scene"], tuple(p["bundle"]), domain_bound(fmts[(p["format"], p["rounding"])]))
        groups.setdefault(key, []).append((k, p))
    stress, done, task_cpu = {}, {}, 0.0
    if executor is None:
        for (f, r), fmt in fmts.items():
            stress[f"{_label(fmt)}/{r}"] = stress_metrics(fmt, spec.modes, spec.per_family,
                                                          spec.seed)
            say(_stress_line(f"{_label(fmt)}/{r}", stress[f"{_label(fmt)}/{r}"]))
        t0 = time.perf_counter()
        _ensure_warm(spec)
        say(f"warm-up (numba compile, excluded from the timings): "
            f"{time.perf_counter() - t0:.1f} s")
        for key, items in groups.items():
            done[key] = _run_group(spec, *key, items, len(points), say=say)
    else:
        if executor.local:      # compile once here: the workers load numba's cache
            _ensure_warm(spec)
        tasks = [("stress", spec, f, r) for f, r in fmts]
        tasks += [("group", spec, *key, items, len(points)) for key, items in groups.items()]
        for task, res in executor.run(_sweep_task, tasks):
            task_cpu += res["cpu_s"]
            if task[0] == "stress":
                k = f"{_label(fmts[task[2:]])}/{task[3]}"
                stress[k] = res["stress"]
                say(_stress_line(k, stress[k]))
            else:
                done[task[2:5]] = res
                for line in res["lines"]:
                    say(line)
        stress = {f"{_label(fmt)}/{r}": stress[f"{_label(fmt)}/{r}"]
                  for (f, r), fmt in fmts.items()}

    # the rows in plan order, a reference before the first point that uses it
    rows, bad_scenes, emitted = [], set(), set()
    by_point = {k: (row, why) for res in done.values() for k, row, why in res["points"]}
    for k, p in enumerate(points):
        fmt = fmts[(p["format"], p["rounding"])]
        key = (p["scene"], tuple(p["bundle"]), domain_bound(fmt))
        if p["scene"] in bad_scenes:
            continue
        res = done[key]
        if res["reference"] is None:
            notes.append(f"scene {p['scene']} skipped: {res['error']}")
            bad_scenes.add(p["scene"])
            continue
        if key not in emitted:
            rows.append(res["reference"])
            emitted.add(key)
        row, why = by_point[k]
        if row is None:
            notes.append(why)
            continue
        row.update(stress[f"{_label(fmt)}/{fmt.rounding}"][p["mode"]])
        rows.append(row)

    rtl = None
    if spec.rtl:
        f_rtl = "FP24" if "FP24" in spec.formats else spec.formats[0]
        rtl = _rtl_point(spec, fmts[(f_rtl, spec.roundings[0])], say)

    costs, checks = {}, {}
    if fut is not None:
        costs, checks = fut.result()
    pool.shutdown()
    clock = dev.CLOCKS_MHZ["board"]
    for row in rows:
        if row["backend"] == "float64":
            continue
        c = costs.get(f"{row['format']}/{row['rounding']}", {})
        row.update(hw_dsp48=c.get("dsp48"), hw_luts=c.get("luts"), hw_ffs=c.get("ffs"),
                   hw_slices=c.get("slices_est"), hw_cost=c.get("device_fraction"))
        row.update(device_figures(row, c.get("device"), clock))
    spec_d = asdict(spec)
    if spec_d["mesh_dir"] is not None:     # results name the project's folder, not a machine's
        spec_d["mesh_dir"] = dev._rel(spec_d["mesh_dir"])
    return {"spec": spec_d, "points": rows, "stress": stress, "costs": costs,
            "device": {"name": "XC4VSX35", "rows": dev.DEVICE_ROWS, "cols": dev.DEVICE_COLS,
                       "testers": dev.DEVICE_TESTERS, "tester_latency": dev.TESTER_LATENCY,
                       "rt_latency": {m: dev.rt_latency(m) for m in MODES},
                       "clocks_mhz": dict(dev.CLOCKS_MHZ), "clock_mhz": clock},
            "synth_checks": checks, "notes": notes, "meshes": [_scene_name(m) for m in meshes],
            "rtl": rtl, "started": started, "wall_seconds": time.perf_counter() - t_start,
            "cpu_seconds": time.process_time() - c_start + task_cpu,
            "load_average": list(os.getloadavg()),
            "executor": "this process" if executor is None else executor.describe()}


#: ``t_*`` keys of a point that are not times.
TIMELESS = ("t_rel_median", "t_rel_p99", "t_pairs")


def _is_timing(key: str) -> bool:
    """Is ``key`` (of a point or a stress metric) a measured time, or a rate from one?"""
    return (key.startswith(("t_", "cpu_")) and key not in TIMELESS) or key in (
        "rays_per_s", "pairs_per_s", "prepass_seconds", "r_seconds")


#: Keys of the results document that describe a run rather than its results.
RUN_KEYS = ("started", "wall_seconds", "cpu_seconds", "load_average", "executor")


def results_of(results: dict) -> dict:
    """The results of :func:`run_sweep` without what describes the run (:data:`RUN_KEYS`)
    and without the measured times of each point and stress metric: the same for two runs of
    one spec, whatever executor ran them (compare their JSON: some metrics may be NaN)."""
    out = {k: v for k, v in results.items() if k not in RUN_KEYS}
    out["points"] = [{k: v for k, v in p.items() if not _is_timing(k)}
                     for p in results["points"]]
    out["stress"] = {f: {m: {k: v for k, v in d.items() if not _is_timing(k)}
                         for m, d in modes.items()} for f, modes in results["stress"].items()}
    return out


_WARM_SCENE = ("cornell", 8.0)


def _warm_settings(rows, cols, spec):
    return RenderSettings(max(16, cols), max(16, rows), rows, cols, spec.shadow[0],
                          spec.shadow[1], bound=_WARM_SCENE[1], progress=False,
                          threads=spec.threads)


def _warm_up(spec: BenchSpec):
    """Render a tiny scene once per bundle size with float64 so that numba's compile (or the
    load of its cache) is not in the first point's timings (the model's kernels: per format,
    rounding and mode, :func:`_warm_model`)."""
    scene = get_scene(_WARM_SCENE[0], bound=_WARM_SCENE[1])
    for rows, cols in spec.bundles:
        render(scene, make_backend("float64"), _warm_settings(rows, cols, spec))


def _warm_model(fmt: FPFormat, mode: str, spec: BenchSpec):
    """A tiny render and pair analysis of the model at ``fmt`` and ``mode``, untimed."""
    scene = get_scene(_WARM_SCENE[0], bound=_WARM_SCENE[1])
    for rows, cols in spec.bundles:
        b = _SweepModel(fmt, mode, sample_pairs=1000)
        render(scene, b, _warm_settings(rows, cols, spec))
        _pair_errors(b, scene.triangles)


def _rtl_point(spec: BenchSpec, fmt: FPFormat, say) -> dict:
    """One tiny rtl render (24-triangle soup, 16x16, 4x4 bundles, no shadows) against the
    model on the same settings."""
    from ..host.scenes import soup_scene

    bound = domain_bound(fmt)
    scene = soup_scene(n=24).normalised(bound)
    st = RenderSettings(16, 16, 4, 4, 0, 0, bound=bound, progress=False)
    mode = spec.modes[0]
    try:
        rtl = make_backend("rtl", fmt, mode=mode, sim=spec.rtl)
    except BackendUnavailable as exc:
        return {"unavailable": str(exc)}
    t0 = time.perf_counter()
    r_rtl = render(scene, rtl, st)
    t_rtl = time.perf_counter() - t0
    t0 = time.perf_counter()
    r_mod = render(scene, make_backend("model", fmt, mode=mode), st)
    t_mod = time.perf_counter() - t0
    out = {"scene": "soup n=24", "size": "16x16", "bundle": "4x4", "shadows": False,
           "format": str(fmt), "mode": mode, "simulator": spec.rtl,
           "rtl_seconds": t_rtl, "model_seconds": t_mod, "rays": int(r_rtl.stats["rays"]),
           "pairs_issued": int(r_rtl.stats["pairs_issued"]),
           "equal_to_model": bool((r_rtl.tri_id == r_mod.tri_id).all()
                                  and (r_rtl.image == r_mod.image).all())}
    say(f"rtl ({spec.rtl}) tiny point: {t_rtl:.1f} s, model {t_mod:.2f} s, equal to model: "
        f"{out['equal_to_model']}")
    return out
