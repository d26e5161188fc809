"""Pairs per cycle one culling array sustains, with 1 to 4 ray-triangle lanes (issue 15.2).

Each scene is rendered through the FP24 golden model (``paper`` mode, 4x4 primary bundles,
4x4 shadow bundles); every run the unit is given (primary and shadow passes, early-out
rounds, in the renderer's order) is recorded, and the cycle model
(:mod:`raplas_hdl.model.throughput`, checked against the RTL's ``cycles`` counter in
``tests/rtl/unit/test_lanes.py``) runs them back to back, the host never the limit, for
``testers`` 8 and 4 and ``lanes`` 1 to 4:

- ``pairs_per_cycle``: the unit as built (``results="stream"``: every pair a result beat,
  one beat per cycle through the lanes' merger);
- ``pairs_per_cycle_lane_results``: the same array and lanes if each lane consumed its own
  results (a reduction per lane, not built): what ``K`` lanes could sustain behind one
  array.

``pairs`` is the model's ``pairs_issued`` counter summed over the runs (checked equal to
the profile's). Rows go to ``docs/results/throughput.json`` (``--out``) and are printed as
a table.

Sizes: the bench's (``raplas-hdl bench``): 128x128 for the procedural scenes, 256x256 for
meshes and scene files.

Usage: ``python benchmarks/bench_throughput.py [--size 128x128] [--mesh-size 256x256]
[--scenes a,b]
[--out docs/results/throughput.json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from raplas_hdl.fp import FP24  # noqa: E402
from raplas_hdl.host.backends import COUNTERS, ModelBackend  # noqa: E402
from raplas_hdl.host.render import RenderSettings, render  # noqa: E402
from raplas_hdl.host.scenes import SCENES as PROCEDURAL  # noqa: E402
from raplas_hdl.host.scenes import get_scene  # noqa: E402
from raplas_hdl.model.config import UnitConfig  # noqa: E402
from raplas_hdl.model.throughput import Timing, profile_arrays, simulate  # noqa: E402

SCENES = ("showcase", "cornell", "teapot", "stanford-bunny")
TESTERS = (8, 4)
LANES = (1, 2, 3, 4)
DEFAULT_OUT = ROOT / "build" / "throughput" / "throughput.json"
PAIRS = COUNTERS.index("pairs_issued")
ROWS = COLS = 4


class RecordingBackend(ModelBackend):
    """The model backend; every run a traced pass gives the unit is kept (its bundle's
    planes, its spheres, the enable bits as they were) for the cycle model."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.runs = []
        self.pairs = 0
        self.other_pairs = 0

    def warm_pass(self, *args, **kwargs):
        """As the model's; the throw-away pass's runs are not kept."""
        kept, pairs = len(self.runs), self.pairs
        seconds = super().warm_pass(*args, **kwargs)
        del self.runs[kept:]
        self.pairs = pairs
        return seconds

    def trace(self, batch, run_b, run_start, run_sph, *args, **kwargs):
        ctr = super().trace(batch, run_b, run_start, run_sph, *args, **kwargs)
        if (batch.rows, batch.cols) != (ROWS, COLS):
            # another unit configuration (a scene file's glossy or ambient-occlusion
            # bundles): not this unit's runs
            self.other_pairs += int(np.asarray(ctr)[:, PAIRS].sum())
            return ctr
        sm = self.scene_memory
        P = batch.n_planes
        for u, b in enumerate(np.asarray(run_b, np.int64)):
            ids = np.asarray(run_sph[run_start[u]:run_start[u + 1]], np.int64)
            self.runs.append((batch.pn[b * P:(b + 1) * P], batch.pp[b * P:(b + 1) * P],
                              sm.centres[ids], sm.radii[ids], sm.tri_counts[ids],
                              batch.enable[b].copy(), bool(batch.keep_all[b]),
                              (id(batch), int(b))))
        self.pairs += int(np.asarray(ctr)[:, PAIRS].sum())
        return ctr


def timing(cfg: UnitConfig) -> Timing:
    """The cycle model's constants from the RTL's components of ``cfg``."""
    from raplas_hdl.rtl.intersection import IntersectionUnit

    unit = IntersectionUnit(cfg)
    unit._MustUse__silence = True                     # built only to be inspected
    return unit.cycle_timing()


