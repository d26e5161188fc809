"""Render benchmark: the Stanford bunny at 256x256 with soft shadows, per backend.

For each backend (float64 reference, FP24 golden model, optionally the RTL on a small
scene): per render stage the wall time, the CPU time inside the backend's calls, the plane
tests and the pairs, and their rates (per wall second of the stage); the render's wall and
CPU time; rays, bundles, pairs issued against brute force (every ray against every
triangle), early-out skips, hits, arithmetic events, and the model's image error against
float64 (PSNR, fraction of pixels whose nearest triangle differs).

**The limit**: the same arithmetic on flat arrays, without the render around it. After each
render, the pairs of a sample of the frame's runs (recorded as the render traces them,
:class:`raplas_hdl.bench.instrumented.RunSampler`) go through the flat pair kernel in one call (on
the render's threads):
:func:`raplas_hdl.model.ray_triangle.intersect` for the model,
:func:`raplas_hdl.host.exact.float64_intersect` for float64 (NumPy, not compiled: slower than
the render's compiled float64 pass, so no limit there); and the sampled bundles' planes
against every leaf sphere through the flat plane test
(:func:`raplas_hdl.model.plane_sphere.tester_flags`; float64: ``|n.C + p| <= r``). The
render's pairs per second over its unit stages divided by the flat kernel's is printed.
When the ``embreex`` package is importable (never a dependency), Embree's nearest-hit query
on the frame's rays (primary and shadow, no ``tmax``) is timed beside the render; otherwise
a note says it was skipped.

``--compare-modes paper,certified``: the model backend in each mode, one warm-up render each,
then ``--repeat`` rounds (default 3) of one render per mode, alternating: per mode the wall
and CPU time of every run and their medians, and each mode's median wall time over the first
mode's (the cost of the certified mode against the paper's, on the same machine in the same
minutes).

Results go to ``build/render-bench/render_bench.json`` (written after every backend, so a
long run leaves partial results), images beside it; ``--out
docs/results/render_bench.json`` updates the committed one.

Usage::

    python benchmarks/bench_render.py [--mesh SCENE|FILE] [--size 256x256] [--shadow 3x3]
        [--backends float64,model] [--format FP24] [--mode certified] [--rtl-sim icarus]
        [--limit-pairs N] [--compare-modes paper,certified [--repeat 3]] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from raplas_hdl.bench.instrumented import RunSampler  # noqa: E402
from raplas_hdl.cli.grammar import jsonable, lattice, size  # noqa: E402
from raplas_hdl.fp import parse_format  # noqa: E402
from raplas_hdl.host.backends import COUNTERS, BackendUnavailable, make_backend  # noqa: E402
from raplas_hdl.host.output import (  # noqa: E402
    compare,
    difference_image,
    format_summary,
    save_png,
)
from raplas_hdl.host.render import RenderSettings, render  # noqa: E402
from raplas_hdl.host.scenes import get_scene  # noqa: E402
from raplas_hdl.model.modes import MODES  # noqa: E402

DEFAULT_MESH = "stanford-bunny"
DEFAULT_OUT = ROOT / "build" / "render-bench" / "render_bench.json"
STAGES = ("spheres", "load", "compile", "primary cull", "primary unit", "shading",
          "shadow cull", "shadow unit", "image")


class StageMeter:
    """Wraps a backend's methods (on the instance) to measure, per render stage, the CPU and
    wall time inside them, the plane tests (host cull and unit) and the pairs; records a
    sample of the unit's runs and, on request, the frame's rays.

    The stage of a ``batch``/``cull``/``trace`` call is the primary one until the primary
    tiles have all been batched, the shadow one after that.
    """

    def __init__(self, backend, n_tiles: int, sample_pairs: int, keep_rays: bool):
        self.backend = backend
        self.n_tiles = n_tiles
        self.primary_left = n_tiles
        self.phase = "primary"
        self.stages = {s: {"cpu": 0.0, "wall": 0.0, "host_plane_tests": 0,
                           "unit_plane_tests": 0, "pairs": 0} for s in STAGES}
        self.sampler = RunSampler(sample_pairs)
        self.rays = [] if keep_rays else None
        self._warming = False
        for name, stage in (("usable", "spheres"), ("load", "load"),
                            ("warm_pass", "compile"), ("batch", None), ("cull", None),
                            ("trace", None)):
            self._wrap(name, stage)

    def _wrap(self, name, stage):
        inner = getattr(self.backend, name)

        def call(*args, **kwargs):
            if self._warming:                  # inside warm_pass: measured as a whole
                return inner(*args, **kwargs)
            if name == "warm_pass":
                self._warming = True
            st = stage or self._stage(name, args, kwargs)
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                out = inner(*args, **kwargs)
            finally:
                rec = self.stages[st]
                rec["wall"] += time.perf_counter() - t0
                rec["cpu"] += time.process_time() - c0
                if name == "warm_pass":
                    self._warming = False
            if not self._warming:
                self._count(name, st, args, out)
            return out

        setattr(self.backend, name, call)

    def _stage(self, name, args, kwargs):
        if self._warming:
            return "compile"
        if name == "batch" and self.phase == "primary" and self.primary_left <= 0:
            self.phase = "shadow"
        return f"{self.phase} {'unit' if name == 'trace' else 'cull'}"

    def _count(self, name, st, args, out):
        rec = self.stages[st]
        if name == "batch":
            if self.phase == "primary":
                self.primary_left -= out.n_bundles
            if self.rays is not None:
                g = out.geometry
                o = np.repeat(np.asarray(args[0], np.float64).reshape(-1, 3), out.n_rays,
                              axis=0)
                self.rays.append((o, g["directions"].reshape(-1, 3),
                                  out.enable.reshape(-1).copy()))
        elif name == "cull":
            rec["host_plane_tests"] += int(out.plane_tests)
        elif name == "trace":
            rec["unit_plane_tests"] += int(out[:, COUNTERS.index("plane_tests")].sum())
            rec["pairs"] += int(out[:, COUNTERS.index("pairs_issued")].sum())
            batch, run_b, run_start, run_sph = args[:4]
            self.sampler.add(batch, np.asarray(run_b, np.int64),
                             np.asarray(run_start, np.int64), np.asarray(run_sph, np.int64),
                             out)

    def table(self, timings: dict) -> dict:
        """Per stage: the render's wall time, the backend's CPU and wall time in it, plane
        tests, pairs and their rates per wall second of the stage."""
        out = {}
        for s in STAGES:
            r = dict(self.stages[s])
            wall = float(timings.get(s, 0.0))
            tests = r["host_plane_tests"] + r["unit_plane_tests"]
            r.update(stage_wall=wall, plane_tests=tests,
                     plane_tests_per_s=tests / wall if wall > 0 and tests else 0.0,
                     pairs_per_s=r["pairs"] / wall if wall > 0 and r["pairs"] else 0.0)
            out[s] = r
        return out


def flat_limit(backend, meter: StageMeter, max_bundles: int = 64) -> dict:
    """The flat kernels on the frame's sampled pairs and planes (module docstring)."""
    from raplas_hdl.host.exact import float64_intersect
    from raplas_hdl.model.plane_sphere import tester_flags
    from raplas_hdl.model.ray_triangle import intersect

    model = backend.name != "float64"
    sc = backend.scene
    o, d, tri = [], [], []
    bundles = []
    for sub, k, _, r in meter.sampler.streams(backend):
        if len(bundles) < max_bundles:
            bundles.append((sub, k))
        if not r.ray_id.size:
            continue
        R = sub.n_rays
        o.append(np.broadcast_to(sub.ro[k], (r.ray_id.size, 3)))
        d.append(sub.rd[k * R + r.ray_id])
        tri.append(r.tri_id)
    out = {"kernel_pairs": "raplas_hdl.model.ray_triangle.intersect" if model
           else "raplas_hdl.host.exact.float64_intersect (NumPy, not compiled: no limit)",
           "kernel_planes": "raplas_hdl.model.plane_sphere.tester_flags" if model
           else "NumPy |n.C + p| <= r"}
    if tri:
        o, d, tri = np.concatenate(o), np.concatenate(d), np.concatenate(tri)
        args = [np.ascontiguousarray(o), np.ascontiguousarray(d)]
        if model:
            args += [sc.v0[tri], sc.e1[tri], sc.e2[tri], sc.nn[tri]]
            run = lambda: intersect(*args, backend.fmt, mode=backend.mode)  # noqa: E731
        else:
            tv = backend.tris[tri]
            args += [tv[:, 0], tv[:, 1], tv[:, 2]]
            run = lambda: float64_intersect(*args)  # noqa: E731
        run()                                  # compile / warm
        t0, c0 = time.perf_counter(), time.process_time()
        run()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        out.update(pairs=int(tri.size), pairs_wall=wall, pairs_cpu=cpu,
                   pairs_per_s=tri.size / wall, pairs_per_cpu_s=tri.size / cpu if cpu else 0.0)
    def planes(sub, k):
        P = sub.n_planes
        pn, pp = sub.pn[k * P:(k + 1) * P], sub.pp[k * P:(k + 1) * P]
        if model:
            tester_flags(pn, pp, sc.sc, sc.sr, backend.fmt)
        else:
            np.abs(sc.sc @ pn.T + pp[None, :]) <= sc.sr[:, None]
        return P * len(sc.sr)

    tests = 0
    t_wall = t_cpu = 0.0
    if bundles:
        planes(*bundles[0])                    # compile / warm
        t0, c0 = time.perf_counter(), time.process_time()
        for sub, k in bundles:
            tests += planes(sub, k)
        t_wall, t_cpu = time.perf_counter() - t0, time.process_time() - c0
    if tests:
        out.update(plane_tests=tests, planes_wall=t_wall, planes_cpu=t_cpu,
                   plane_tests_per_s=tests / t_wall,
                   plane_tests_per_cpu_s=tests / t_cpu if t_cpu else 0.0)
    return out


