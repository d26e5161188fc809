"""What exact ordering costs the certified on-chip reduction, on real render passes.

Renders each scene through the certified model backend, records every pass
(:func:`raplas_hdl.host.reduction_passes.recorded_runs`), and runs each pass's runs through
the unit's model without and with the reduction. Per scene: the pairs, the certain hits and
how many are *tight* (``model/ordering.py``), the uncertain pairs, the reduced stream's beats
passed on to the host and its answers, and the rays whose resolved triangle or ``t`` differ
between the two streams (must be 0).

Usage::

    python benchmarks/bench_reduction_ordering.py [--size 64] [--scenes cornell,stanford-bunny]
        [--out docs/results/reduction_ordering.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from raplas_hdl.fp import FP24  # noqa: E402
from raplas_hdl.host.reduction_passes import (  # noqa: E402
    pass_runs,
    recorded_runs,
    resolve_streams,
)
from raplas_hdl.host.render import RenderSettings  # noqa: E402
from raplas_hdl.model.intersection import run_runs  # noqa: E402
from raplas_hdl.model.records import OUTCOME_HIT, OUTCOME_UNCERTAIN  # noqa: E402


def measure(scene: str, size: int) -> dict:
    st = RenderSettings(size, size, rows=8, cols=8, shadow_rows=3, shadow_cols=3,
                        progress=False)
    t0 = time.perf_counter()
    backend, passes = recorded_runs(scene, st, FP24, mode="certified")
    tot = dict(pairs=0, certain=0, tight=0, uncertain=0, beats_unreduced=0, passed_on=0,
               answers=0, rays=0, rays_differing=0)
    for rec in passes:
        cfg = backend.config(rec.batch.rows, rec.batch.cols)
        runs = pass_runs(backend, rec, cfg)
        plain = [s for s, _ in run_runs(cfg, backend.scene_memory, runs)]
        red = [a for a, _ in run_runs(replace(cfg, reduce=True), backend.scene_memory, runs)]
        for s in plain:
            tot["beats_unreduced"] += s.size
            if s["empty"].any():
                continue
            tot["pairs"] += s.size
            tot["certain"] += int((s["outcome"] == OUTCOME_HIT).sum())
            tot["tight"] += int(s["tight"].sum())
            tot["uncertain"] += int((s["outcome"] == OUTCOME_UNCERTAIN).sum())
        for a in red:
            tot["passed_on"] += int((a["outcome"] == OUTCOME_UNCERTAIN).sum())
            tot["answers"] += int((a["outcome"] == OUTCOME_HIT).sum())
        tri_p, t_p = resolve_streams(backend, rec, plain)
        tri_r, t_r = resolve_streams(backend, rec, red)
        same_t = (t_p == t_r) | (np.isnan(t_p) & np.isnan(t_r))
        tot["rays_differing"] += int(((tri_p != tri_r) | ~same_t).sum())
        tot["rays"] += int(tri_p.size)
    tot["tight_fraction"] = tot["tight"] / max(1, tot["certain"])
    tot["seconds"] = round(time.perf_counter() - t0, 2)
    return tot


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--scenes", default="cornell,stanford-bunny")
    p.add_argument("--out", default=str(ROOT / "build" / "reduction_ordering.json"))
    args = p.parse_args(argv)
    report = {"size": args.size, "format": "FP24", "machine": platform.platform(),
              "cpus": os.cpu_count(), "load_before": os.getloadavg(), "scenes": {}}
    for scene in args.scenes.split(","):
        row = measure(scene, args.size)
        report["scenes"][scene] = row
        print(f"{scene:16s} {args.size}x{args.size}: pairs {row['pairs']:,}, certain "
              f"{row['certain']:,} ({100 * row['tight_fraction']:.1f} % tight), uncertain "
              f"{row['uncertain']:,}; reduced: passed on {row['passed_on']:,}, answers "
              f"{row['answers']:,} ({row['beats_unreduced']:,} beats unreduced); rays "
              f"differing {row['rays_differing']} of {row['rays']:,}", flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=2))
    print(f"wrote {args.out}")
    return 1 if any(r["rays_differing"] for r in report["scenes"].values()) else 0


if __name__ == "__main__":
    sys.exit(main())