def measure(scene_name: str, size, threads=None):
    """Render ``scene_name`` and return the profile of its runs, the model's pairs and the
    unit configuration (4x4, FP24, paper)."""
    scene = get_scene(scene_name)
    be = RecordingBackend(FP24, "paper")
    settings = RenderSettings.for_scene(scene, width=size[0], height=size[1], rows=ROWS,
                                        cols=COLS, shadow_rows=ROWS, shadow_cols=COLS,
                                        progress=False, threads=threads)
    t0 = time.process_time()
    render(scene, be, settings)
    cfg = be.config(ROWS, COLS)
    profile = profile_arrays(cfg, be.runs)
    if profile.pairs != be.pairs:
        raise AssertionError(f"{scene_name}: the profile has {profile.pairs} pairs, the "
                             f"model's counters {be.pairs}")
    return profile, cfg, time.process_time() - t0, be.other_pairs


def rows_of(scene_name, profile, cfg):
    import dataclasses

    out = []
    for testers in TESTERS:
        c = dataclasses.replace(cfg, testers=testers)
        tm = timing(c)
        for lanes in LANES:
            row = {"scene": scene_name, "format": str(cfg.fmt), "rows": cfg.rows,
                   "cols": cfg.cols, "testers": testers, "lanes": lanes,
                   "pairs": profile.pairs}
            for results, suffix in (("stream", ""), ("lanes", "_lane_results")):
                t_cmd, t_last = simulate(profile, c, tm, lanes=lanes, results=results)
                cycles = int(t_last.max() - t_cmd[0])
                row["cycles" + suffix] = cycles
                row["pairs_per_cycle" + suffix] = round(profile.pairs / cycles, 4)
            row.update(runs=profile.n_runs, spheres=profile.spheres)
            out.append(row)
    return out


def write(path, sizes, meta, rows, wall):
    """The JSON (after every scene: a long run leaves its finished scenes)."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    doc = {"image": {k: f"{v[0]}x{v[1]}" for k, v in sizes.items()},
           "bundles": f"{ROWS}x{COLS} primary, {ROWS}x{COLS} shadow", "mode": "paper",
           "model": "raplas_hdl.model.throughput (runs back to back, host never the limit)",
           "cpus": os.cpu_count(), "wall_s": round(wall, 1), "scenes": meta, "rows": rows}
    out.write_text(json.dumps(doc, indent=1) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="128x128", help="procedural scenes' image size")
    ap.add_argument("--mesh-size", default="256x256", help="meshes' and scene files' size")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--out", default=str(DEFAULT_OUT))
    args = ap.parse_args(argv)
    sizes = {k: tuple(int(x) for x in v.lower().split("x"))
             for k, v in (("procedural", args.size), ("mesh", args.mesh_size))}
    rows, meta = [], []
    t_all = time.perf_counter()
    for name in args.scenes.split(","):
        t0 = time.perf_counter()
        size = sizes["procedural" if name in PROCEDURAL else "mesh"]
        profile, cfg, cpu, other = measure(name, size)
        t1 = time.perf_counter()
        rows.extend(rows_of(name, profile, cfg))
        meta.append({"scene": name, "size": f"{size[0]}x{size[1]}",
                     "render_wall_s": round(t1 - t0, 2), "render_cpu_s": round(cpu, 2), "other_bundle_pairs": other,
                     "model_wall_s": round(time.perf_counter() - t1, 2)})
        print(f"{name}: {profile.n_runs} runs, {profile.spheres} spheres, {profile.pairs} "
              f"pairs; render {t1 - t0:.1f} s wall / {cpu:.1f} s CPU, cycle model "
              f"{time.perf_counter() - t1:.1f} s", flush=True)
        write(args.out, sizes, meta, rows, time.perf_counter() - t_all)
    print(f"\n{'scene':16s} {'testers':>7s} {'lanes':>5s} {'pairs':>10s} {'cycles':>10s} "
          f"{'pairs/cycle':>11s} {'lane results':>12s}")
    for r in rows:
        print(f"{r['scene']:16s} {r['testers']:7d} {r['lanes']:5d} {r['pairs']:10d} "
              f"{r['cycles']:10d} {r['pairs_per_cycle']:11.3f} "
              f"{r['pairs_per_cycle_lane_results']:12.3f}")
    print(f"saved {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