def embree_limit(meter: StageMeter, tris: np.ndarray) -> dict:
    """Embree's nearest-hit query on the frame's rays, when ``embreex`` is importable."""
    try:
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh
    except ImportError as exc:
        return {"skipped": f"embreex is not importable ({exc}): Embree not compared "
                           "(pip install embreex to compare; never a dependency)"}
    if not meter.rays:
        return {"skipped": "no rays recorded"}
    o = np.concatenate([r[0] for r in meter.rays])
    d = np.concatenate([r[1] for r in meter.rays])
    en = np.concatenate([r[2] for r in meter.rays])
    o, d = np.ascontiguousarray(o[en], np.float32), np.ascontiguousarray(d[en], np.float32)
    t0, c0 = time.perf_counter(), time.process_time()
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(tris, np.float32))
    build = time.perf_counter() - t0
    t1, c1 = time.perf_counter(), time.process_time()
    ids = scene.run(o, d)
    wall, cpu = time.perf_counter() - t1, time.process_time() - c1
    return {"rays": int(len(o)), "build_seconds": build, "seconds": wall, "cpu_seconds": cpu,
            "setup_cpu_seconds": c1 - c0, "rays_per_s": len(o) / wall,
            "hits": int(np.count_nonzero(np.asarray(ids) >= 0)),
            "query": "nearest hit, tnear 0, no tmax (shadow rays too)"}


