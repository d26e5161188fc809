"""Cold start: what each compiled kernel group costs from an empty numba cache.

Each measurement runs in a fresh Python process with its own empty ``NUMBA_CACHE_DIR``, so
nothing is loaded from a previous compile; a second process then loads the same cache
(the warm start every later command, pytest worker and campaign worker pays). The groups
run in first-use order within one process, so a group's time is what it adds over the
groups before it (the scalar FP kernels are compiled with the first group that calls
them). Also timed end to end: the first ``raplas-hdl render --backend model`` of cornell at
32x32 from an empty cache, and the same command again, in each mode of ``--modes`` (default
paper and certified; each first render with an empty cache of its own).

CPU time is reported beside wall time (the machine may be shared). Results go to
``build/bench/cold_start.json`` unless ``--out`` says otherwise.

    python benchmarks/bench_cold_start.py [--format FP24/rtz] [--modes paper,certified]
        [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# One child process: compile the groups in order, print JSON lines of timings.
_CHILD = r"""
import json, sys, time
import numpy as np
spec = sys.argv[1]

def clock():
    return time.process_time(), time.perf_counter()

t_imp = clock()
from raplas_hdl.fp.format import parse_format
from raplas_hdl.fp import model as fpm
fmt = parse_format(spec)
from raplas_hdl.model import plane_sphere, ray_triangle
import raplas_hdl.engine.kernels
t0 = clock()
print(json.dumps({"group": "import", "cpu": t0[0] - t_imp[0], "wall": t0[1] - t_imp[1]}),
      flush=True)

def group(name, fn):
    global t0
    fn()
    t1 = clock()
    print(json.dumps({"group": name, "cpu": t1[0] - t0[0], "wall": t1[1] - t0[1]}),
          flush=True)
    t0 = clock()

rng = np.random.default_rng(0)
x = rng.normal(size=64)
bits = fpm.encode(x, fmt)
big = np.resize(bits, 1 << 16)

group("fp: encode, decode", lambda: (fpm.encode(x, fmt, direction="up"), fpm.decode(bits, fmt)))
group("fp: add, sub, mul, compare (generic loops)",
      lambda: (fpm.add(bits, bits, fmt), fpm.sub(bits, bits, fmt), fpm.mul(bits, bits, fmt),
               fpm.le(bits, bits, fmt), fpm.lt(bits, bits, fmt), fpm.abs_le(bits, bits, fmt),
               fpm.neg(bits, fmt)))
group("fp: add, mul (per-format block kernels)",
      lambda: (fpm.add(big, big, fmt, flags=True), fpm.mul(big, big, fmt, flags=True)))
v = [fpm.encode(rng.normal(size=(256, 3)), fmt) for _ in range(6)]
group("unit models: plane-sphere tester",
      lambda: plane_sphere.tester_flags(v[0], v[1][:, 0], v[2], v[3][:, 0], fmt))
group("unit models: ray-triangle, paper",
      lambda: ray_triangle.intersect(*v, fmt, "paper"))
group("unit models: ray-triangle, conservative",
      lambda: ray_triangle.intersect(*v, fmt, "conservative"))
group("unit models: ray-triangle, certified",
      lambda: ray_triangle.intersect(*v, fmt, "certified"))

def engine(mode):
    from raplas_hdl.host.backends import make_backend
    from raplas_hdl.host.render import RenderSettings, render
    from raplas_hdl.host.scenes import get_scene
    st = RenderSettings(width=8, height=8, shadow_rows=2, shadow_cols=2, progress=False)
    render(get_scene("cornell"), make_backend("model", fmt, mode=mode), st)

group("engine: model passes, paper", lambda: engine("paper"))
group("engine: model passes, conservative", lambda: engine("conservative"))
group("engine: model passes, certified", lambda: engine("certified"))

def f64():
    from raplas_hdl.host.backends import make_backend
    from raplas_hdl.host.render import RenderSettings, render
    from raplas_hdl.host.scenes import get_scene
    render(get_scene("cornell"), make_backend("float64"),
           RenderSettings(width=8, height=8, shadow_rows=2, shadow_cols=2, progress=False))

group("engine: float64 passes", f64)
"""


def _child(spec: str, cache: str) -> list[dict]:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    out = subprocess.run([sys.executable, "-c", _CHILD, spec], env=env, check=True,
                         capture_output=True, text=True, cwd=ROOT)
    return [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]


def _render(cache: str, png: str, mode: str) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    cmd = [sys.executable, "-c", "import sys; from raplas_hdl.cli import main; "
           "sys.exit(main(sys.argv[1:]))", "render", "--scene", "cornell", "--size", "32x32",
           "--backend", "model", "--mode", mode, "--no-progress", "-o", png]
    c0 = os.times()
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, capture_output=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    c1 = os.times()
    return {"wall": wall, "cpu": (c1.children_user - c0.children_user)
            + (c1.children_system - c0.children_system)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--format", default="FP24/rtz", help="format of the model kernels "
                    "(default FP24/rtz)")
    ap.add_argument("--modes", default="paper,certified",
                    help="modes of the first-render rows (default paper,certified)")
    ap.add_argument("--out", default=str(ROOT / "build" / "bench" / "cold_start.json"),
                    help="JSON results (default build/bench/cold_start.json)")
    args = ap.parse_args(argv)
    res = {"machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                       "python": platform.python_version(),
                       "load_before": os.getloadavg()}, "format": args.format}
    with tempfile.TemporaryDirectory() as tmp:
        cold = _child(args.format, str(Path(tmp) / "groups"))
        warm = _child(args.format, str(Path(tmp) / "groups"))
        res["groups"] = [{"group": c["group"], "cold_cpu": c["cpu"], "cold_wall": c["wall"],
                          "warm_cpu": w["cpu"], "warm_wall": w["wall"]}
                         for c, w in zip(cold, warm)]
        res["first_render"] = {}
        for mode in args.modes.split(","):
            cache, png = str(Path(tmp) / f"render-{mode}"), str(Path(tmp) / "a.png")
            res["first_render"][mode] = {"cold": _render(cache, png, mode),
                                         "warm": _render(cache, png, mode)}
    res["machine"]["load_after"] = os.getloadavg()
    print(f"cold start, {args.format}, {os.cpu_count()} cores, load "
          f"{res['machine']['load_before'][0]:.2f}")
    print(f"{'group':45s} {'cold cpu':>9s} {'cold wall':>9s} {'warm cpu':>9s} {'warm wall':>9s}")
    for g in res["groups"]:
        print(f"{g['group']:45s} {g['cold_cpu']:9.2f} {g['cold_wall']:9.2f} "
              f"{g['warm_cpu']:9.2f} {g['warm_wall']:9.2f}")
    tot = sum(g["cold_cpu"] for g in res["groups"])
    print(f"{'total':45s} {tot:9.2f}")
    for mode, runs in res["first_render"].items():
        for k, r in runs.items():
            print(f"{'first render, ' + mode + ', ' + k + ' cache':45s} cpu {r['cpu']:.2f} s, "
                  f"wall {r['wall']:.2f} s")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
