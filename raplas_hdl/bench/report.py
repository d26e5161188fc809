"""Outputs of ``raplas-hdl bench``: ``results.csv``, ``results.json``, PNG plots and the markdown
report (:func:`write_outputs`)."""

from __future__ import annotations

import csv
import json
import math
import os
import platform
from pathlib import Path

import numba
import numpy

from . import cost as dev
from .metrics import missing_metrics
from .pareto import COSTS, ERRORS, aggregate, fronts

__all__ = ["STRESS_CAMPAIGN_JSON", "jsonable", "load_results", "write_csv", "write_json",
           "plot", "render_markdown", "write_outputs", "machine"]

#: Written by the stress campaign (another command); summarised here when present.
STRESS_CAMPAIGN_JSON = Path(__file__).resolve().parents[2] / "docs" / "results" / \
    "stress_campaign.json"


def jsonable(x):
    """Plain JSON values: non-finite floats become the strings ``"inf"``, ``"-inf"``,
    ``"nan"``; tuples lists; NumPy scalars Python numbers."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if hasattr(x, "item") and not isinstance(x, (str, bytes)):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    return x


def _unjson(x):
    if isinstance(x, dict):
        return {k: _unjson(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_unjson(v) for v in x]
    if x in ("inf", "-inf", "nan"):
        return float(x)
    return x


def load_results(path) -> dict:
    """Read a ``results.json`` back (the non-finite strings become floats again, the bundle
    sizes of the spec tuples)."""
    res = _unjson(json.loads(Path(path).read_text()))
    res["spec"]["bundles"] = [tuple(b) for b in res["spec"]["bundles"]]
    return res


def machine() -> dict:
    return {"platform": platform.platform(), "processor": platform.processor() or
            platform.machine(), "cpus": os.cpu_count(), "python": platform.python_version(),
            "numpy": numpy.__version__, "numba": numba.__version__}


def _columns(points):
    cols = []
    for p in points:
        for k in p:
            if k not in cols:
                cols.append(k)
    return cols


def write_csv(points: list[dict], path) -> Path:
    path = Path(path)
    cols = _columns(points)
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        for p in points:
            w.writerow({k: _cell(p.get(k)) for k in cols})
    return path


def _cell(v):
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else str(v)
    return "" if v is None else v


def write_json(results: dict, path) -> Path:
    path = Path(path)
    path.write_text(json.dumps(jsonable(results), indent=1, sort_keys=True) + "\n")
    return path


# -- plots ---------------------------------------------------------------------------------

_MARK = {"FP16": "v", "FP20": "s", "FP24": "o", "FP32": "D"}
_COL = {"rtz": "tab:blue", "rne": "tab:orange", "chop": "tab:green"}


_SHORT = {"err_pixels": "pixels differing", "err_t": "median rel. error of t"}


def _floor(v, lo):
    return v if v > lo else lo


PLOTS = {"time_s": "pareto_time.png", "hw_cost": "pareto_hw.png",
         "device_s": "pareto_device.png"}


def plot(results: dict, out_dir) -> list[Path]:
    """``pareto_time.png``, ``pareto_hw.png``, ``pareto_device.png`` (each: both errors
    against one cost, the front marked) and ``error_by_format.png`` (per scene, error against
    the format)."""
    import matplotlib      # lazy: matplotlib loads only to draw the plots

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    rows = aggregate(results["points"])
    fr = fronts(rows)
    paths = []
    floors = {"err_pixels": 1e-4, "err_t": 1e-9}
    for cost, fname in PLOTS.items():
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
        left_out = sorted({r["config"] for r in rows if r.get(cost) is None
                           or not math.isfinite(r[cost]) or r.get("capped")})
        for ax, err in zip(axes, ERRORS):
            lo = floors[err]
            for r in rows:
                if (r.get(cost) is None or not math.isfinite(r[cost])
                        or not math.isfinite(r[err])):
                    continue
                ax.scatter(r[cost], _floor(r[err], lo), marker=_MARK.get(r["format"], "x"),
                           color=_COL.get(r["rounding"], "k"),
                           facecolors="none" if r["mode"] == "conservative" else None, s=46)
            idx = fr[(err, cost)]
            if idx:
                xs = [rows[i][cost] for i in idx]
                ys = [_floor(rows[i][err], lo) for i in idx]
                ax.step(xs, ys, where="post", color="crimson", lw=1.2, zorder=0)
                ax.scatter(xs, ys, s=160, facecolors="none", edgecolors="crimson", lw=1.5,
                           label="Pareto front")
                for i in idx:
                    ax.annotate(rows[i]["config"], (rows[i][cost], _floor(rows[i][err], lo)),
                                fontsize=7, xytext=(4, 4), textcoords="offset points")
            ax.set_yscale("log")
            if cost == "device_s":
                ax.set_xscale("log")
            ax.set_xlabel(COSTS[cost])
            ax.set_ylabel(_SHORT[err] + f" (0 drawn at {lo:g})")
            title = ERRORS[err]
            if left_out:
                title += "\nnot drawn (no unit fits, capped or no value): " + (
                    ", ".join(left_out) if len(left_out) <= 6
                    else f"{len(left_out)} configurations (see the report)")
            ax.set_title(title, fontsize=8)
            ax.grid(alpha=0.3)
        handles = [plt.Line2D([], [], marker=m, ls="", color="gray", label=f)
                   for f, m in _MARK.items() if any(r["format"] == f for r in rows)]
        handles += [plt.Line2D([], [], marker="o", ls="", color=c, label=k)
                    for k, c in _COL.items() if any(r["rounding"] == k for r in rows)]
        handles += [plt.Line2D([], [], marker="o", ls="", mfc="none", color="gray",
                               label="conservative (hollow)")]
        handles += [plt.Line2D([], [], marker="o", ls="", mfc="none", ms=11, color="crimson",
                               label="Pareto front")]
        fig.legend(handles=handles, loc="upper center", ncol=len(handles), fontsize=8)
        fig.tight_layout(rect=(0, 0, 1, 0.93))
        p = out_dir / fname
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)

    pts = [p for p in results["points"] if p["backend"] != "float64"
           and p["grid"] in ("main", "meshes")]
    r0 = results["spec"]["roundings"][0]
    m0 = results["spec"]["modes"][0]
    sel = [p for p in pts if p["rounding"] == r0 and p["mode"] == m0]
    scenes = list(dict.fromkeys(p["scene"] for p in sel))
    fmts = list(dict.fromkeys(p["format"] for p in sel))
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    for key, ax, lo, label in (("t_rel_median", axes[0], 1e-9, "median relative error of t"),
                               ("tri_differs", axes[1], 1e-4, "pixels whose triangle differs"),
                               ("psnr", axes[2], None, "PSNR vs float64 (dB, inf drawn at 100)")):
        for s in scenes:
            ys = []
            for f in fmts:
                v = next((p.get(key) for p in sel if p["scene"] == s and p["format"] == f
                          and not p.get("capped")), math.nan)
                v = float(v) if v is not None else math.nan
                if key == "psnr":
                    v = 100.0 if math.isinf(v) else v
                elif lo is not None and math.isfinite(v):
                    v = _floor(v, lo)
                ys.append(v)
            ax.plot(fmts, ys, marker="o", label=s)
        if lo is not None:
            ax.set_yscale("log")
        ax.set_title(f"{label}\n({r0}, {m0} mode)", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    p = out_dir / "error_by_format.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)
    return paths


# -- markdown ------------------------------------------------------------------------------

def _f(v, spec="{:.3g}"):
    if v is None:
        return "-"
    if isinstance(v, str):
        return v
    if isinstance(v, float):
        if math.isnan(v):
            return "n/a"
        if math.isinf(v):
            return "inf"
    return spec.format(v)


def _pct(v):
    return "-" if v is None else ("n/a" if isinstance(v, float) and math.isnan(v)
                                  else f"{100 * v:.2f} %")


def _table(head, rows):
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


#: How the sweep runs on a Dask cluster (a fixed text: the report is regenerated whole).
_CLUSTER_SECTION = [
    "## On a Dask cluster", "",
    "`raplas-hdl bench --dask-workers N` (a local Dask cluster) or `--scheduler ADDRESS` (a "
    "running one) with the `cluster` extra (`pip install 'raplas-hdl[cluster]'`) runs the "
    "sweep's tasks on Dask. Each task is the R metrics of a format and rounding, or a group: "
    "a float64 reference and the model points that share its scene, bundle size and bound. "
    "The client puts the rows back in plan order. Every result equals the in-process sweep's "
    "and only the timings differ: each point's are those of the worker that rendered it "
    "(`raplas_hdl.bench.sweep.results_of`, `tests/project/test_cluster.py`). The `--rtl` point and "
    "the Yosys costs stay on the client ([docs/cluster.md](cluster.md)).", ""]


def _stress_campaign_section(path=STRESS_CAMPAIGN_JSON) -> list[str]:
    lines = ["## Stress campaign", ""]
    if not Path(path).exists():
        return lines + [f"`{_rel(path)}` is not there yet: the stress campaign (issue 6, point "
                        "2; its own command) writes it. The R metrics above come from the "
                        "seeded stress families run by this benchmark (smaller).", ""]
    try:
        data = json.loads(Path(path).read_text())
    except ValueError as exc:
        return lines + [f"`{_rel(path)}` could not be read: {exc}", ""]
    lines.append(f"Results of the stress campaign, from `{_rel(path)}` (written by the campaign "
                 "command, read here):")
    lines.append("")
    if isinstance(data, dict):
        for k in ("command", "generated", "date", "seed", "cases", "total_cases", "wall_seconds"):
            if k in data:
                lines.append(f"- {k}: `{data[k]}`")
        summary = data.get("summary") or data.get("results") or data.get("pooled")
        if isinstance(summary, list) and summary and isinstance(summary[0], dict):
            keys = [k for k in summary[0] if not isinstance(summary[0][k], (dict, list))][:10]
            lines += ["", _table(keys, [[_f(r.get(k)) for k in keys] for r in summary[:40]])]
        elif isinstance(summary, dict):
            lines += ["", "```", json.dumps(jsonable(summary), indent=1)[:3000], "```"]
        else:
            lines.append(f"- top-level keys: {', '.join(sorted(data))}")
    elif isinstance(data, list) and data and isinstance(data[0], dict):
        keys = [k for k in data[0] if not isinstance(data[0][k], (dict, list))][:10]
        lines += [_table(keys, [[_f(r.get(k)) for k in keys] for r in data[:40]])]
    lines.append("")
    return lines


def _rel(path, start=None):
    root = Path(__file__).resolve().parents[2]
    try:
        return os.path.relpath(Path(path).resolve(), start or root)
    except ValueError:
        return str(path)


def _ms(v):
    """Seconds as milliseconds; ``inf`` (no unit fits) as such."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "n/a"
    if isinstance(v, float) and math.isinf(v):
        return "no fit"
    return f"{1e3 * v:.3g}"


