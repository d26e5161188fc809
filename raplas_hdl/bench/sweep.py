"""The benchmark sweep: which points run, and what is measured at each.

Axes: formats (FP16, FP20, FP24, FP32 and any extra), roundings (rtz, rne, chop), ray-triangle
modes (paper, conservative), scenes (the procedural ones, and the mesh files of
``../shared/meshes`` when that directory exists), bundle sizes, backends (``float64``,
``model``; ``rtl`` on one tiny point on request). The full product is too large for one
machine, so the points form three grids:

``main``     every format x rounding x mode on every procedural scene at the main bundle
             size (the grid of the Pareto fronts);
``meshes``   every format on every mesh file, first rounding and mode, main bundle size
             (the conservative mode at FP16 and FP20 on a 70k-triangle mesh issues nearly
             the brute-force pairs: tens of GB, more than this machine has);
``bundles``  every format on every procedural scene at the other bundle sizes, first rounding,
             first mode;

plus a ``float64`` reference point per scene, bundle size and bound, and an ``rtl`` point when
asked (a 24-triangle soup at 16x16, no shadows, against the model: slow).

Each scene is normalised into its format's domain (:func:`domain_bound`: the largest power
of two inside :func:`raplas_hdl.model.conservative.domain`, at most :data:`BOUND_CAP`); the
float64 reference is rendered at the same bound. The model backend of the sweep loads every
triangle the record builder accepts, also those outside the domain (the host's
``check_domain`` drop would hide the error the format makes there); such triangles are
counted and every pair with one of them is an *out-of-domain pair*, left out of the t errors.

Per point (see :data:`MODEL_METRICS`): wall time per render stage, throughput (rays per
second over the whole render, pairs per second over the unit's stages), and errors:

- against float64, per pair: every pair the model issues is also evaluated in float64 on the
  original geometry (:func:`raplas_hdl.host.exact.float64_intersect`, after the render, so the
  timings do not include it); median and 99th percentile of ``|t - t64| / |t64|`` over the
  in-domain pairs both hit, and the in-domain pairs whose hit bit differs;
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
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..fp import ROUNDINGS, FPFormat, parse_format
from ..host.backends import BackendUnavailable, ModelBackend, make_backend
from ..host.exact import float64_intersect
from ..host.render import RenderSettings, compare, render
from ..host.scenes import MESH_SUFFIXES, SCENES, get_scene
from ..host.triangles import make_triangles
from ..model.conservative import domain

__all__ = ["BOUND_CAP", "MODEL_METRICS", "REFERENCE_METRICS", "MODES", "BenchSpec",
           "quick_spec", "full_spec", "domain_bound", "find_meshes", "plan", "stress_metrics",
           "run_sweep", "missing_metrics", "DEFAULT_MESH_DIR"]

MODES = ("paper", "conservative")
#: Largest normalisation bound used (beyond it only the host's float64 shading changes).
BOUND_CAP = 256.0
#: ``../shared/meshes`` beside the repository.
DEFAULT_MESH_DIR = Path(__file__).resolve().parents[3] / "shared" / "meshes"

STAGES = ("spheres", "load", "primary cull", "primary unit", "shading", "shadow cull",
          "shadow unit", "image")

#: Metrics every model (or rtl) point must have (none may be None or NaN).
MODEL_METRICS = (
    "t_total", *(f"t_{s.replace(' ', '_')}" for s in STAGES), "rays", "pairs_issued",
    "rays_per_s", "pairs_per_s",
    "psnr", "tri_differs", "tri_differs_in_domain", "hit_differs",
    "t_rel_median", "t_rel_p99", "t_pairs", "pair_hit_differs", "pairs_out_of_domain",
    "pairs_out_of_domain_frac", "tris_out_of_domain", "unguaranteed_bundles",
    "overflow", "underflow", "invalid",
    "r_pairs", "r_in_domain", "r_false_hits", "r_false_misses", "r_edge_rays", "r_leaks",
    "r_t_rel_median", "r_t_rel_p99",
    "hw_dsp48", "hw_luts", "hw_ffs", "hw_slices", "hw_cost",
)
#: Metrics of a float64 reference point.
REFERENCE_METRICS = ("t_total", *(f"t_{s.replace(' ', '_')}" for s in STAGES), "rays",
                     "pairs_issued", "rays_per_s", "pairs_per_s")


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
    quick : bool
    """

    formats: list = field(default_factory=lambda: ["FP16", "FP20", "FP24", "FP32"])
    roundings: list = field(default_factory=lambda: list(ROUNDINGS))
    modes: list = field(default_factory=lambda: list(MODES))
    scenes: list = field(default_factory=lambda: list(SCENES))
    mesh_dir: str | None = str(DEFAULT_MESH_DIR)
    bundles: list = field(default_factory=lambda: [(8, 8), (4, 4), (16, 16)])
    size: tuple = (32, 32)
    mesh_size: tuple = (32, 32)
    shadow: tuple = (2, 2)
    rtl: str | None = None
    per_family: int = 2000
    seed: int = 0
    repeats: int = 1
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