def compare_modes(scene, settings, fmt, modes, repeat) -> dict:
    """The model backend's render in each of ``modes``, alternating (module docstring)."""
    backends = {mode: make_backend("model", fmt, mode=mode) for mode in modes}
    for mode, backend in backends.items():            # warm: kernels compiled or loaded
        render(scene, backend, settings)
    runs = []
    for i in range(repeat):
        for mode, backend in backends.items():
            load = os.getloadavg()[0]
            t0, c0 = time.perf_counter(), time.process_time()
            res = render(scene, backend, settings)
            runs.append({"round": i, "mode": mode, "wall_seconds": time.perf_counter() - t0,
                         "cpu_seconds": time.process_time() - c0, "load_before": load,
                         "pairs_issued": res.stats["pairs_issued"]})
            print(f"  round {i + 1}/{repeat} {mode:12s} wall {runs[-1]['wall_seconds']:6.2f} s "
                  f"CPU {runs[-1]['cpu_seconds']:6.2f} s (load {load:.2f})", flush=True)
    med = {mode: float(np.median([r["wall_seconds"] for r in runs if r["mode"] == mode]))
           for mode in modes}
    cpu = {mode: float(np.median([r["cpu_seconds"] for r in runs if r["mode"] == mode]))
           for mode in modes}
    first = modes[0]
    out = {"modes": list(modes), "repeat": repeat, "runs": runs, "median_wall_seconds": med,
           "median_cpu_seconds": cpu,
           "wall_ratio_to_" + first: {mode: med[mode] / med[first] for mode in modes}}
    for mode in modes:
        print(f"  {mode:12s} median wall {med[mode]:6.2f} s, CPU {cpu[mode]:6.2f} s: "
              f"{med[mode] / med[first]:.2f}x {first}", flush=True)
    return out


