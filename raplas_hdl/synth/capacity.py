"""Capacity per configuration: how many intersection units fit on a device, and the pairs per
second they sustain (issue 15, point 4).

A *configuration* is a device (its family), the DSP48 target of the FP units (``generic``:
inferred multiplies, adders in the fabric; ``virtex4``: the significand multiplies and the
FP adders as Virtex-4 ``DSP48`` primitives, ``--target virtex4 --adder virtex4``), the
testers of the 4x4 plane-sphere array (8: one pass per sphere; 4: two passes), ``K``
ray-triangle lanes behind the array (``UnitConfig.lanes``) and the Triangle Memory size
``N``. One *unit* is the intersection unit of that configuration.

**Resources of one unit, composed.** A whole-unit Yosys run takes minutes, so a unit is
estimated from its parts::

    unit = array(testers, target) + K x ray-triangle(target) + rest

``rest`` (the memories' fabric, feeder, selector, record fetch, FIFOs, framing, counters) is
the whole-unit run minus its array and ray-triangle unit, taken from one whole-unit run per
family; :func:`validate` compares the composition with other whole-unit runs. Slices are the
Yosys estimates summed (a lower bound; the x1.25 column is the packing margin). The extra
fabric of a lane beyond the first (its job FIFO, record fetch and pair FIFO, and the
distributor and merger) is in ``rest`` once only; the K=2 validation shows what it costs.

**Block RAM** of the memories for ``N`` triangles (:func:`bram_blocks`), in 18 Kbit blocks:
each memory is split into its write lanes, each lane mapped to the best aspect ratio of an
18 Kbit block (16Kx1 .. 512x36), calibrated by the difference between Yosys's count and the
model at the synthesised size. ``K`` lanes read Triangle Memory, the triangle lists and Ray
Memory through their own read ports: Yosys builds those memories ``K`` times.

**Pairs per second** = units x the modelled pairs per cycle of the configuration (testers,
``K``) on the bench scenes x 100 MHz, not ``K`` x clock: the pairs per cycle come from the
throughput model's results (rows ``scene, format, rows, cols, testers, lanes,
pairs_per_cycle``). The paper: one unit, 100 M pairs/s at its board's 100 MHz.

**These rows are Yosys estimates** (synthesis only; no place and route for the Xilinx
devices here). The ECP5 rows (:mod:`.capacity_ecp5`) are the opposite: read from a place and
route of several whole units side by side (``docs/results/pnr.json``), or *not measured*.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from ..rtl.emit import emit_verilog
from .capacity_ecp5 import ecp5_rows, render_ecp5
from .rates import pairs_per_cycle
from .report import report_format_label, synth_row
from .yosys import count_cells, synthesize

__all__ = ["DEVICES", "Config", "CONFIGS", "bram_blocks", "compose", "capacity_row",
           "capacity_table", "validate", "PAPER_PAIRS_PER_SECOND", "CLOCK_MHZ"]

#: Devices: family, DSP slices, logic slices, 18 Kbit block RAMs (RAMB16 / RAMB18E1).
DEVICES = {
    "XC4VSX35": {"family": "xc4v", "dsp48": 192, "slices": 15360, "bram18": 192},
    "XC7A100T": {"family": "xc7", "dsp48": 240, "slices": 15850, "bram18": 270},
    "XC7K325T": {"family": "xc7", "dsp48": 840, "slices": 50950, "bram18": 890},
}

#: The paper's sustained rate: one unit at 1 pair per clock at 100 MHz.
PAPER_PAIRS_PER_SECOND = 100e6
CLOCK_MHZ = 100.0
PACKING_MARGIN = 1.25

#: 18 Kbit block aspect ratios (depth, width).
_ASPECTS = ((16384, 1), (8192, 2), (4096, 4), (2048, 9), (1024, 18), (512, 36))

#: Memories read by every lane (each lane has its own read port: K copies).
LANE_MEMORIES = ("tri", "tlist", "ray")


@dataclass(frozen=True)
class Config:
    device: str
    target: str         # generic | virtex4 (multipliers and adders)
    testers: int
    lanes: int
    reduce: bool = False    # the on-chip nearest-hit / any-hit reduction (UnitConfig.reduce)

    @property
    def family(self) -> str:
        return DEVICES[self.device]["family"]

    @property
    def label(self) -> str:
        return (f"{self.device} {self.target} t{self.testers} K{self.lanes}"
                + (" reduce" if self.reduce else ""))


#: The configurations of the table: Virtex-4 with both targets, the 7-series devices with
#: the generic RTL (the DSP48 adder is a Virtex-4 primitive design).
CONFIGS = tuple(
    [Config("XC4VSX35", t, n, k) for t in ("generic", "virtex4") for n in (8, 4)
     for k in (1, 2, 3)]
    + [Config("XC4VSX35", t, n, k, True) for t in ("generic", "virtex4") for n in (8, 4)
       for k in (1, 2)]
    + [Config(d, "generic", n, k) for d in ("XC7A100T", "XC7K325T") for n in (8, 4)
       for k in (1, 2, 3)])


def _bram_lane(width: int, depth: int) -> int:
    return min(math.ceil(width / w) * math.ceil(depth / d) for d, w in _ASPECTS)


def bram_blocks(config, lanes: int = 1) -> dict:
    """18 Kbit blocks per memory of ``config`` (a :class:`UnitConfig`), ``K = lanes`` copies
    of the lanes' memories; ``{"total": n, memory: n, ...}`` (model, uncalibrated)."""
    # lazy: rtl.unit.memories loads Amaranth and the model's numba kernels
    from ..rtl.unit.memories import memory_geometry

    out = {}
    for name, (width, depth, lane) in memory_geometry(config).items():
        n = (width // lane) * _bram_lane(lane, depth)
        out[name] = n * (lanes if name in LANE_MEMORIES else 1)
    out["total"] = sum(out.values())
    return out


def unit_config(fmt, n_triangles: int, testers: int = 8, lanes: int = 1):
    """The :class:`UnitConfig` of a 4x4 unit with Triangle Memory for ``n_triangles`` (and
    Sphere Memory for one sphere per 4 triangles, the ratio of the unit's defaults: 1,024 and 256)."""
    # lazy: model.config loads numba; the capacity tables need no kernels
    from ..model.config import UnitConfig

    spheres = max(1, math.ceil(n_triangles / 4))
    return UnitConfig(fmt=fmt, rows=4, cols=4, testers=testers, max_triangles=n_triangles,
                      max_spheres=spheres, lanes=lanes)


_FIELDS = ("dsp48", "slices_est", "luts", "ffs")


def _with_cells(*rows) -> bool:
    return all(r.get("cells_by_type") is not None for r in rows)


def compose(array: dict, rtu: dict, rest: dict, lanes: int, family: str = "xc4v", *,
            cells: bool = False) -> dict:
    """``array + lanes x rtu + rest``: ``dsp48``, ``slices_est``, ``luts``, ``ffs``.

    By default the parts' own figures are summed, slices included: an upper bound, since a
    part bound by its flip-flops and another bound by its LUTs could share slices. With
    ``cells`` (and the cell counts of every part, ``cells_by_type``) the cells are summed
    and the slice estimate is taken of the sum (:func:`.yosys.summarize`'s formula)."""
    if cells and _with_cells(array, rtu, rest):
        types = set(array["cells_by_type"]) | set(rtu["cells_by_type"]) | set(rest["cells_by_type"])
        cells = {t: array["cells_by_type"].get(t, 0) + lanes * rtu["cells_by_type"].get(t, 0)
                 + rest["cells_by_type"].get(t, 0) for t in types}
        c = count_cells(cells, family)
        return {k: c[k] for k in _FIELDS}
    return {k: array[k] + lanes * rtu[k] + rest[k] for k in _FIELDS}


def _plus(a: dict, b: dict) -> dict:
    """Fields (and cells, when both have them) of ``a`` plus ``b``."""
    out = {k: a[k] + b[k] for k in _FIELDS}
    if _with_cells(a, b):
        types = set(a["cells_by_type"]) | set(b["cells_by_type"])
        out["cells_by_type"] = {t: a["cells_by_type"].get(t, 0) + b["cells_by_type"].get(t, 0)
                                for t in types}
    return out


def rest_of(unit: dict, array: dict, rtu: dict, lanes: int = 1) -> dict:
    """The whole-unit row minus its array and ray-triangle units (cell by cell too, when
    the rows have their cell counts)."""
    out = {k: unit[k] - array[k] - lanes * rtu[k] for k in _FIELDS}
    if _with_cells(unit, array, rtu):
        types = set(unit["cells_by_type"]) | set(array["cells_by_type"]) | set(rtu["cells_by_type"])
        out["cells_by_type"] = {t: unit["cells_by_type"].get(t, 0)
                                - array["cells_by_type"].get(t, 0)
                                - lanes * rtu["cells_by_type"].get(t, 0) for t in types}
    return out


def _limit(avail, per):
    return None if not per else int(avail // per)


def capacity_row(cfg: Config, need: dict, bram: dict, ppc: dict, path_cells: int) -> dict:
    """One row of the table: ``need`` (``dsp48``, ``slices_est``), ``bram`` ({label: blocks}),
    ``ppc`` ({scene: pairs per cycle})."""
    dev = DEVICES[cfg.device]
    limits = {"dsp48": _limit(dev["dsp48"], need["dsp48"]),
              "slices": _limit(dev["slices"], need["slices_est"]),
              "slices_x1.25": _limit(dev["slices"], math.ceil(need["slices_est"] * PACKING_MARGIN))}
    bram_limits = {label: _limit(dev["bram18"], n) for label, n in bram.items()}
    row = {"device": cfg.device, "family": cfg.family, "target": cfg.target,
           "testers": cfg.testers, "lanes": cfg.lanes, "reduce": cfg.reduce,
           "dsp48": need["dsp48"],
           "slices_est": need["slices_est"],
           "slices_x1.25": math.ceil(need["slices_est"] * PACKING_MARGIN),
           "bram18": bram, "limits": limits, "bram_limits": bram_limits,
           "path_cells": path_cells, "pairs_per_cycle": ppc}
    lo = min(ppc.values()) if ppc else None
    for label in bram:
        for margin in ("", "_x1.25"):
            cand = [limits["dsp48"], limits["slices" + margin], bram_limits[label]]
            units = min(v for v in cand if v is not None)
            row[f"units{margin}[{label}]"] = units
            row[f"pairs_per_s{margin}[{label}]"] = (None if lo is None
                                                   else units * lo * CLOCK_MHZ * 1e6)
    return row


def validate(predicted: dict, actual: dict) -> dict:
    """Relative error of a composed estimate against a whole-unit run."""
    return {k: {"predicted": predicted[k], "actual": actual[k],
                "error": (predicted[k] - actual[k]) / actual[k] if actual[k] else None}
            for k in ("dsp48", "slices_est", "luts", "ffs")}


def load_throughput(path) -> list[dict]:
    """Rows of the throughput results (a list, or ``{"rows": [...]}``)."""
    data = json.loads(Path(path).read_text())
    rows = data["rows"] if isinstance(data, dict) else data
    need = {"scene", "testers", "lanes", "pairs_per_cycle"}
    for r in rows:
        if not need <= set(r):
            raise ValueError(f"{path}: a throughput row lacks {', '.join(sorted(need - set(r)))}")
    return rows


def capacity_table(parts: dict, throughput_rows, n_triangles: dict, fmt, *,
                   configs=CONFIGS, bram_calibration: dict | None = None,
                   reduce_cost: dict | None = None) -> list[dict]:
    """The rows for ``configs``.

    ``parts[(family, target)]`` holds ``array`` ({testers: row}), ``rtu`` (row) and ``rest``
    (dict) — rows of :func:`.report.synth_row`. ``n_triangles``: {label: N}.
    ``bram_calibration``: {family: blocks to add to the model (Yosys minus model at the
    synthesised size)}. ``reduce_cost``: {family: the reduction's ``dsp48``,
    ``slices_est``, ``luts``, ``ffs``, ``bram`` over the same unit without it}; the
    ``reduce`` configurations of a family without it are left out.
    """
    out = []
    for cfg in configs:
        p = parts.get((cfg.family, cfg.target))
        if p is None or cfg.testers not in p["array"]:
            continue
        array, rtu = p["array"][cfg.testers], p["rtu"]
        rest = p["rest"]
        cal = (bram_calibration or {}).get(cfg.family, 0)
        if cfg.reduce:
            extra = (reduce_cost or {}).get(cfg.family)
            if extra is None:
                continue
            rest = _plus(rest, extra)
            cal += extra["bram"]
        need = compose(array, rtu, rest, cfg.lanes, cfg.family)
        # the memories' model, the calibration and the ray-triangle units' own block RAM
        # (their output FIFOs with the DSP48 adders)
        cal += cfg.lanes * rtu.get("bram", 0)
        bram = {label: bram_blocks(unit_config(fmt, n, cfg.testers), cfg.lanes)["total"] + cal
                for label, n in n_triangles.items()}
        path = max(array["path_cells"], rtu["path_cells"])
        ppc = pairs_per_cycle(throughput_rows, cfg.testers, cfg.lanes)
        row = capacity_row(cfg, need, bram, ppc, path)
        row["pairs_per_cycle_lane_results"] = pairs_per_cycle(
            throughput_rows, cfg.testers, cfg.lanes, key="pairs_per_cycle_lane_results")
        out.append(row)
    return out


# -- gathering the parts ------------------------------------------------------------------

#: Option defaults of the rows, so that rows written before an option existed still match.
_DEFAULTS = {"target": "generic", "adder": "generic", "rows": 4, "cols": 4}
_UNIT_DEFAULTS = {"plane-sphere": {"testers": 8}, "intersection-unit": {"testers": 8},
                  "ray-triangle": {"mode": "paper"}}


def _norm(unit: str, options: dict) -> dict:
    o = {**_DEFAULTS, **_UNIT_DEFAULTS.get(unit, {}), **(options or {})}
    if unit in ("ray-triangle",):
        o.pop("rows"), o.pop("cols")
    return o


def find_row(rows, unit: str, fmt, options: dict, family: str = "xc4v"):
    """The row of ``rows`` (report rows) for ``unit`` at ``fmt`` with ``options``."""
    want = _norm(unit, options)
    for r in rows:
        if (r.get("unit") == unit and r.get("rounding") == fmt.rounding
                and r.get("family", "xc4v") == family
                and (r.get("exp_bits"), r.get("man_bits")) == (fmt.exp_bits, fmt.man_bits)
                and _norm(unit, r.get("options", {})) == want):
            return r
    return None


def _targets(target: str) -> dict:
    return {} if target == "generic" else {"target": target, "adder": target}


#: The syntheses behind the table: (family, target) -> units and options.
def needed_runs(families=("xc4v", "xc7")) -> list[tuple]:
    """``(unit, options, family)`` of every synthesis the table uses, the most useful first."""
    runs = []
    for family in families:
        for target in (("generic", "virtex4") if family == "xc4v" else ("generic",)):
            t = _targets(target)
            runs.append(("ray-triangle", {**t}, family))
            for testers in (8, 4):
                runs.append(("plane-sphere", {"rows": 4, "cols": 4, "testers": testers, **t},
                             family))
        # the whole unit behind the rest (the 8-tester generic one, the paper's array) and,
        # on xc7, the 4-tester one to validate the composition
        for testers in ((8,) if family == "xc4v" else (8, 4)):
            runs.append(("intersection-unit", {"rows": 4, "cols": 4, "testers": testers},
                         family))
    # the on-chip reduction (UnitConfig.reduce): its cost over the same unit without it
    runs.append(("intersection-unit", {"rows": 4, "cols": 4, "testers": 4, "reduce": True,
                                       **_targets("virtex4")}, "xc4v"))
    # validation of the composition: other targets, testers and K than the rest's unit
    for lanes in (1, 2):
        runs.append(("intersection-unit", {"rows": 4, "cols": 4, "testers": 4,
                                           **({"lanes": lanes} if lanes > 1 else {}),
                                           **_targets("virtex4")}, "xc4v"))
    return runs


def unit_row(fmt, options: dict, family: str = "xc4v", *, cached_only: bool = False) -> dict:
    """:func:`.report.synth_row` for ``intersection-unit`` with ``UnitConfig`` fields the
    unit registry has no option for (``reduce``): the unit built directly."""
    # lazy: the unit's RTL loads Amaranth and model.config numba, only to build the unit
    from ..model.config import UnitConfig
    from ..rtl.intersection import IntersectionUnit

    o = dict(options)
    targets = {"multiplier": o.pop("target", "generic"), "adder": o.pop("adder", "generic")}
    comp = IntersectionUnit(UnitConfig(fmt=fmt, **o), **targets)
    params = {"exp_bits": fmt.exp_bits, "man_bits": fmt.man_bits, "rounding": fmt.rounding,
              **options}
    text, _ = emit_verilog(comp, "intersection_unit", params)
    r = synthesize(text, "intersection_unit", cached_only=cached_only, family=family)
    return {"unit": "intersection-unit", "format": fmt.name, "exp_bits": fmt.exp_bits,
            "man_bits": fmt.man_bits, "rounding": fmt.rounding, "options": dict(options),
            "latency": None, "family": family, **r.to_dict()}


def gather(fmt, *, rows=(), cached_only: bool = True, progress=None, runs=None) -> dict:
    """Synthesis rows for :func:`needed_runs`: from ``rows`` (an earlier report's rows), the
    Yosys cache, or (``cached_only`` False) a Yosys run. ``{(unit, options key, family):
    row}`` and the runs that had no result under ``"missing"``."""
    found, missing = {}, []
    for unit, options, family in runs or needed_runs():
        key = (unit, tuple(sorted(_norm(unit, options).items())), family)

        def synth(only):
            if "reduce" in options:
                return unit_row(fmt, options, family, cached_only=only)
            return synth_row(unit, fmt, dict(options), cached_only=only, family=family)

        # the cache (today's RTL) first, then an earlier report's row, then Yosys
        try:
            row = synth(True)
        except LookupError:
            row = find_row(rows, unit, fmt, options, family)
            if row is None and not cached_only:
                row = synth(False)
        if row is None:
            missing.append({"unit": unit, "options": options, "family": family})
            if progress:
                progress(f"{unit} {options} {family}: no result")
            continue
        if progress:
            progress(f"{unit} {options} {family}: slices~ {row['slices_est']}, "
                     f"DSP {row['dsp48']}, path {row['path_cells']}"
                     + (" (cached)" if row.get("cached") else f" ({row['seconds']:.0f} s)"))
        found[key] = row
    return {"rows": found, "missing": missing}


def _get(found, unit, options, family):
    return found.get((unit, tuple(sorted(_norm(unit, options).items())), family))


def build_capacity(fmt, found: dict, throughput_rows, n_triangles: dict, *,
                   pnr_runs=None, pnr_source: str = "docs/results/pnr.json") -> dict:
    """The table, its inputs and the validation of the composition (see module docstring).

    ``rest`` of a family comes from its generic 8-tester whole-unit run (xc4v) or any
    whole-unit run of the family; the other whole-unit runs validate the composition.
    ``pnr_runs`` (the runs of ``docs/results/pnr.json``) give the ECP5 rows
    (:func:`.capacity_ecp5.ecp5_rows`; without a multi-copy run: *not measured*)."""
    parts, validation, rests = {}, [], {}
    units = [(opts, fam, r) for (u, okey, fam), r in found.items()
             if u == "intersection-unit" for opts in [dict(okey)]]
    # the rest of each family: prefer the generic 8-tester unit
    units.sort(key=lambda x: (x[0].get("target") != "generic", x[0].get("testers") != 8))
    cal, reduce_cost = {}, {}
    for opts, fam, r in units:
        if opts.get("reduce"):
            plain = _get(found, "intersection-unit",
                         {k: v for k, v in opts.items() if k != "reduce"}, fam)
            if plain is not None:
                reduce_cost[fam] = {k: r[k] - plain[k]
                                    for k in ("dsp48", "slices_est", "luts", "ffs", "bram")}
                if _with_cells(r, plain):
                    types = set(r["cells_by_type"]) | set(plain["cells_by_type"])
                    reduce_cost[fam]["cells_by_type"] = {
                        t: r["cells_by_type"].get(t, 0) - plain["cells_by_type"].get(t, 0)
                        for t in types}
                reduce_cost[fam].update(basis={**opts, "family": fam},
                                        path_cells=r["path_cells"])
            continue
        tgt = opts.get("target", "generic")
        arr = _get(found, "plane-sphere", {"testers": opts["testers"], **_targets(tgt)}, fam)
        rtu = _get(found, "ray-triangle", _targets(tgt), fam)
        if arr is None or rtu is None:
            continue
        lanes = opts.get("lanes", 1)
        if fam not in rests:
            rests[fam] = {**rest_of(r, arr, rtu, lanes), "basis": {**opts, "family": fam},
                          "path_cells": r["path_cells"]}
            model = bram_blocks(unit_config(fmt, 1024, opts["testers"]), lanes)["total"]
            cal[fam] = r["bram"] - model - lanes * rtu.get("bram", 0)
            continue
        pred = compose(arr, rtu, rests[fam], lanes, fam)
        by_cells = compose(arr, rtu, rests[fam], lanes, fam, cells=True)
        bram = (bram_blocks(unit_config(fmt, 1024, opts["testers"]), lanes)["total"] + cal[fam]
                + lanes * rtu.get("bram", 0))
        validation.append({"family": fam, "options": opts, **validate(pred, r),
                           "slices_of_summed_cells": by_cells["slices_est"],
                           "bram": {"predicted": bram, "actual": r["bram"]},
                           "path_cells": r["path_cells"]})
    for fam, rest in rests.items():
        for target in ("generic", "virtex4"):
            t = _targets(target)
            rtu = _get(found, "ray-triangle", t, fam)
            arrays = {n: a for n in (8, 4)
                      if (a := _get(found, "plane-sphere", {"testers": n, **t}, fam))}
            if rtu is None or not arrays:
                continue
            parts[(fam, target)] = {"array": arrays, "rtu": rtu, "rest": rest,
                                    "unit_path_cells": rest["path_cells"]}
    table = capacity_table(parts, throughput_rows, n_triangles, fmt, bram_calibration=cal,
                           reduce_cost=reduce_cost)
    inputs = {f"{fam}/{target}": {
        "array": {n: _brief(a) for n, a in p["array"].items()}, "rtu": _brief(p["rtu"]),
        "rest": {k: v for k, v in p["rest"].items() if k != "cells_by_type"}}
        for (fam, target), p in parts.items()}
    return {"format": f"{report_format_label(fmt)}/{fmt.rounding}", "table": table,
            "validation": validation, "inputs": inputs,
            "bram_calibration": cal,
            "reduce_cost": {f: {k: v for k, v in rc.items() if k != "cells_by_type"}
                            for f, rc in reduce_cost.items()},
            "n_triangles": n_triangles, "devices": DEVICES,
            "clock_mhz": CLOCK_MHZ, "paper_pairs_per_second": PAPER_PAIRS_PER_SECOND,
            "packing_margin": PACKING_MARGIN,
            "ecp5": ecp5_rows(pnr_runs, throughput_rows, fmt), "ecp5_source": pnr_source}


def _brief(row: dict) -> dict:
    return {k: row[k] for k in ("dsp48", "slices_est", "luts", "lutram", "ffs", "bram",
                                "path_cells", "path_levels", "latency", "seconds") if k in row}


# -- markdown ---------------------------------------------------------------------------

def _lim(v):
    return "-" if v is None else str(v)


def _mps(v):
    return "-" if v is None else f"{v / 1e6:.0f} M"


def best(table, device: str = "XC4VSX35", label: str | None = None, margin: str = ""):
    """The row of ``device`` with the most pairs per second (N = ``label``)."""
    rows = [r for r in table if r["device"] == device]
    if not rows:
        return None
    label = label or next(iter(rows[0]["bram18"]))
    key = f"pairs_per_s{margin}[{label}]"
    rows = [r for r in rows if r.get(key) is not None]
    return max(rows, key=lambda r: (r[key], -r["slices_est"])) if rows else None


def render_capacity(cap: dict, *, worst_path: int | None = None) -> list[str]:
    """The capacity section (markdown lines) of :func:`build_capacity`'s result."""
    table = cap["table"]
    labels = list(cap["n_triangles"])
    first = labels[0]
    scenes = sorted({s for r in table for s in r["pairs_per_cycle"]})
    out = ["## Capacity per configuration (issue 15)", ""]
    devs = ", ".join(f"{name} ({d['family']}: {d['dsp48']} DSP, {d['slices']:,} slices, "
                     f"{d['bram18']} x 18 Kbit BRAM)" for name, d in cap["devices"].items())
    out += [f"Devices: {devs}. **Every figure of this table is a Yosys estimate** (synthesis "
            "only, no place and route; the ECP5 rows below are placed and routed). "
            f"Format {cap['format']}; 4x4 bundles. **target** `virtex4` is "
            "`--target virtex4 --adder virtex4` (significand multiplies and FP adders in "
            "Virtex-4 DSP48 primitives); the 7-series rows are the generic RTL (Yosys maps "
            "the multiplies to DSP48E1; the two-DSP48 adder is a Virtex-4 primitive design). "
            "**t** = testers of the array, **K** = ray-triangle lanes behind it. One unit = "
            "array + K x ray-triangle + the rest (see the method below). BRAM in 18 Kbit "
            "blocks for Triangle Memory of N triangles ("
            + ", ".join(f"{k}: N = {v:,}" for k, v in cap["n_triangles"].items())
            + "). Each limit is the device's amount over the unit's need; **units** is the "
            "minimum (x1.25: with the slice estimate raised 25 % for packing). "
            f"**pairs/s** = units x the modelled pairs per cycle of (t, K) on the bench "
            f"scenes ({', '.join(scenes) or 'none'}; the minimum over them) x "
            f"{cap['clock_mhz']:g} MHz, the unit as "
            "built (its lanes' results merge into one stream, one beat per cycle; the next "
            "column is what K lanes would sustain if each consumed its own results, a "
            "per-lane reduction that is not built); the paper: "
            f"{cap['paper_pairs_per_second'] / 1e6:.0f} M pairs/s (one unit, 1 pair per "
            "clock). **path**: the longest combinational path (cells) of the array and the "
            "ray-triangle unit (the whole units' paths are in the validation table).",
            ""]
    hdr = ["device", "target", "t", "K", "reduce", "DSP48", "slices~", "x1.25"]
    hdr += [f"BRAM ({k})" for k in labels]
    hdr += ["DSP limit", "slice limit", "x1.25 limit"] + [f"BRAM limit ({k})" for k in labels]
    hdr += [f"units ({first})", f"units x1.25 ({first})", "pairs/cycle (scenes)",
            "if lanes kept their results",
            "pairs/s", "pairs/s x1.25", "vs paper", "vs paper x1.25", "path", "basis"]
    out += ["| " + " | ".join(hdr) + " |", "|" + "---|" * len(hdr)]
    paper = cap["paper_pairs_per_second"]
    for r in table:
        ppc = r["pairs_per_cycle"]
        ppc_s = (f"{min(ppc.values()):.3f}-{max(ppc.values()):.3f}" if ppc else "n/a")
        lane = r.get("pairs_per_cycle_lane_results") or {}
        lane_s = (f"{min(lane.values()):.2f}-{max(lane.values()):.2f}"
                  if lane and r["lanes"] > 1 else "")
        p, p125 = r[f"pairs_per_s[{first}]"], r[f"pairs_per_s_x1.25[{first}]"]
        ratio = "-" if p is None else f"{p / paper:.2f}x"
        ratio125 = "-" if p125 is None else f"{p125 / paper:.2f}x"
        path = str(r["path_cells"]) + (" (!)" if worst_path and r["path_cells"] > worst_path
                                       else "")
        cells = [r["device"], r["target"], r["testers"], r["lanes"],
                 "on" if r["reduce"] else "off", r["dsp48"], r["slices_est"], r["slices_x1.25"]]
        cells += [r["bram18"][k] for k in labels]
        cells += [_lim(r["limits"]["dsp48"]), _lim(r["limits"]["slices"]),
                  _lim(r["limits"]["slices_x1.25"])]
        cells += [_lim(r["bram_limits"][k]) for k in labels]
        cells += [f"**{r[f'units[{first}]']}**", r[f"units_x1.25[{first}]"], ppc_s, lane_s,
                  _mps(p), _mps(p125), ratio, ratio125, path, "Yosys estimate"]
        out.append("| " + " | ".join(str(c) for c in cells) + " |")
    out.append("")
    for dev in cap["devices"]:
        b, b125 = best(table, dev, first), best(table, dev, first, "_x1.25")
        if b is None:
            continue
        p, p125 = b[f"pairs_per_s[{first}]"], b125[f"pairs_per_s_x1.25[{first}]"]
        out.append(
            f"* **{dev}**: best by the estimate {b['target']} t{b['testers']} K{b['lanes']}, "
            f"{b[f'units[{first}]']} unit(s), {p / 1e6:.0f} M pairs/s = **{p / paper:.2f}x** "
            f"the paper; with the x1.25 packing margin {b125['target']} t{b125['testers']} "
            f"K{b125['lanes']}, {b125[f'units_x1.25[{first}]']} unit(s), {p125 / 1e6:.0f} M "
            f"pairs/s = **{p125 / paper:.2f}x**.")
    if "ecp5" in cap:
        out += [""] + render_ecp5(cap["ecp5"], paper, cap.get("ecp5_source",
                                                             "docs/results/pnr.json"))
    out += _render_method(cap) + [""]
    for label in labels[1:]:
        fits = [r for r in table if r[f"units[{label}]"] > 0]
        if not fits:
            need = min(r["bram18"][label] for r in table)
            out.append(f"* N = {cap['n_triangles'][label]:,} ({label}) fits on no device: its "
                       f"memories alone take {need:,} block RAMs; a scene that large needs "
                       "Triangle Memory outside the FPGA.")
    return out


def _render_method(cap: dict) -> list[str]:
    out = ["", "### Parts, composition and its validation", "",
           "The parts (Yosys, FP24 rtz; the array is 4x4; `seconds`: Yosys's wall time on "
           "the shared machine):", "",
           "| family / target | part | latency | DSP48 | LUT | LUT-RAM and SRL16E sites | FF | "
           "slices~ | path cells | Yosys s |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, p in cap["inputs"].items():
        parts = [(f"array, {n} testers", a) for n, a in sorted(p["array"].items(),
                                                             key=lambda x: -int(x[0]))]
        parts.append(("ray-triangle", p["rtu"]))
        for label, r in parts:
            out.append(f"| {name} | {label} | {r.get('latency', '-')} | {r['dsp48']} | "
                       f"{r['luts']} | {r.get('lutram', '-')} | {r['ffs']} | "
                       f"{r['slices_est']} | {r['path_cells']} | {r.get('seconds', '-')} |")
        rest = p["rest"]
        basis = ", ".join(f"{k}={v}" for k, v in rest["basis"].items()
                          if k not in ("rows", "cols"))
        out.append(f"| {name} | rest (whole unit {basis} minus its parts) | - | "
                   f"{rest['dsp48']} | {rest['luts']} | - | {rest['ffs']} | "
                   f"{rest['slices_est']} | ({rest['path_cells']}: whole unit) | - |")
    for fam, rc in cap.get("reduce_cost", {}).items():
        basis = ", ".join(f"{k}={v}" for k, v in rc["basis"].items() if k not in ("rows", "cols"))
        out.append(f"| {fam} | the reduction (whole unit {basis} minus the same unit without "
                   f"it; BRAM {rc['bram']:+d}) | - | {rc['dsp48']} | {rc['luts']} | - | "
                   f"{rc['ffs']} | {rc['slices_est']} | ({rc['path_cells']}: whole unit) | - |")
    cal = ", ".join(f"{fam} {n:+d}" for fam, n in cap["bram_calibration"].items())
    out += ["", "Block RAM: the per-lane model, plus K times the ray-triangle part's own (its "
            "output FIFO with the DSP48 adders), plus the difference to Yosys's count at the "
            f"synthesised size (1,024 triangles, 256 spheres): {cal} blocks.", ""]
    if cap["validation"]:
        out += ["The composition against whole-unit syntheses it was not built from:", "",
                "| family | unit | DSP48 predicted / actual | slices~ predicted / actual | "
                "error | LUT error | FF error | slices~ of the summed cells (error) | BRAM "
                "predicted / actual | whole unit's path cells |",
                "|---|---|---|---|---|---|---|---|---|---|"]
        for v in cap["validation"]:
            o = ", ".join(f"{k}={x}" for k, x in v["options"].items() if k not in ("rows", "cols"))
            err = {k: v[k]["error"] for k in ("slices_est", "luts", "ffs")}
            out.append(f"| {v['family']} | {o} | {v['dsp48']['predicted']} / "
                       f"{v['dsp48']['actual']} | {v['slices_est']['predicted']} / "
                       f"{v['slices_est']['actual']} | {err['slices_est']:+.1%} | "
                       f"{err['luts']:+.1%} | {err['ffs']:+.1%} | {v['slices_of_summed_cells']} "
                       f"({v['slices_of_summed_cells'] / v['slices_est']['actual'] - 1:+.1%}) | "
                       f"{v['bram']['predicted']} / "
                       f"{v['bram']['actual']} | {v['path_cells']} |")
    else:
        out += ["No whole-unit synthesis other than the rest's basis was available: the "
                "composition is not validated in this run."]
    miss = cap.get("missing") or []
    if miss:
        out += ["", "Not synthesised in this run (rows that need them are left out): "
                + "; ".join(f"{m['unit']} {m['options']} {m['family']}" for m in miss) + "."]
    return out
