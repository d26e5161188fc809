"""The benchmark sweep: each point rendered under its cap and measured.

The points come from :mod:`.plan`, the render's backend from :mod:`.instrumented`, the
figures from :mod:`.metrics`.

**Cap.** A point may issue at most ``max_pairs`` pairs. When the brute-force bound of the
render (every ray against every triangle) is above it, a pre-pass renders the point at
1/:data:`PREPASS_DIVISOR` of the image side under the cap scaled down by the pixel ratio;
its pairs scaled up by the pixel ratio are the point's estimate. A point whose estimate is
over the cap (or whose pre-pass, or render, goes over its budget: the sweep's backend counts
the pairs as the unit's runs go and stops the render there) is not rendered to the end: it
is reported with ``capped`` set, its reason, and the figures of the pre-pass scaled up
(estimates, or lower bounds when a budget stopped it).
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, replace
from datetime import datetime, timezone

from ..fp import FP24, FPFormat
from ..host.backends import BackendUnavailable, make_backend
from ..host.render import RenderSettings, render
from ..host.scenes import SCENES, get_scene, soup_scene
from ..model.modes import MODES
from . import cost as dev
from .instrumented import PairBudgetExceeded, SweepBackend
from .metrics import (device_counts, device_figures, pair_errors, pixel_errors, run_figures,
                      stress_metrics)
from .plan import (PREPASS_DIVISOR, BenchSpec, domain_bound, find_meshes, format_label, plan,
                   point_format, scene_label)

__all__ = ["run_sweep", "results_of", "RUN_KEYS"]


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
        return SweepBackend(fmt, mode, pair_budget=budget, sample_pairs=spec.pair_sample,
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
        out.update(run_figures(res, wall, cpu))
        out["tris_out_of_domain"] = int(backend.out_of_domain.sum())
        out.update(pixel_errors(res, ref, backend.out_of_domain))
        out.update(pair_errors(backend, scene.triangles))
        out.update(device_counts(backend, mode))
        return out
    # capped: the pre-pass's figures scaled to the point's size (estimates, or lower bounds
    # when a budget stopped it), or those of the render that went over the cap
    out.setdefault("t_total", t_pre)
    out.setdefault("cpu_total", c_pre)
    if src is not None and src.passes:
        out["figures_from"] = "pre-pass, scaled" if src is pre else "render, up to the cap"
        out.update(device_counts(src, mode, src_scale))
        out["pairs_issued"] = out["device_pairs"]
        errs = pair_errors(src, scene.triangles)
        for k in ("pair_hit_differs", "pairs_out_of_domain", "in_domain_pairs"):
            errs[k] = int(round(errs[k] * src_scale))
        out.update({k: v for k, v in errs.items() if k != "pairs_total"})
        out["tris_out_of_domain"] = int(src.out_of_domain.sum())
    else:
        out["figures_from"] = "none"
        out["pairs_issued"] = cap
    return out


def _model_row(p, fmt, settings, bound, spec, fig) -> dict:
    return {"grid": p["grid"], "backend": "model", "format": format_label(fmt),
            "rounding": fmt.rounding, "mode": p["mode"], "scene": scene_label(p["scene"]),
            "bundle": f"{p['bundle'][0]}x{p['bundle'][1]}",
            "size": f"{settings.width}x{settings.height}", "bound": bound,
            "shadow": f"{spec.shadow[0]}x{spec.shadow[1]}", **fig}


def _point_line(k, n, p, fmt, row) -> str:
    head = (f"[{k + 1:3d}/{n}] {p['grid']:7s} {format_label(fmt)}/{fmt.rounding:4s} "
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
                        "rounding": "-", "mode": "-", "scene": scene_label(name),
                        "bundle": f"{bundle[0]}x{bundle[1]}", "size": ref.stats["size"],
                        "bound": bound, **run_figures(ref, wall, cpu)}
    tell(f"float64      {scene_label(name):18s} {out['reference']['bundle']:>5s} bound "
         f"{bound:g}: {wall:6.2f} s (CPU {cpu:.2f} s)")
    for k, p in points:
        fmt = point_format(p["format"], p["rounding"])
        _ensure_warm(spec, fmt, p["mode"])
        try:
            fig = _measure_point(p, fmt, scene, settings, spec, ref)
        except ValueError as exc:
            out["points"].append((k, None, f"point {format_label(fmt)}/{fmt.rounding} {p['mode']} "
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
        return {"stress": stress_metrics(point_format(f, r), spec.modes, spec.per_family, spec.seed),
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
    say = progress or (lambda *_: None)
    t_start, c_start = time.perf_counter(), time.process_time()
    started = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    notes = []
    meshes, note = find_meshes(spec.mesh_dir)
    if note and spec.mesh_dir is not None:
        notes.append(note)
    points = plan(spec, meshes)
    fmts = {(f, r): point_format(f, r) for f in spec.formats for r in spec.roundings}

    def costs_job():
        out = {}
        for (f, r), fmt in fmts.items():
            key = f"{format_label(fmt)}/{r}"
            try:
                out[key] = dev.format_cost(fmt, allow_json=spec.quick)
            except (RuntimeError, LookupError, OSError) as exc:
                out[key] = {"error": str(exc)}
                continue
            try:
                ref = (out[key] if format_label(fmt) == "FP24" else
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
            stress[f"{format_label(fmt)}/{r}"] = stress_metrics(fmt, spec.modes, spec.per_family,
                                                          spec.seed)
            say(_stress_line(f"{format_label(fmt)}/{r}", stress[f"{format_label(fmt)}/{r}"]))
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
                k = f"{format_label(fmts[task[2:]])}/{task[3]}"
                stress[k] = res["stress"]
                say(_stress_line(k, stress[k]))
            else:
                done[task[2:5]] = res
                for line in res["lines"]:
                    say(line)
        stress = {f"{format_label(fmt)}/{r}": stress[f"{format_label(fmt)}/{r}"]
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
        row.update(stress[f"{format_label(fmt)}/{fmt.rounding}"][p["mode"]])
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
        spec_d["mesh_dir"] = dev.rel_path(spec_d["mesh_dir"])
    return {"spec": spec_d, "points": rows, "stress": stress, "costs": costs,
            "device": {"name": "XC4VSX35", "rows": dev.DEVICE_ROWS, "cols": dev.DEVICE_COLS,
                       "testers": dev.DEVICE_TESTERS, "tester_latency": dev.TESTER_LATENCY,
                       "rt_latency": {m: dev.rt_latency(m) for m in MODES},
                       "clocks_mhz": dict(dev.CLOCKS_MHZ), "clock_mhz": clock},
            "synth_checks": checks, "notes": notes, "meshes": [scene_label(m) for m in meshes],
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
        b = SweepBackend(fmt, mode, sample_pairs=1000)
        render(scene, b, _warm_settings(rows, cols, spec))
        pair_errors(b, scene.triangles)


def _rtl_point(spec: BenchSpec, fmt: FPFormat, say) -> dict:
    """One tiny rtl render (24-triangle soup, 16x16, 4x4 bundles, no shadows) against the
    model on the same settings."""
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