def _mega(v, unit=1e6):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    return f"{v / unit:.3g}"


def _device_section(results: dict, rows: list) -> list[str]:
    """``## Frame time on the device``: the model, the device unit per format, the figures
    per configuration and per point, the capped points."""
    d = results.get("device") or {}
    clocks = d.get("clocks_mhz") or dict(dev.CLOCKS_MHZ)
    lat = d.get("rt_latency") or {m: dev.rt_latency(m) for m in ("paper", "conservative")}
    t = d.get("testers", dev.DEVICE_TESTERS)
    L = ["## Frame time on the device", "",
         "What a hardware user decides on: the time one XC4VSX35 full of intersection units "
         "would take for the frame, from the model's counters of the render (`device_*` "
         "columns; `raplas_hdl/bench/cost.py`).", "",
         f"- **The unit**: the synthesised intersection unit of `docs/results/synthesis.json` "
         f"(`raplas-hdl synth intersection-unit`: a {d.get('rows', dev.DEVICE_ROWS)}x"
         f"{d.get('cols', dev.DEVICE_COLS)} bundle, {t} plane-sphere testers, the memories, "
         "selector, FIFOs and the ray-triangle unit). At FP24 its DSP48, slices~ and block "
         "RAM are the synthesised row's; at another format they are *estimated*: the FP24 row "
         "plus the difference of the composed operators between that format and FP24 (18 "
         f"fp-mul + 15 fp-add of the ray-triangle unit, 3 + 3 per tester, x {t} testers), "
         "block RAM scaled by the word width. The units that fit are the minimum over DSP48, "
         "slices~ and block RAM (`raplas_hdl.synth.report.capacity`); 0 when one does not fit "
         "(frame time `no fit`).",
         "- **Cycles of a frame**: summed over the unit's runs (a run: one bundle of "
         "P = rows + cols planes against its list of S leaf spheres, N pairs issued), "
         f"`cycles = P + S * G + (G + {dev.TESTER_LATENCY} + 1) + N + L_rt` with "
         f"G = ceil(P / {t}) clocks per sphere in the array (its passes), "
         f"G + {dev.TESTER_LATENCY} + 1 the array's latency, one pair per clock into the "
         f"ray-triangle unit and L_rt its latency ({lat['paper']} paper, "
         f"{lat['conservative']} conservative). P clocks load the bundle's planes. The stages "
         "are taken one after the other, within a run and between runs: an upper bound on "
         "the RTL's time for the same runs (`device_cycles_overlap` replaces S * G + N by "
         "max(S * G, N) per run: the bound the other way). A bundle larger than the unit's "
         "is taken in G passes of the same testers (its Ray and Plane Memories deeper; the "
         "resources are the synthesised unit's). The host's hierarchy cull is software and "
         "not counted, nor are the cycles of disabled rays' skipped pairs.",
         "- **Frame time** = cycles / units / clock, the runs spread evenly over the units; "
         "clocks: " + ", ".join(f"{k} {v:g} MHz" for k, v in clocks.items())
         + " (the `device_frame_s` column is at the first).",
         "- **Result link**: one result beat per issued pair (`RESULT` of "
         "`raplas_hdl.model.records` bound to the unit configuration of the point's largest "
         "bundle: W, ray ID and triangle ID bits), so `link_bits` = pairs x beat bits per "
         "frame and `link_bits_per_s` = link_bits x the device frame rate. The beat of a run "
         "that issued no pair (`link_empty_beats`) is left out.", ""]
    costs = results.get("costs", {})
    units = [(k, c["device"]) for k, c in costs.items() if isinstance(c.get("device"), dict)]
    if units:
        L += ["**The device unit per format** (one XC4VSX35: 192 DSP48, 15,360 slices, 192 "
              "block RAMs):", "",
              _table(["format", "basis", "DSP48", "slices~", "BRAM", "units that fit",
                      "binding", "units with slices x1.25"],
                     [[k, u.get("basis", "-"), u.get("dsp48", "-"), u.get("slices_est", "-"),
                       u.get("bram", "-"), u.get("units", "-"),
                       ", ".join(u.get("binding", [])) or "-",
                       u.get("units_with_margin", "-")] if "error" not in u else
                      [k, "-", "-", "-", "-", "-", "-", u["error"]] for k, u in units]), ""]
    names = list(clocks)
    have = [r for r in rows if r.get("device_cycles") is not None
            and math.isfinite(r.get("device_cycles", math.nan))]
    if have:
        def at(r, mhz):
            u = r.get("device_units")
            if u is None or (isinstance(u, float) and math.isnan(u)):
                return math.nan
            return math.inf if not u else r["device_cycles"] / u / (mhz * 1e6)

        L += ["**Per configuration** (main grid, summed over its scenes):", "",
              _table(["config", "scenes", "pairs (M)", "cycles (M)", "units"]
                     + [f"frame ms @ {clocks[n]:g} MHz" for n in names]
                     + [f"fps @ {clocks[names[0]]:g} MHz", "link Mbit/frame",
                        "link Gbit/s", "software s", "CPU s", "capped"],
                     [[r["config"], r["scenes"], _mega(r.get("pairs_issued")),
                       _mega(r["device_cycles"]), _f(r.get("device_units"))]
                      + [_ms(at(r, clocks[n])) for n in names]
                      + [_f(1.0 / at(r, clocks[names[0]]) if 0 < at(r, clocks[names[0]])
                            < math.inf else 0.0, "{:.3g}"),
                         _mega(r.get("link_bits")),
                         "no fit" if r.get("device_units") == 0
                         else _mega(r.get("link_bits_per_s"), 1e9),
                         _f(r.get("time_s"), "{:.1f}"), _f(r.get("cpu_s"), "{:.1f}"),
                         r.get("capped", 0)]
                      for r in sorted(have, key=lambda r: (r["format"], r["rounding"],
                                                           r["mode"]))]), ""]
    pts = [p for p in results["points"] if p.get("backend") != "float64"
           and p.get("device_cycles") is not None]
    if pts:
        L += ["**Per point** (every model point; capped points marked, their figures "
              "estimates or lower bounds):", "",
              _table(["grid", "format", "mode", "scene", "bundle", "size", "pairs (M)",
                      "cycles (M)", "overlapped (M)", "units", "frame ms", "fps",
                      "beat bits", "link Mbit/frame", "link Gbit/s", "software s", "CPU s",
                      "capped"],
                     [[p["grid"], f"{p['format']}/{p['rounding']}", p["mode"], p["scene"],
                       p["bundle"], p.get("size", "-"), _mega(p.get("pairs_issued")),
                       _mega(p["device_cycles"]), _mega(p.get("device_cycles_overlap")),
                       _f(p.get("device_units")), _ms(p.get("device_frame_s")),
                       _f(p.get("device_fps"), "{:.3g}"), _f(p.get("link_beat_bits")),
                       _mega(p.get("link_bits")),
                       "no fit" if p.get("device_units") == 0
                       else _mega(p.get("link_bits_per_s"), 1e9),
                       _f(p.get("t_total"), "{:.2f}"), _f(p.get("cpu_total"), "{:.2f}"),
                       "**capped**" if p.get("capped") else ""] for p in pts]), ""]
    capped = [p for p in results["points"] if p.get("capped")]
    if capped:
        L += ["**Capped points** (not rendered to the end):", "",
              _table(["grid", "format", "mode", "scene", "bundle", "cap (pairs)", "reason",
                      "figures from"],
                     [[p["grid"], f"{p['format']}/{p['rounding']}", p["mode"], p["scene"],
                       p["bundle"], f"{p['max_pairs']:,}", p.get("capped_reason", ""),
                       p.get("figures_from", "-")] for p in capped]), ""]
    return L


