"""The ECP5 rows of the capacity table: measured by place and route, never estimated.

The Xilinx rows of :mod:`.capacity` are Yosys estimates composed from parts. The ECP5 rows
come from ``raplas-hdl pnr intersection-unit --copies N`` (``benchmarks/bench_pnr.py
--copies N``): N whole intersection units placed and routed side by side on the LFE5U-85F,
one record of ``docs/results/pnr.json`` with a ``copies`` field. From it:

- **copies placed** N, and the device's share each resource of the N copies takes
  (nextpnr's ``utilization``: used over available per cell type);
- **units per device** = N / the largest share, rounded down: the utilisation of the placed
  copies scaled to the whole device. Only N are placed; the bound says how many the
  resources allow, not that a design of that many routes at the same clock;
- **Fmax**: the median (min-max) over the seeds of the N copies, as placed;
- **pairs/s** = measured Fmax x the modelled pairs per cycle of one unit (the throughput
  model's minimum over the bench scenes, as in the Xilinx rows) x units: for the N copies
  placed, and for the units per device at the N copies' Fmax.

Without such a record the row says *not measured* and gives no figure.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from .rates import pairs_per_cycle

__all__ = ["ECP5_DEVICE", "MEASURE_COMMAND", "load_pnr_runs", "ecp5_rows", "render_ecp5"]

#: The device of the rows (the ULX3S's).
ECP5_DEVICE = "LFE5U-85F"

#: The command that measures the default row.
MEASURE_COMMAND = ("python benchmarks/bench_pnr.py --only intersection-unit --default-options "
                   "--roundings rtz --speeds 6 --copies 2")

#: nextpnr cell types whose share bounds the units per device.
_BOUND_BY = ("TRELLIS_COMB", "TRELLIS_FF", "TRELLIS_RAMW", "MULT18X18D", "ALU54B", "DP16KD")


def load_pnr_runs(path) -> list[dict]:
    """The runs of a ``docs/results/pnr.json`` (``{"runs": [...]}``); ``ValueError`` when it
    is not one."""
    data = json.loads(Path(path).read_text())
    runs = data.get("runs") if isinstance(data, dict) else None
    if not isinstance(runs, list):
        raise ValueError(f"{path}: no \"runs\" list (the results of benchmarks/bench_pnr.py)")
    for r in runs:
        for k in ("unit", "format", "options", "speed", "fmax", "utilisation"):
            if k not in r:
                raise ValueError(f"{path}: a run lacks {k!r}")
    return runs


def _config(options: dict) -> tuple[int, int, bool]:
    rows, cols = options.get("rows", 4), options.get("cols", 4)
    return options.get("testers") or rows + cols, options.get("lanes", 1), bool(
        options.get("reduce", False))


def ecp5_rows(pnr_runs, throughput_rows, fmt) -> list[dict]:
    """One row per multi-copy intersection-unit run at ``fmt`` on :data:`ECP5_DEVICE` (4x4
    bundles, the generic target), or one *not measured* row."""
    out = []
    for r in pnr_runs or ():
        o = r.get("options") or {}
        if (r.get("unit") != "intersection-unit" or r.get("copies", 1) < 2
                or r.get("device", ECP5_DEVICE) != ECP5_DEVICE or r.get("format") != fmt.name
                or (o.get("rows", 4), o.get("cols", 4)) != (4, 4)
                or o.get("target", "generic") != "generic"
                or o.get("adder", "generic") != "generic"):
            continue
        n = r["copies"]
        testers, lanes, reduce = _config(o)
        util = r["utilisation"]
        share = {k: util[k]["used"] / util[k]["available"] for k in _BOUND_BY
                 if k in util and util[k]["available"] and util[k]["used"]}
        bound = max(share, key=share.get)
        units = math.floor(n / share[bound])
        clk = r["fmax"].get("clk") or next(iter(r["fmax"].values()))
        ppc = pairs_per_cycle(throughput_rows, testers, lanes)
        lo = min(ppc.values()) if ppc else None
        per_unit = None if lo is None else clk["median"] * 1e6 * lo
        out.append({
            "device": ECP5_DEVICE, "speed": r["speed"], "target": "generic",
            "testers": testers, "lanes": lanes, "reduce": reduce, "measured": True,
            "basis": "place and route (nextpnr-ecp5)", "copies": n, "seeds": clk["seeds"],
            "fmax": clk, "share": {k: round(v, 5) for k, v in share.items()},
            "bound_by": bound, "units": units,
            "used": {k: util[k]["used"] for k in share},
            "available": {k: util[k]["available"] for k in share},
            "pairs_per_cycle": ppc,
            "pairs_per_s_placed": None if per_unit is None else n * per_unit,
            "pairs_per_s": None if per_unit is None else units * per_unit,
            "command": r.get("command", "")})
    if not out:
        out.append({"device": ECP5_DEVICE, "speed": 6, "target": "generic", "testers": 8,
                    "lanes": 1, "reduce": False, "measured": False, "basis": "not measured",
                    "command": MEASURE_COMMAND})
    return sorted(out, key=lambda x: (x["speed"], x["testers"], x["lanes"], x["reduce"],
                                      x.get("copies", 0)))


def _mps(v) -> str:
    return "-" if v is None else f"{v / 1e6:.0f} M"


def render_ecp5(rows: list[dict], paper: float, source: str = "docs/results/pnr.json") -> list:
    """The ECP5 section (markdown lines) of :func:`ecp5_rows`."""
    out = ["### ECP5: placed and routed", "",
           f"Measured, not estimated: N whole intersection units placed and routed side by "
           f"side on the {ECP5_DEVICE} (CABGA381, the ULX3S's part; out of context) by "
           f"`raplas-hdl pnr intersection-unit --copies N`, read from `{source}`. **units** "
           "= N / the largest share of a resource the N copies take, rounded down (the "
           "placed copies' utilisation scaled to the device: only N are placed). **Fmax**: "
           "the median (min-max) over the seeds of the N copies. **pairs/s** = that Fmax x "
           "the modelled pairs per cycle of one unit (minimum over the bench scenes) x the N "
           "placed copies, and x the units per device (at the N copies' Fmax).", "",
           "| device | speed | target | t | K | reduce | basis | copies placed | LUT4 used (of "
           "the device) | MULT18X18D | EBR | units per device (bound by) | Fmax MHz median "
           "(min-max, seeds) | pairs/cycle | pairs/s, N placed | pairs/s, units per device | "
           "vs paper |", "|" + "---|" * 17]
    for r in rows:
        head = [r["device"], r["speed"], r["target"], r["testers"], r["lanes"],
                "on" if r["reduce"] else "off"]
        if not r["measured"]:
            out.append("| " + " | ".join(map(str, head)) + " | **not measured**: no "
                       "multi-copy place and route in the results (`" + r["command"]
                       + "`) |" + " - |" * 10)
            continue
        used, av, share = r["used"], r["available"], r["share"]

        def cell(k):
            return (f"{used[k]:,} / {av[k]:,} ({share[k]:.1%})" if k in used else "0")

        f = r["fmax"]
        ppc = r["pairs_per_cycle"]
        ppc_s = f"{min(ppc.values()):.3f}-{max(ppc.values()):.3f}" if ppc else "n/a"
        ratio = "-" if r["pairs_per_s"] is None else f"{r['pairs_per_s'] / paper:.2f}x"
        out.append("| " + " | ".join(map(str, head + [
            r["basis"], r["copies"], cell("TRELLIS_COMB"), cell("MULT18X18D"),
            cell("DP16KD"), f"**{r['units']}** ({r['bound_by']})",
            f"**{f['median']:.1f}** ({f['min']:.1f}-{f['max']:.1f}, {f['seeds']})", ppc_s,
            _mps(r["pairs_per_s_placed"]), _mps(r["pairs_per_s"]), ratio])) + " |")
    return out
