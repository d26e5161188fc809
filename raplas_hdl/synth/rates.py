"""The modelled rates the capacity tables multiply by a clock: pairs per cycle per scene,
from the cycle model's rows (``benchmarks/bench_throughput.py``), for one array and lane
configuration. Shared by the Xilinx estimates (:mod:`.capacity`) and the placed and routed
ECP5 rows (:mod:`.capacity_ecp5`)."""

from __future__ import annotations

__all__ = ["pairs_per_cycle"]


def pairs_per_cycle(rows, testers: int, lanes: int, fmt_name: str | None = None,
                    key: str = "pairs_per_cycle") -> dict:
    """``{scene: pairs per cycle}`` of the 4x4 rows with ``testers`` and ``lanes``
    (``key``: another column of the rows, e.g. ``pairs_per_cycle_lane_results``)."""
    out = {}
    for r in rows:
        if (r["testers"], r["lanes"]) != (testers, lanes):
            continue
        if r.get("rows", 4) != 4 or r.get("cols", 4) != 4:
            continue
        if fmt_name and r.get("format") and not str(r["format"]).startswith(fmt_name):
            continue
        if key in r:
            out[r["scene"]] = float(r[key])
    return out