def quick_spec(**overrides) -> BenchSpec:
    """``--quick``: FP16, FP24, FP32; rtz; paper; cornell and spheres; 8x8; 32x32; no meshes."""
    kw = dict(formats=["FP16", "FP24", "FP32"], roundings=["rtz"], modes=["paper"],
              scenes=["cornell", "spheres"], mesh_dir=None, bundles=[(8, 8)], size=(32, 32),
              mesh_size=(32, 32), shadow=(2, 2), per_family=300, quick=True)
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
    """The model points of the three grids (see the module docstring), in run order."""
    main = spec.bundles[0]
    pts = []

    def add(grid, f, r, m, scene, b):
        pts.append({"grid": grid, "format": f, "rounding": r, "mode": m, "scene": scene,
                    "bundle": b})

    for f in spec.formats:
        for r in spec.roundings:
            for m in spec.modes:
                for s in spec.scenes:
                    add("main", f, r, m, s, main)
    for f in spec.formats:
        for s in meshes:
            add("meshes", f, spec.roundings[0], spec.modes[0], s, main)
    for b in spec.bundles[1:]:
        for f in spec.formats:
            for s in spec.scenes:
                add("bundles", f, spec.roundings[0], spec.modes[0], s, b)
    return pts


# -- the model backend of the sweep --------------------------------------------------------

class _SweepModel(ModelBackend):
    """The model backend, loading out-of-domain triangles too, and keeping every run's pairs
    (references only: the analysis runs after the render, outside its timings)."""

    def __init__(self, fmt, mode):
        super().__init__(fmt, mode)
        self.log = []
        self.out_of_domain = None

    def usable(self, tris):
        tris = np.asarray(tris, dtype=np.float64)
        rec = make_triangles(tris, self.fmt, on_bad="skip", check_domain=False)
        self._records = (tris, rec)
        ok = np.zeros(len(tris), bool)
        ok[rec.ids] = True
        self.out_of_domain = _out_of_domain(tris, self.fmt)
        return ok, dict(rec.skipped)

    def run_many(self, runs):
        runs = list(runs)
        out = super().run_many(runs)
        for (job, _), res in zip(runs, out):
            if res.ray_id.size:
                self.log.append((job.bundle.origin, job.bundle.directions, res))
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
    """Errors of the issued pairs against float64 on the same pairs (original geometry)."""
    ood = backend.out_of_domain
    if not backend.log:
        return {"t_rel_median": math.nan, "t_rel_p99": math.nan, "t_pairs": 0,
                "pair_hit_differs": 0, "pairs_out_of_domain": 0, "in_domain_pairs": 0}
    ray = np.concatenate([r.ray_id for _, _, r in backend.log])
    tri = np.concatenate([r.tri_id for _, _, r in backend.log])
    hit = np.concatenate([r.hit for _, _, r in backend.log])
    t = np.concatenate([r.t for _, _, r in backend.log])
    o = np.concatenate([np.broadcast_to(np.asarray(org, float), (r.ray_id.size, 3))
                        for org, _, r in backend.log])
    d = np.concatenate([np.asarray(dirs, float)[r.ray_id] for _, dirs, r in backend.log])
    tv = tris[tri]
    ref = float64_intersect(o, d, tv[:, 0], tv[:, 1], tv[:, 2])
    ind = ~ood[tri]
    t64 = ref["t"]
    both = ind & hit & ref["hit"] & np.isfinite(t) & np.isfinite(t64) & (t64 != 0)
    rel = np.abs(t[both] - t64[both]) / np.abs(t64[both])
    med, p99 = _quantiles(rel)
    return {"t_rel_median": med, "t_rel_p99": p99, "t_pairs": int(both.sum()),
            "pair_hit_differs": int((ind & (hit != ref["hit"])).sum()),
            "pairs_out_of_domain": int((~ind).sum()), "in_domain_pairs": int(ind.sum()),
            "pairs_total": int(ray.size)}


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
    best = None
    for _ in range(repeats):
        backend = make()
        t0 = time.perf_counter()
        res = render(scene, backend, settings)
        wall = time.perf_counter() - t0
        if best is None or wall < best[2]:
            best = (backend, res, wall)
    return best


