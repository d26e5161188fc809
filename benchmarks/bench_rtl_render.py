"""RTL render speed: unit cycles per second of the co-simulated render against the limit.

For each simulator the scene is rendered through ``--backend rtl`` (one live simulation per
unit configuration: the primary tile and the shadow bundle, the scene loaded once per
session through the unit's write port at full rate, jobs fed round after round) and through
the golden model; image, nearest triangle per pixel and visibility must be equal bit for
bit. The sessions record their op streams; the limit is the same simulator model (for
Verilator: the plain C++ main, the cocotb build's flags, no tracing) replaying those op
streams from a file in one go, with no host in the loop, one after another. Reported per
simulator: clock cycles simulated (over every instance), render wall time, unit cycles per
second of the render (over the whole render and over the time spent in RTL rounds) and of
the replay, and their ratio (target: at least 0.5). With ``--instances 2`` (the rtl
backend's default on two cores) two simulations of each configuration share each round, so
the render's cycles per second can exceed one replay's.

Usage::

    python benchmarks/bench_rtl_render.py [--scene stanford-bunny] [--size 32x32]
        [--icarus-size 8x8] [--sims verilator,icarus] [--out build/bench-rtl-render]

Writes ``<out>/rtl_render.json`` and prints a table. The issue's baseline (per-cycle cocotb
driver, one cocotb run per pass reloading the scene) took 3 min 59 s for the primary pass
alone of the bunny at 32x32 under Verilator, and about 4 minutes per shadow round.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from raplas_hdl.fp import FP24
from raplas_hdl.host.backends import make_backend
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene
from raplas_hdl.sim.drive.unit_harness import replay

BASELINE_PRIMARY_S = 239.0   # issue 12: bunny 32x32, Verilator, per-cycle driver, primary pass


def _size(text):
    w, h = text.lower().split("x")
    return int(w), int(h)


def _same(a, b) -> bool:
    """Equal bit for bit (NaN where the other has NaN counts as equal)."""
    try:
        np.testing.assert_array_equal(a, b)
    except AssertionError:
        return False
    return True


def _cpu() -> float:
    """CPU seconds of this process and its finished children (the simulators)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def bench(sim, scene_name, size, shadow, mode, model_cache, instances=None):
    scene = get_scene(scene_name)
    st = RenderSettings(*size, rows=8, cols=8, shadow_rows=shadow[0], shadow_cols=shadow[1],
                        progress=False)
    key = (scene_name, size)
    if key not in model_cache:
        model_cache[key] = render(scene, make_backend("model", FP24, mode=mode), st)
    model = model_cache[key]
    be = make_backend("rtl", FP24, mode=mode, sim=sim)
    if instances is not None:
        be.instances = instances
    with tempfile.TemporaryDirectory(prefix="raplas-bench-rtl-") as tmp:
        be.record_dir = tmp
        load0 = os.getloadavg()
        t0, c0 = time.perf_counter(), _cpu()
        rtl = render(scene, be, st)
        wall = time.perf_counter() - t0
        load1 = os.getloadavg()
        stats = {f"{c.rows}x{c.cols}": dict(v) for c, v in be.session_stats.items()}
        configs = {f"{c.rows}x{c.cols}": c for c in be.session_stats}
        be.close()
        cpu = _cpu() - c0      # the simulators' CPU counts once they have exited
        # certified: the unit's certain hits are those of its bound variant (exp), the
        # model pass's of lead3 (docs/certified-render.md): every other counter must agree
        skip = ("hits",) if mode == "certified" else ()
        unit = {k: v for k, v in rtl.stats["unit"].items()
                if not k.startswith(("_", "cycles")) and k not in skip}
        want = {k: v for k, v in model.stats["unit"].items() if k not in skip}
        equal = bool(_same(rtl.tri_id, model.tri_id) and _same(rtl.image, model.image)
                     and _same(rtl.visibility, model.visibility) and _same(rtl.t, model.t)
                     and unit == want)
        limit = {}
        for name, cfg in configs.items():
            parts = [replay(sim, cfg, Path(tmp) / f"{name}.{k}.ops")
                     for k in range(stats[name]["instances"])]
            limit[name] = {"cycles": sum(p["cycles"] for p in parts),
                           "wall_s": sum(p["wall_s"] for p in parts),
                           "beats_bytes": sum(p["beats_bytes"] for p in parts)}
    cycles = sum(v["cycles"] for v in stats.values())
    rounds_s = sum(v["rounds_s"] + v["load_s"] for v in stats.values())
    lim_cycles = sum(v["cycles"] for v in limit.values())
    lim_s = sum(v["wall_s"] for v in limit.values())
    out = {
        "simulator": sim, "scene": scene_name, "size": list(size), "shadow": list(shadow),
        "mode": mode, "instances": be.instances,
        "equal_to_model": equal, "render_s": wall, "render_cpu_s": cpu,
        "load_before": list(load0), "load_after": list(load1), "sessions": stats,
        "replay": limit,
        "cycles": cycles, "rtl_s": rounds_s,
        "render_cycles_per_s": cycles / wall, "rtl_cycles_per_s": cycles / rounds_s,
        "limit_cycles": lim_cycles, "limit_s": lim_s, "limit_cycles_per_s": lim_cycles / lim_s,
        "pairs_issued": int(rtl.stats["unit"].get("pairs_issued", 0)),
    }
    out["ratio_render"] = out["render_cycles_per_s"] / out["limit_cycles_per_s"]
    out["ratio_rtl"] = out["rtl_cycles_per_s"] / out["limit_cycles_per_s"]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="stanford-bunny")
    ap.add_argument("--size", type=_size, default=(32, 32))
    ap.add_argument("--icarus-size", type=_size, default=(8, 8))
    ap.add_argument("--shadow", type=_size, default=(3, 3))
    ap.add_argument("--mode", default="certified",
                    help="render mode (default certified, the render's default; or paper)")
    ap.add_argument("--sims", default="verilator,icarus")
    ap.add_argument("--instances", type=int, default=None,
                    help="live simulations per unit configuration (default: the backend's)")
    ap.add_argument("--out", type=Path, default=REPO / "build" / "bench-rtl-render")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    results, cache = [], {}
    for sim in args.sims.split(","):
        size = args.icarus_size if sim == "icarus" else args.size
        r = bench(sim, args.scene, size, args.shadow, args.mode, cache, args.instances)
        results.append(r)
        (args.out / "rtl_render.json").write_text(json.dumps(results, indent=1))
        print(f"{sim:9s} {args.scene} {size[0]}x{size[1]} {args.mode} x{r['instances']}: "
              f"equal={r['equal_to_model']} "
              f"render {r['render_s']:.1f} s (CPU {r['render_cpu_s']:.1f} s, load "
              f"{r['load_before'][0]:.2f}), {r['cycles']:,} cycles, "
              f"{r['render_cycles_per_s']:,.0f} cyc/s (render), "
              f"{r['rtl_cycles_per_s']:,.0f} cyc/s (RTL rounds), "
              f"limit {r['limit_cycles_per_s']:,.0f} cyc/s; ratio {r['ratio_render']:.2f} "
              f"(render) {r['ratio_rtl']:.2f} (rounds)", flush=True)
        if sim == "verilator" and args.scene == "stanford-bunny" and tuple(size) == (32, 32):
            print(f"          before: {BASELINE_PRIMARY_S:.0f} s for the primary pass alone; "
                  f"after: {r['render_s']:.1f} s for the whole render")
    return 0 if all(r["equal_to_model"] for r in results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
