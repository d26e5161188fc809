"""Certified renders against the exact reference: uncertain pairs, host work, zero error.

For each scene and format: the paper-mode render and the certified render, each checked
pixel by pixel against the exact reference R on the rays it issued
(:func:`raplas_hdl.host.reference.exact_reference`, ``tree`` method: R over the triangles of
the leaf spheres the ray's line passes near, float64 filter with exact fallback). Reported:
wall and CPU seconds, pairs issued, the unit's uncertain pairs (fraction of issued), pairs
through the host's float64 filter, pairs resolved in exact arithmetic and the host seconds
that took, pixels whose nearest triangle or shadow visibility differ from R, and the
composed hardware cost of the format's ray-triangle unit (fraction of one XC4VSX35,
:func:`raplas_hdl.bench.cost.format_cost`).

The showcase (every ray type: three generations of reflection and refraction, 3x3 glossy and
ambient-occlusion bundles, 3x3 soft shadows, its scene file's defaults) at FP24, paper and
certified, with and without the on-chip reduction's model: every recorded ray of every pass
against R (:func:`raplas_hdl.host.reference.check_passes`): rays whose triangle (nearest
passes) or blocked state (any-hit passes) differ from R's, and nearest hits whose ``t`` is not
R's correctly rounded ``t``, per ray type.

    .venv/bin/python benchmarks/bench_certified_render.py [--quick] [--showcase SIZE]
        [--showcase-only] [--out FILE.json]

Writes ``docs/results/certified_render.json`` by default. Run it on a quiet machine for
the wall times; the CPU times are reported beside them.
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import time
from pathlib import Path

from raplas_hdl.fp import parse_format
from raplas_hdl.host.backends import ModelBackend
from raplas_hdl.host.reference import check_passes, compare_reference, exact_reference
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene

ROOT = Path(__file__).resolve().parents[1]


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _point(scene, fmt, mode, settings):
    backend = ModelBackend(fmt, mode=mode)
    t0, c0 = time.perf_counter(), _cpu()
    res = render(scene, backend, settings)
    wall, cpu = time.perf_counter() - t0, _cpu() - c0
    t1 = time.perf_counter()
    ref = exact_reference(res, scene.triangles, "tree")
    cmp = compare_reference(res, ref)
    st = res.stats
    row = {"scene": st["scene"], "size": st["size"], "format": str(fmt), "mode": mode,
           "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
           "compile_s": round(res.timings.get("compile", 0.0), 2),
           "pairs_issued": st["pairs_issued"], "rays": st["rays"],
           "tri_id_differ": cmp["tri_id_differ"], "visibility_differ": cmp["visibility_differ"],
           "pixels": cmp["pixels"], "reference_s": round(time.perf_counter() - t1, 2)}
    if "certified" in st:
        c = st["certified"]
        row.update(uncertain=c["uncertain"], uncertain_fraction=c["uncertain_fraction"],
                   certified_hits=c["certified_hits"], filtered=c["filtered"],
                   pending=c["pending"], exact=c["exact"], exact_s=round(c["exact_s"], 4))
    return row


def _showcase(size, mode, reduce):
    """Every pass of the showcase against R (module docstring)."""
    scene = get_scene("showcase")
    d = scene.render_defaults
    gr, gc = (int(x) for x in str(d.get("glossy", "3x3")).split("x"))
    ar, ac = (int(x) for x in str(d.get("ao", "3x3")).split("x"))
    settings = RenderSettings(width=size, height=size, rows=8, cols=8, shadow_rows=3,
                              shadow_cols=3, progress=False, record_rays=True,
                              depth=int(d.get("depth", 3)), glossy_rows=gr, glossy_cols=gc,
                              ao_rows=ar, ao_cols=ac, ao_angle=float(d.get("ao_angle", 60.0)),
                              ao_distance=float(d.get("ao_distance", 0.25)))
    backend = ModelBackend(parse_format("FP24"), mode=mode, reduce=reduce)
    t0, c0 = time.perf_counter(), _cpu()
    res = render(scene, backend, settings)
    wall, cpu = time.perf_counter() - t0, _cpu() - c0
    t1 = time.perf_counter()
    kinds = check_passes(res, scene.triangles, "tree")
    return {"scene": "showcase", "size": f"{size}x{size}", "format": "FP24", "mode": mode,
            "reduce": reduce, "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
            "pairs_issued": res.stats["pairs_issued"], "rays": res.stats["rays"],
            "reference_s": round(time.perf_counter() - t1, 2), "passes": kinds}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (a minute)")
    ap.add_argument("--showcase", type=int, default=128, metavar="SIZE",
                    help="size of the showcase's every-ray check (default 128; 0: skip)")
    ap.add_argument("--showcase-only", action="store_true",
                    help="only the showcase's check (the scene rows kept from --out)")
    ap.add_argument("--out", default=str(ROOT / "docs/results/certified_render.json"))
    args = ap.parse_args(argv)
    if args.showcase_only and not args.showcase:
        ap.error("--showcase-only needs a --showcase size")
    if args.quick:
        cases = [("cornell", 32), ("stanford-bunny", 32)]
    else:
        cases = [("cornell", 128), ("terrain", 128), ("stanford-bunny", 256)]
    formats = ["FP24", "FP20", "FP16"]
    from raplas_hdl.bench.cost import format_cost

    rows = []
    if args.showcase_only:
        cases = []
        if Path(args.out).exists():
            rows = json.loads(Path(args.out).read_text()).get("rows", [])
    for name, size in cases:
        scene = get_scene(name)
        settings = RenderSettings(width=size, height=size, rows=8, cols=8, shadow_rows=3,
                                  shadow_cols=3, progress=False, record_rays=True)
        for f in formats:
            fmt = parse_format(f)
            try:
                cost = format_cost(fmt, allow_json=True)
            except Exception as exc:            # no Yosys result for this format
                cost = {"error": str(exc)}
            for mode in ("paper", "certified"):
                try:
                    row = _point(scene, fmt, mode, settings)
                except ValueError as exc:       # e.g. every triangle outside the domain
                    print(f"{name:15s} {size}x{size} {f:5s} {mode:10s} not rendered: {exc}")
                    rows.append({"scene": name, "format": f, "mode": mode,
                                 "not_rendered": str(exc)})
                    continue
                row["unit_cost_device_fraction"] = cost.get("device_fraction")
                row["units_fit"] = cost.get("units_fit")
                rows.append(row)
                unc = (f"uncertain {100 * row['uncertain_fraction']:.3f} %, filtered "
                       f"{row['filtered']:,}, exact {row['exact']:,} in {row['exact_s']}s"
                       if mode == "certified" else "")
                print(f"{name:15s} {size}x{size} {f:5s} {mode:10s} wall {row['wall_s']:7.2f}s "
                      f"cpu {row['cpu_s']:7.2f}s pairs {row['pairs_issued']:>11,} "
                      f"differ from R: ids {row['tri_id_differ']}, vis "
                      f"{row['visibility_differ']}  {unc}", flush=True)
    showcase = []
    size = 32 if args.quick and args.showcase else args.showcase
    for mode, reduce in (("paper", False), ("certified", False), ("certified", True)):
        if not size:
            break
        row = _showcase(size, mode, reduce)
        showcase.append(row)
        differ = {k: (v["differ"], v["t_differ"]) for k, v in row["passes"].items()}
        print(f"showcase        {size}x{size} FP24  {mode:10s}{' reduce' if reduce else ''} "
              f"wall {row['wall_s']:7.2f}s cpu {row['cpu_s']:7.2f}s rays {row['rays']:,}; "
              f"rays differing from R (triangle or blocked, t) per type: {differ}", flush=True)
    out = {"machine": {"platform": platform.platform(), "cpus": __import__("os").cpu_count()},
           "settings": "8x8 primary bundles, 3x3 shadow bundles, FP rounding rtz",
           "rows": rows, "showcase": showcase}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {args.out}")
    bad = [r for r in rows if r["mode"] == "certified"
           and (r.get("tri_id_differ") or r.get("visibility_differ"))]
    bad += [r for r in showcase if r["mode"] == "certified"
            and any(v["differ"] or v["t_differ"] for v in r["passes"].values())]
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