def _run_figures(res, wall) -> dict:
    st, tm = res.stats, res.timings
    out = {"t_total": wall}
    for s in STAGES:
        out[f"t_{s.replace(' ', '_')}"] = float(tm.get(s, 0.0))
    unit_t = tm.get("primary unit", 0.0) + tm.get("shadow unit", 0.0)
    out.update(rays=int(st["rays"]), bundles=int(st["bundles"]),
               pairs_issued=int(st["pairs_issued"]),
               brute_force_pairs=int(st["brute_force_pairs"]),
               rays_per_s=st["rays"] / wall if wall > 0 else math.nan,
               pairs_per_s=st["pairs_issued"] / unit_t if unit_t > 0 else math.nan,
               hits=int(st["hits"]), triangles=int(st["triangles"]),
               unguaranteed_bundles=int(st["unguaranteed_bundles"]),
               **{k: int(v) for k, v in st["events"].items()})
    return out


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
    need = REFERENCE_METRICS if point.get("backend") == "float64" else MODEL_METRICS
    bad = []
    for k in need:
        v = point.get(k)
        if v is None or (isinstance(v, float) and math.isnan(v)) or v == "nan":
            bad.append(k)
    return bad


def run_sweep(spec: BenchSpec, progress=print, cost_thread: bool = True) -> dict:
    """Run every point of ``spec`` and return the results (see :mod:`.report`).

    The hardware costs and synthesis checks (:mod:`.cost`) run in a background thread while
    the renders run (Yosys is a subprocess: on a cold cache it takes the other core).

    Returns
    -------
    dict
        ``spec``, ``points`` (one flat dict per point), ``stress`` (R metrics per format,
        rounding and mode), ``costs`` (per format and rounding), ``synth_checks``, ``notes``,
        ``rtl`` (or None), ``wall_seconds``, ``started``.
    """
    from concurrent.futures import ThreadPoolExecutor
    from datetime import datetime, timezone

    from . import cost

    say = progress or (lambda *_: None)
    t_start = time.perf_counter()
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
            try:
                out[f"{_label(fmt)}/{r}"] = cost.format_cost(fmt, allow_json=spec.quick)
            except (RuntimeError, LookupError, OSError) as exc:
                out[f"{_label(fmt)}/{r}"] = {"error": str(exc)}
        checks = cost.synth_checks(spec.roundings[0], full=not spec.quick)
        return out, checks

    pool = ThreadPoolExecutor(max_workers=1)
    fut = pool.submit(costs_job) if cost_thread else None

    # R metrics, once per format, rounding (and mode)
    stress = {}
    for (f, r), fmt in fmts.items():
        stress[f"{_label(fmt)}/{r}"] = stress_metrics(fmt, spec.modes, spec.per_family,
                                                      spec.seed)
        say(f"stress vs R  {_label(fmt)}/{r}: " + ", ".join(
            f"{m}: FH {v['r_false_hits']} FM {v['r_false_misses']} leaks {v['r_leaks']}"
            for m, v in stress[f"{_label(fmt)}/{r}"].items()))

    scenes, refs, rows = {}, {}, []

    def scene_for(name, bound):
        key = (name, bound)
        if key not in scenes:
            scenes[key] = get_scene(name, bound=bound)
        return scenes[key]

    def settings_for(name, bundle, bound):
        w, h = spec.mesh_size if name not in SCENES else spec.size
        return RenderSettings(w, h, bundle[0], bundle[1], spec.shadow[0], spec.shadow[1],
                              bound=bound, progress=False, threads=1)

    def reference(name, bundle, bound):
        key = (name, bundle, bound)
        if key not in refs:
            scene = scene_for(name, bound)
            _, res, wall = _timed_render(scene, lambda: make_backend("float64"),
                                         settings_for(name, bundle, bound), spec.repeats)
            row = {"grid": "reference", "backend": "float64", "format": "float64",
                   "rounding": "-", "mode": "-", "scene": _scene_name(name),
                   "bundle": f"{bundle[0]}x{bundle[1]}", "size": res.stats["size"],
                   "bound": bound, **_run_figures(res, wall)}
            rows.append(row)
            refs[key] = res
            say(f"float64      {_scene_name(name):18s} {row['bundle']:>5s} bound {bound:g}: "
                f"{wall:6.2f} s")
        return refs[key]

    t0 = time.perf_counter()
    _warm_up(spec, next(iter(fmts.values())))
    say(f"warm-up (numba compile, excluded from the timings): {time.perf_counter() - t0:.1f} s")

    bad_scenes = set()
    for k, p in enumerate(points):
        fmt = fmts[(p["format"], p["rounding"])]
        bound = domain_bound(fmt)
        name = p["scene"]
        if name in bad_scenes:
            continue
        try:
            ref = reference(name, p["bundle"], bound)
        except (ValueError, FileNotFoundError) as exc:
            notes.append(f"scene {name} skipped: {exc}")
            bad_scenes.add(name)
            continue
        scene = scene_for(name, bound)
        try:
            backend, res, wall = _timed_render(scene, lambda: _SweepModel(fmt, p["mode"]),
                                               settings_for(name, p["bundle"], bound),
                                               spec.repeats)
        except ValueError as exc:
            notes.append(f"point {_label(fmt)}/{fmt.rounding} {p['mode']} {name} skipped: {exc}")
            continue
        row = {"grid": p["grid"], "backend": "model", "format": _label(fmt),
               "rounding": fmt.rounding, "mode": p["mode"], "scene": _scene_name(name),
               "bundle": f"{p['bundle'][0]}x{p['bundle'][1]}", "size": res.stats["size"],
               "bound": bound, **_run_figures(res, wall)}
        ood = backend.out_of_domain
        row["tris_out_of_domain"] = int(ood.sum())
        row.update(_pixel_errors(res, ref, ood))
        row.update(_pair_errors(backend, scene.triangles))
        row["pairs_out_of_domain_frac"] = (row["pairs_out_of_domain"] / row["pairs_total"]
                                           if row.get("pairs_total") else 0.0)
        row.update(stress[f"{_label(fmt)}/{fmt.rounding}"][p["mode"]])
        rows.append(row)
        say(f"[{k + 1:3d}/{len(points)}] {p['grid']:7s} {_label(fmt)}/{fmt.rounding:4s} "
            f"{p['mode']:12s} {row['scene']:18s} {row['bundle']:>5s}: {wall:6.2f} s  "
            f"t_rel {row['t_rel_median']:.2e}  pixels {100 * row['tri_differs']:.2f} %  "
            f"PSNR {row['psnr']:.1f}")

    rtl = None
    if spec.rtl:
        f_rtl = "FP24" if "FP24" in spec.formats else spec.formats[0]
        rtl = _rtl_point(spec, fmts[(f_rtl, spec.roundings[0])], say)

    costs, checks = {}, {}
    if fut is not None:
        costs, checks = fut.result()
    pool.shutdown()
    for row in rows:
        if row["backend"] == "float64":
            continue
        c = costs.get(f"{row['format']}/{row['rounding']}", {})
        row.update(hw_dsp48=c.get("dsp48"), hw_luts=c.get("luts"), hw_ffs=c.get("ffs"),
                   hw_slices=c.get("slices_est"), hw_cost=c.get("device_fraction"))
    spec_d = asdict(spec)
    return {"spec": spec_d, "points": rows, "stress": stress, "costs": costs,
            "synth_checks": checks, "notes": notes, "meshes": [_scene_name(m) for m in meshes],
            "rtl": rtl, "started": started, "wall_seconds": time.perf_counter() - t_start}


def _warm_up(spec: BenchSpec, fmt: FPFormat):
    """Render a tiny scene once per backend, mode and bundle size so that numba's compile
    (or the load of its cache) is not in the first point's timings."""
    scene = get_scene("cornell", bound=8.0)
    for rows, cols in spec.bundles:
        st = RenderSettings(max(16, cols), max(16, rows), rows, cols, spec.shadow[0],
                            spec.shadow[1], bound=8.0, progress=False, threads=1)
        render(scene, make_backend("float64"), st)
        for mode in spec.modes:
            render(scene, _SweepModel(fmt, mode), st)


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