@contextmanager
def _threads(n):
    import numba

    old = numba.get_num_threads()
    if n is not None:
        numba.set_num_threads(max(1, min(n, numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(old)


def _entry(result):
    st = result.stats
    return {"seconds": sum(result.timings.values()), "timings": result.timings,
            "rays": st["rays"], "bundles": st["bundles"], "spheres": st["spheres"],
            "plane_tests": st["plane_tests"], "pairs_issued": st["pairs_issued"],
            "brute_force_pairs": st["brute_force_pairs"],
            "pair_fraction": st["pair_fraction"],
            "early_out_pairs_skipped": st["early_out_pairs_skipped"], "hits": st["hits"],
            "events": st["events"], "hierarchy": st["hierarchy"], "stats": st}


def _stage_lines(entry) -> list[str]:
    lines = [f"  {'stage':13s} {'wall s':>8s} {'CPU s*':>8s} {'plane tests':>13s} "
             f"{'tests/s':>10s} {'pairs':>12s} {'pairs/s':>10s}"]
    for s, r in entry["stages"].items():
        if not (r["stage_wall"] or r["cpu"]):
            continue
        lines.append(f"  {s:13s} {r['stage_wall']:8.2f} {r['cpu']:8.2f} {r['plane_tests']:13,} "
                     f"{r['plane_tests_per_s']:10.3g} {r['pairs']:12,} {r['pairs_per_s']:10.3g}")
    lines.append(f"  (* CPU inside the backend's calls, all threads; render: wall "
                 f"{entry['wall_seconds']:.2f} s, CPU {entry['cpu_seconds']:.2f} s)")
    lim = entry["limit"]
    if "pairs_per_s" in lim:
        lines.append(f"  limit: {lim['kernel_pairs']} on {lim['pairs']:,} of the frame's "
                     f"pairs: {lim['pairs_per_s']:.3g} pairs/s (CPU {lim['pairs_per_cpu_s']:.3g}"
                     f"/s); the render's unit stages: {entry['unit_pairs_per_s']:.3g} pairs/s "
                     f"= {entry['ratio_to_flat_kernel']:.2f} x the flat kernel")
    if "plane_tests_per_s" in lim:
        lines.append(f"  limit: {lim['kernel_planes']} on {lim['plane_tests']:,} plane tests: "
                     f"{lim['plane_tests_per_s']:.3g} tests/s (CPU "
                     f"{lim['plane_tests_per_cpu_s']:.3g}/s)")
    emb = entry.get("embree", {})
    if "skipped" in emb:
        lines.append(f"  Embree: skipped: {emb['skipped']}")
    elif emb:
        lines.append(f"  Embree ({emb['query']}): {emb['rays']:,} rays in {emb['seconds']:.3f} s "
                     f"= {emb['rays_per_s']:.3g} rays/s; the render: "
                     f"{entry['rays_per_s']:.3g} rays/s = {entry['ratio_to_embree']:.3g} x")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--mesh", default=DEFAULT_MESH,
                   help="a scene (cornell, ...), a shipped mesh's name or a mesh file "
                        "(default stanford-bunny)")
    p.add_argument("--size", default="256x256")
    p.add_argument("--tile", default="8x8")
    p.add_argument("--shadow", default="3x3")
    p.add_argument("--backends", default="float64,model")
    p.add_argument("--format", default="FP24")
    p.add_argument("--mode", default="certified", choices=MODES,
                   help="mode of the model and rtl backends (default certified, the render's "
                        "default; paper: the paper's own inequalities)")
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--threads", type=int, default=None,
                   help="threads of the compiled passes (default: every core)")
    p.add_argument("--limit-pairs", type=int, default=2_000_000,
                   help="pairs of the frame sampled for the flat kernel (default 2,000,000)")
    p.add_argument("--rtl-sim", default=None, choices=("icarus", "verilator"),
                   help="also time the rtl backend on a small scene (soup, 16x16)")
    p.add_argument("--compare-modes", default=None, metavar="MODES",
                   help="comma-separated modes of the model backend to time alternately "
                        "(e.g. paper,certified; the first is the reference)")
    p.add_argument("--repeat", type=int, default=3,
                   help="rounds of --compare-modes (default 3)")
    p.add_argument("--out", default=str(DEFAULT_OUT))
    args = p.parse_args(argv)
    modes = args.compare_modes.split(",") if args.compare_modes else []
    bad = [m for m in modes if m not in MODES]
    if bad or (args.compare_modes is not None and len(modes) < 2):
        p.error(f"--compare-modes takes two or more of {', '.join(MODES)}, not "
                f"{args.compare_modes!r}")
    if args.repeat < 1:
        p.error("--repeat must be at least 1")

    try:    # before any work: a scene by name (cornell, ...), a shipped mesh or a file
        scene = get_scene(args.mesh)
    except (ValueError, OSError) as exc:
        print(f"bench_render: {exc}", file=sys.stderr)
        return 2
    w, h = size(args.size)
    rows, cols = lattice(args.tile, "--tile")
    sr, sc = lattice(args.shadow, "--shadow")
    fmt = parse_format(args.format)
    settings = RenderSettings(w, h, rows, cols, sr, sc, batch_spheres=args.batch,
                              threads=args.threads)
    n_tiles = len(scene.camera.tiles(w, h, rows, cols))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        import embreex  # noqa: F401
        have_embree = True
    except ImportError:
        have_embree = False
        print("bench_render: embreex is not importable: the Embree comparison is skipped "
              "(optional; pip install embreex)", flush=True)
    report = {"scene": scene.name, "triangles": scene.n_triangles, "size": f"{w}x{h}",
              "tile": f"{rows}x{cols}", "shadow": f"{sr}x{sc}", "format": str(fmt),
              "mode": args.mode, "machine": platform.platform(), "cpus": os.cpu_count(),
              "command": " ".join(["python", "benchmarks/bench_render.py"] + (argv or
                                                                              sys.argv[1:])),
              "backends": {}}
    results = {}
    if modes:
        report["compare_modes"] = compare_modes(scene, settings, fmt, modes, args.repeat)
        out.write_text(json.dumps(jsonable(report), indent=2))
    for name in (args.backends.split(",") if args.backends else []):
        backend = make_backend(name, fmt, mode=args.mode,
                               **({"sim": args.rtl_sim or "verilator"} if name == "rtl" else {}))
        meter = StageMeter(backend, n_tiles, args.limit_pairs, keep_rays=have_embree)
        load0 = os.getloadavg()
        t0, c0 = time.perf_counter(), time.process_time()
        res = render(scene, backend, settings)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        results[name] = res
        entry = _entry(res)
        entry.update(wall_seconds=wall, cpu_seconds=cpu,
                     load_average={"before": load0, "after": os.getloadavg()},
                     stages=meter.table(res.timings))
        unit_t = res.timings.get("primary unit", 0.0) + res.timings.get("shadow unit", 0.0)
        entry["unit_pairs_per_s"] = res.stats["pairs_issued"] / unit_t if unit_t else 0.0
        entry["rays_per_s"] = res.stats["rays"] / wall
        if name != "rtl":
            with _threads(args.threads):       # the flat kernels on the render's threads
                entry["limit"] = flat_limit(backend, meter)
            lp = entry["limit"].get("pairs_per_s")
            entry["ratio_to_flat_kernel"] = entry["unit_pairs_per_s"] / lp if lp else None
            entry["embree"] = (embree_limit(meter, scene.triangles) if have_embree else
                               {"skipped": "embreex is not importable"})
            if "rays_per_s" in entry["embree"]:
                entry["ratio_to_embree"] = entry["rays_per_s"] / entry["embree"]["rays_per_s"]
        else:
            entry["limit"] = {}
        if name != "float64" and "float64" in results:
            entry["vs_float64"] = compare(res, results["float64"])
            save_png(difference_image(res, results["float64"]),
                     out.parent / f"render_bench_{scene.name}_"
                     f"{'' if name == 'model' else name + '_'}diff.png", linear=False)
        if name == "rtl" and "model" in results:
            entry["equal_to_model"] = bool(
                (res.tri_id == results["model"].tri_id).all()
                and (res.image == results["model"].image).all()
                and (res.visibility == results["model"].visibility).all())
        report["backends"][backend.describe()] = entry
        save_png(res.image, out.parent / f"render_bench_{scene.name}_{name}.png")
        print(format_summary(res, entry.get("vs_float64")), flush=True)
        print("\n".join(_stage_lines(entry)), flush=True)
        out.write_text(json.dumps(jsonable(report), indent=2))
    if args.rtl_sim and "rtl" not in args.backends.split(","):
        small = get_scene("soup", n=24)
        st = RenderSettings(16, 16, 4, 4, 0, 0, progress=False)
        try:
            rtl = make_backend("rtl", fmt, mode=args.mode, sim=args.rtl_sim)
            t0 = time.perf_counter()
            r_rtl = render(small, rtl, st)
            t_rtl = time.perf_counter() - t0
            t0 = time.perf_counter()
            r_mod = render(small, make_backend("model", fmt, mode=args.mode), st)
            t_mod = time.perf_counter() - t0
            report["rtl_small"] = {"scene": "soup n=24, 16x16, no shadows",
                                   "simulator": args.rtl_sim, "rtl_seconds": t_rtl,
                                   "model_seconds": t_mod,
                                   "equal_to_model": bool((r_rtl.tri_id == r_mod.tri_id).all()
                                                          and (r_rtl.image == r_mod.image).all())}
        except BackendUnavailable as exc:
            report["rtl_small"] = {"unavailable": str(exc)}
        out.write_text(json.dumps(jsonable(report), indent=2))
    if report["backends"]:
        bf = next(iter(report["backends"].values()))
        print(f"pairs issued / brute force: {bf['pair_fraction']:.5f}")
    out.write_text(json.dumps(jsonable(report), indent=2))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