def render_markdown(results: dict, plots: list, md_path, *, command: str,
                    files: list) -> str:
    """The markdown report (paths of the plots relative to ``md_path``)."""
    spec = results["spec"]
    pts = results["points"]
    model = [p for p in pts if p["backend"] != "float64"]
    rows = aggregate(pts)
    fr = fronts(rows)
    md_dir = Path(md_path).resolve().parent
    mach = results.get("machine") or machine()
    L = ["# Benchmark: run time against error", "",
         "Generated by `raplas-hdl bench` (`raplas_hdl/bench/`). Do not edit by hand.", "",
         f"- **Command**: `{results.get('command', command)}`"
         + (f" (report regenerated from its JSON by `{command}`)"
            if results.get("command", command) != command else ""),
         f"- **Date**: {results['started']}; wall time {results['wall_seconds']:.0f} s "
         f"({len(model)} model points, {len(pts) - len(model)} float64 reference renders)",
         f"- **Machine**: {mach['platform']}, {mach['cpus']} CPUs ({mach['processor']}), "
         f"Python {mach['python']}, NumPy {mach['numpy']}, numba {mach['numba']}; shared with "
         "other jobs, so times carry noise of some 10-30 %",
         f"- **Runs per point**: {spec['repeats']} (the fastest run's timings are kept); "
         "a warm-up render per backend, format, rounding, mode and bundle size keeps "
         "numba's compile out of the timings (the `compile` stage is what is left)",
         f"- **Images**: procedural scenes {spec['size'][0]}x{spec['size'][1]}, meshes "
         f"{spec['mesh_size'][0]}x{spec['mesh_size'][1]}, soft shadows "
         f"{spec['shadow'][0]}x{spec['shadow'][1]} per point"
         + (f"; at most {spec['max_pairs']:,} pairs per point (the cap), per-pair errors on a "
            f"sample of at most {spec.get('pair_sample', 0):,} pairs, "
            f"{spec.get('threads', 1)} thread(s) per render" if "max_pairs" in spec else ""),
         f"- **Time**: wall {results['wall_seconds']:.0f} s, CPU "
         + (f"{results['cpu_seconds']:.0f} s" if "cpu_seconds" in results else "not recorded")
         + (f", load average at the end {', '.join(f'{x:.1f}' for x in results['load_average'])}"
            if results.get("load_average") else ""),
         f"- **Axes**: formats {', '.join(spec['formats'])}; roundings "
         f"{', '.join(spec['roundings'])}; modes {', '.join(spec['modes'])}; scenes "
         f"{', '.join(spec['scenes'] + results.get('meshes', []))}; bundles "
         f"{', '.join(f'{r}x{c}' for r, c in spec['bundles'])} (main "
         f"{spec['bundles'][0][0]}x{spec['bundles'][0][1]})",
         f"- **Stress families for R**: {spec['per_family']} rays per family, seed "
         f"{spec['seed']}", ""]
    for n in results.get("notes", []):
        L.append(f"> Note: {n}")
    if results.get("notes"):
        L.append("")
    L += ["## What is measured", "",
          "Grids: `main` = every format x rounding x mode on every procedural scene at the main "
          "bundle size (the Pareto fronts use it); `meshes` = every format and mode on the "
          "mesh files at the first rounding (the conservative mode's wide margins at "
          "FP16/FP20 make a 70k-triangle mesh issue nearly the brute-force pairs: such "
          "points come out capped); `bundles` = every format on the procedural scenes at "
          "the other bundle sizes (first rounding and mode); `cap` = a point under a tiny "
          "cap that must come out capped (with `--quick`). Each scene is normalised (a "
          "power-of-two scale, exact) into its format's domain: bound = min(2^P, 256) with P "
          "the domain's exponent (FP16: 4, the others: 256); the float64 reference is "
          "rendered at the same bound.", "",
          "- **Error against float64, per pair**: the sweep's backend records a uniform "
          "sample of the unit's runs as the render traces them (whole runs, at most "
          "`pair_sample` pairs; `pairs_sampled` says how many), streams their pairs after the "
          "render and evaluates each in float64 on the original geometry; `t_rel` = "
          "|t - t64| / |t64| over the *in-domain* pairs both hit (median, p99; `t_pairs` "
          "of them); `pair_hit_differs` counts in-domain pairs whose hit bit differs (scaled "
          "from the sample to the issued pairs). A pair is *out of the domain* when its "
          "triangle is (a coordinate beyond 2^P or an edge below the minimum edge): the "
          "sweep loads such triangles (the host's `render` would drop them) and counts "
          "their pairs in `pairs_out_of_domain`.",
          "- **Error against float64, per pixel**: PSNR of the 8-bit images; fraction of "
          "pixels whose nearest triangle differs (`tri_differs`; `tri_differs_in_domain` "
          "counts only pixels whose triangles, in both renders, are in the domain).",
          "- **Error against R** (the exact reference): false hits, false misses and edge "
          "leaks of the model on the seeded stress families of `raplas_hdl.verify.stress`, once "
          "per format, rounding and mode (in-domain pairs only), and the relative error of "
          "t against R's.",
          "- **Run time** (software): wall time (`t_total`) and CPU time (`cpu_total`) of the "
          "render, wall time per render stage (`t_*`), rays per second over the render, "
          "pairs per second over the unit's stages (`primary unit` + `shadow unit`).",
          "- **Frame time on the device** and **result-link traffic**: see "
          "[below](#frame-time-on-the-device).",
          "- **Cap**: a point may issue at most `max_pairs` pairs. When the brute-force bound "
          "of its render is above the cap, a pre-pass at a quarter of the image side (under "
          "the cap scaled by the pixel ratio) estimates its pairs; a point whose estimate is "
          "over the cap, or whose pre-pass or render goes over its budget (the sweep's backend "
          "counts the pairs as the runs go and stops there), is reported with `capped` set "
          "and its reason, its figures those of the pre-pass scaled up (estimates, or lower "
          "bounds when a budget stopped it); it has no pixel errors and takes no part in the "
          "fronts.",
          "", "### What \"cost\" means", "",
          "Two costs. **Run time**: the model backend's wall time for the render (summed over "
          "the scenes of a configuration). **Hardware**: the Yosys resources "
          "(`synth_xilinx -family xc4v`, through `raplas_hdl.synth`, cached under "
          "`build/synth`) of the ray-triangle unit the format implies, *composed* as "
          "18 fp-mul + 15 fp-add of that format and rounding (synthesising the whole unit per "
          "format takes 3-6 minutes each; the comparators and delay lines are left out). The "
          "scalar hardware cost is the fraction of one XC4VSX35 the unit takes, "
          "max(DSP48/192, slices/15360): its binding resource (1/cost units fit). Slices are "
          "Yosys-based estimates and no timing is implied. **Device frame time**: the cycles "
          "of the whole intersection unit for the frame, over the units that fit and the "
          "clock (next section): the axis a hardware user decides on.", ""]

    L += ["## Pareto fronts", "",
          "Configurations of the `main` grid, aggregated over its scenes; a configuration is "
          "on the front when no other is at least as good in both error and cost. Read "
          "them with two caveats: the model's *run time* hardly depends on the format (it "
          "is software emulation; differences of a few percent are noise and pair counts), "
          "so the hardware-cost fronts are the ones that rank formats; and the t error "
          "counts only pairs that both the model and float64 hit. The conservative "
          "unit's hits are a superset of R's (no false misses, many false hits); the "
          "render resolves them on the host like the certified mode's uncertain pairs "
          "(docs/conservative-mode.md), so its pixels are R's and the host's share is in "
          "its run time.", ""]
    for (err, cost), idx in fr.items():
        L.append(f"**{ERRORS[err]}** against **{COSTS[cost]}**:")
        L.append("")
        L.append(_table(["configuration", "error", "cost", "DSP48", "slices~", "time (s)"],
                        [[rows[i]["config"], _f(rows[i][err]), _f(rows[i][cost]),
                          _f(rows[i]["hw_dsp48"]), _f(rows[i]["hw_slices"]),
                          _f(rows[i]["time_s"])] for i in idx]))
        L.append("")
    for p in plots:
        L.append(f"![{p.stem}]({os.path.relpath(p.resolve(), md_dir)})")
        L.append("")

    L += _device_section(results, rows)

    L += ["## Configurations (main grid, aggregated)", "",
          _table(["config", "bundle", "scenes", "pixels differ", "in domain", "t_rel median",
                  "t_rel p99 (max)", "min PSNR", "out-of-domain pairs", "time (s)",
                  "pairs/s", "DSP48", "slices~", "hw cost", "R: FH", "R: FM", "R: leaks"],
                 [[r["config"], r["bundle"], r["scenes"], _pct(r["err_pixels"]),
                   _pct(r["err_pixels_in_domain"]), _f(r["err_t"]), _f(r["err_t_p99"]),
                   _f(r["psnr_min"], "{:.1f}"), _pct(r["pairs_out_of_domain_frac"]),
                   _f(r["time_s"], "{:.1f}"), _f(r["pairs_per_s"], "{:.3g}"),
                   _f(r["hw_dsp48"]), _f(r["hw_slices"]), _f(r["hw_cost"]),
                   _f(r["r_false_hits"]), _f(r["r_false_misses"]), _f(r["r_leaks"])]
                  for r in sorted(rows, key=lambda r: (r["format"], r["rounding"], r["mode"]))]),
          ""]

    holes = [(p, missing_metrics(p)) for p in pts if missing_metrics(p)]
    n_capped = sum(1 for p in model if p.get("capped"))
    L += ["## Points", "",
          "Every model point (all metrics are in `results.csv` / `results.json`). "
          + (f"{n_capped} capped point(s) have only the figures of a capped point "
             "(section above). " if n_capped else "")
          + ("Every point has every metric." if not holes else
             f"{len(holes)} points lack a value, because they have no in-domain hit pair or "
             "no in-domain pixel (their triangles are all outside the format's domain): "
             + "; ".join(f"{p['format']}/{p['rounding']} {p['mode']} {p['scene']} "
                         f"{p['bundle']}: {', '.join(m)}" for p, m in holes) + "."), "",
          _table(["grid", "format", "mode", "scene", "bundle", "time (s)", "unit (s)",
                  "rays/s", "pairs/s", "t_rel med", "t_rel p99", "pixels differ",
                  "PSNR", "ood pairs", "events o/u/i (operations)"],
                 [[p["grid"], f"{p['format']}/{p['rounding']}", p["mode"], p["scene"],
                   p["bundle"], _f(p.get("t_total"), "{:.2f}"),
                   _f(p["t_primary_unit"] + p["t_shadow_unit"], "{:.2f}")
                   if "t_primary_unit" in p else "-",
                   _f(p.get("rays_per_s"), "{:.3g}"), _f(p.get("pairs_per_s"), "{:.3g}"),
                   _f(p.get("t_rel_median")), _f(p.get("t_rel_p99")),
                   "capped" if p.get("capped") else _pct(p.get("tri_differs")),
                   _f(p.get("psnr"), "{:.1f}"), _pct(p.get("pairs_out_of_domain_frac")),
                   f"{p['overflow']}/{p['underflow']}/{p['invalid']}" if "overflow" in p
                   else "-"] for p in model]), ""]
    refs = [p for p in pts if p["backend"] == "float64"]
    L += ["### float64 reference renders", "",
          _table(["scene", "bundle", "bound", "size", "time (s)", "rays/s", "pairs/s"],
                 [[p["scene"], p["bundle"], _f(p["bound"], "{:g}"), p["size"],
                   _f(p["t_total"], "{:.2f}"), _f(p["rays_per_s"], "{:.3g}"),
                   _f(p["pairs_per_s"], "{:.3g}")] for p in refs]), ""]

    L += ["## Against R: stress families", "",
          f"{spec['per_family']} rays per family (seed {spec['seed']}), in-domain pairs only.",
          "", _table(["format", "mode", "pairs", "in domain", "R hits", "false hits",
                      "false misses", "edge rays", "leaks", "t_rel med", "t_rel p99"],
                     [[k, m, v["r_pairs"], v["r_in_domain"], v["r_hits"], v["r_false_hits"],
                       v["r_false_misses"], v["r_edge_rays"], v["r_leaks"],
                       _f(v["r_t_rel_median"]), _f(v["r_t_rel_p99"])]
                      for k, d in results["stress"].items() for m, v in d.items()]), ""]

    costs = results.get("costs", {})
    L += ["## Hardware cost per format", "",
          "Ray-triangle unit composed as 18 x fp-mul + 15 x fp-add (Yosys, Virtex-4).", "",
          _table(["format", "fp-mul DSP48/LUT/slices~", "fp-add LUT/slices~", "unit DSP48",
                  "unit LUTs", "unit FFs", "unit slices~", "device fraction", "units fit",
                  "source"],
                 [[k, f"{c['fp_mul']['dsp48']}/{c['fp_mul']['luts']}/"
                      f"{c['fp_mul']['slices_est']}",
                   f"{c['fp_add']['luts']}/{c['fp_add']['slices_est']}", c["dsp48"], c["luts"],
                   c["ffs"], c["slices_est"], _f(c["device_fraction"]), c["units_fit"],
                   "; ".join(c["sources"])] if "error" not in c else [k] + ["-"] * 8 +
                  [c["error"]] for k, c in costs.items()]), ""]
    chk = results.get("synth_checks", {})
    if chk:
        L += ["### Synthesis checks (FP24)", "",
              _table(["unit", "rounding", "DSP48", "LUTs", "FFs", "slices~", "path cells",
                      "target", "source"],
                     [[u, c["rounding"], c["dsp48"], c["luts"], c["ffs"], c["slices_est"],
                       c["path_cells"], {"fp-mul": "exactly 1", "plane-sphere-tester":
                                         "at most 3", "ray-triangle": "at most 18"}.get(u, ""),
                       c["source"]] for u, c in chk.items()]), ""]
        rt = chk.get("ray-triangle")
        comp = costs.get(f"FP24/{rt['rounding']}") if rt else None
        if rt and comp and "error" not in comp:
            L += [f"The synthesised FP24/{rt['rounding']} ray-triangle unit takes {rt['dsp48']} "
                  f"DSP48, {rt['luts']} LUTs and ~{rt['slices_est']} slices; the composition "
                  f"gives {comp['dsp48']} DSP48, {comp['luts']} LUTs and ~{comp['slices_est']} "
                  f"slices ({100 * (comp['slices_est'] / rt['slices_est'] - 1):+.0f} % slices).",
                  ""]
    if results.get("rtl"):
        r = results["rtl"]
        L += ["## RTL point", ""]
        if "unavailable" in r:
            L += [f"rtl backend unavailable: {r['unavailable']}", ""]
        else:
            L += [f"{r['scene']}, {r['size']}, {r['bundle']} bundles, no shadows, {r['format']} "
                  f"{r['mode']}, {r['simulator']}: rtl {r['rtl_seconds']:.1f} s against model "
                  f"{r['model_seconds']:.2f} s ({r['pairs_issued']} pairs); equal to the model "
                  f"bit for bit: **{r['equal_to_model']}**.", ""]
    L += _stress_campaign_section()
    L += _CLUSTER_SECTION
    L += ["## Files", ""] + [f"- `{_rel(f)}`" for f in files] + [""]
    return "\n".join(L)


def write_outputs(results: dict, out_dir, md_path, *, command: str) -> list[Path]:
    """Write ``results.csv``, ``results.json`` and the plots under ``out_dir`` and the
    markdown report at ``md_path``. Returns the paths written."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results.setdefault("machine", machine())
    results.setdefault("command", command)
    if results["command"] != command:
        results["report_command"] = command
    # the JSON first: a long run's results survive a failure further on
    results["aggregate"] = aggregate(results["points"])
    results["fronts"] = {f"{e} vs {c}": [results["aggregate"][i]["config"] for i in idx]
                         for (e, c), idx in fronts(results["aggregate"]).items()}
    json_p = write_json(results, out_dir / "results.json")
    csv_p = write_csv(results["points"], out_dir / "results.csv")
    plots = plot(results, out_dir)
    md_path = Path(md_path)
    md_path.parent.mkdir(parents=True, exist_ok=True)
    files = [csv_p, json_p, *plots, md_path]
    md_path.write_text(render_markdown(results, plots, md_path, command=command, files=files))
    return files
