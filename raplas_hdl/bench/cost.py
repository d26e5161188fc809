"""Hardware cost of a format: Yosys resources of the ray-triangle unit it implies.

Synthesising the whole ray-triangle unit takes Yosys 3 to 6 minutes per format and rounding,
too slow for a sweep of twelve. The cost of a format is therefore *composed* from the
synthesised FP operators: the division-free Moller-Trumbore datapath of
``shared/spec/raplas.md`` has **18 multipliers and 15 adders** (``T = V0 - O``: 3 adds;
``det = N.D``, ``t' = N.T``, ``u' = -Q.E2``, ``v' = Q.E1``: 3 multiplies and 2 adds each;
``Q = D x T``: 6 multiplies and 3 adds; ``u' + v'``: 1 add), so

    cost(fmt) = 18 x fp-mul(fmt) + 15 x fp-add(fmt)

in DSP48, LUTs, flip-flops, carry cells and the slice estimate of :mod:`raplas_hdl.synth`
(the comparators, pipeline delay lines and control are left out; where the unit itself was
synthesised, the report shows both). The scalar cost used for the Pareto front is the
fraction of one XC4VSX35 the unit occupies, ``max(DSP48 / 192, slices / 15360)``: the
binding resource, so that ``1 / cost`` is the number of units that fit.

Every operator row goes through :func:`raplas_hdl.synth.report.synth_row` (Yosys's result
cached under ``build/synth``); with ``allow_json`` a row that is not cached is taken from the
committed ``docs/results/synthesis.json`` (``raplas-hdl synth``) before Yosys is run.

**The device** (:func:`device_unit`, :func:`device_cycles`): frame time on one XC4VSX35.
The *device unit* is the synthesised intersection unit of ``docs/results/synthesis.json``
(``raplas-hdl synth intersection-unit``: a 4x4 bundle, one plane-sphere tester per plane,
so :data:`DEVICE_TESTERS` = 8 testers, with its memories, selector, FIFOs and ray-triangle
unit). At FP24 its DSP48, slices and block RAM are the synthesised row's; at another format
they are *estimated* from it: the FP24 row plus the difference of the composed operators
(18 fp-mul + 15 fp-add of the ray-triangle unit, 3 fp-mul + 3 fp-add per tester) between
that format and FP24, block RAM scaled by the word width (``ceil(BRAM * W / 24)``). The units
that fit are :func:`raplas_hdl.synth.report.capacity`'s: the minimum over DSP48, slices
and block RAM (0 when one unit does not fit).

The cycles a unit needs for a frame (:func:`run_cycles`), from the model's counters of the
render, per run ``u`` (one bundle of ``P = rows + cols`` planes and its list of ``S_u``
leaf spheres, ``N_u`` pairs issued)::

    cycles_u = P                      load the bundle's planes into the testers (1/clock)
             + S_u * G                spheres through the array, G = ceil(P / testers)
             + (G + 17 + 1)           the array's latency (passes, tester, decoder)
             + N_u                    pairs into the ray-triangle unit, one per clock
             + L_rt                   its pipeline latency: 41 (paper), 47 (conservative)

summed over the runs of the frame. The stages are taken one after the other (no overlap
between the array and the pair issue, nor between runs), so this is an upper bound on the
RTL's time for the same runs; :func:`run_cycles` with ``overlap=True`` gives the bound the
other way (``max(S_u * G, N_u)`` instead of the sum). Pairs skipped for disabled rays and
the host's hierarchy cull (software) are not counted. The frame time is
``cycles / units / clock``: the runs spread evenly over the units that fit, at the board's
100 MHz or the paper's clocks (:data:`CLOCKS_MHZ`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from ..fp import FP24, FPFormat
from ..model.plane_sphere import n_passes
from ..synth.report import DEFAULT_OPTIONS, DEVICE, PAPER, capacity, synth_row

__all__ = ["RT_MULS", "RT_ADDS", "TESTER_MULS", "TESTER_ADDS", "RESOURCES", "SYNTH_JSON",
           "DEVICE_ROWS", "DEVICE_COLS", "DEVICE_TESTERS", "LAT_MUL", "LAT_ADD",
           "TESTER_LATENCY", "CLOCKS_MHZ", "rt_latency", "array_latency", "run_cycles",
           "device_cycles", "device_unit", "unit_row", "format_cost", "synth_checks"]

#: Operators of the ray-triangle unit.
RT_MULS, RT_ADDS = 18, 15
#: Operators of one plane-sphere tester (``d = n.C + p``: 3 products, 3 sums).
TESTER_MULS, TESTER_ADDS = 3, 3
#: The device unit's bundle (the synthesised intersection unit's) and its testers (one per
#: plane: the unit's default).
DEVICE_ROWS = DEFAULT_OPTIONS["intersection-unit"]["rows"]
DEVICE_COLS = DEFAULT_OPTIONS["intersection-unit"]["cols"]
DEVICE_TESTERS = DEVICE_ROWS + DEVICE_COLS
#: Pipeline depths of the generic FP multiplier and adder at their defaults in rtz
#: (:data:`raplas_hdl.rtl.step_delays.DEFAULT_STAGES`, which a test compares): the device
#: unit's FP24 rtz.
LAT_MUL, LAT_ADD = 4, 6
#: A plane-sphere tester: 4 multiplier, 2 x 6 adder stages and the comparator (17).
TESTER_LATENCY = LAT_MUL + 2 * LAT_ADD + 1
#: Clocks of the frame time: the paper's board, and its place-and-route Fmax.
CLOCKS_MHZ = {"board": PAPER["board_mhz"],
              "paper plane-sphere Fmax": PAPER["plane-sphere"]["fmax_mhz"],
              "paper ray-triangle Fmax": PAPER["ray-triangle"]["fmax_mhz"]}


def rt_latency(mode: str) -> int:
    """The ray-triangle unit's latency: ``5 La + 2 Lm + 3`` (paper, 41), one adder more in
    the conservative mode (47); :attr:`raplas_hdl.rtl.ray_triangle.RayTriangleUnit.latency`."""
    return 5 * LAT_ADD + 2 * LAT_MUL + 3 + (LAT_ADD if mode == "conservative" else 0)


def array_latency(passes: int) -> int:
    """The plane-sphere array's latency: ``G`` passes, the tester, the decoder register."""
    return passes + TESTER_LATENCY + 1


def run_cycles(rows: int, cols: int, runs, spheres, pairs, mode: str, *,
               testers: int = DEVICE_TESTERS, overlap_core=None) -> int:
    """Cycles of ``runs`` runs of ``rows`` x ``cols`` bundles that tested ``spheres`` spheres
    and issued ``pairs`` pairs (totals), module docstring. ``overlap_core``: the sum over
    the runs of ``max(S_u * G, N_u)`` (replaces ``spheres * G + pairs``)."""
    planes = rows + cols
    g = n_passes(rows, cols, testers)
    fill = planes + array_latency(g) + rt_latency(mode)
    core = spheres * g + pairs if overlap_core is None else overlap_core
    return int(runs * fill + core)


def device_cycles(passes: list, mode: str, *, overlap: bool = False) -> int:
    """Cycles of a frame from its per-bundle-size counters (``passes``: dicts with ``rows``,
    ``cols``, ``testers``, ``runs``, ``spheres``, ``pairs``, ``overlap_core``)."""
    return sum(run_cycles(p["rows"], p["cols"], p["runs"], p["spheres"], p["pairs"], mode,
                          testers=p.get("testers", DEVICE_TESTERS),
                          overlap_core=p["overlap_core"] if overlap else None)
               for p in passes)
#: Resource columns summed by the composition.
RESOURCES = ("dsp48", "luts", "ffs", "carry", "slices_est", "bram")
#: The committed synthesis report.
SYNTH_JSON = Path(__file__).resolve().parents[2] / "docs" / "results" / "synthesis.json"


def _label(fmt: FPFormat) -> str:
    return str(fmt).split("/")[0]


def _json_row(unit: str, fmt: FPFormat, path=SYNTH_JSON) -> dict | None:
    try:
        rows = json.loads(Path(path).read_text())["rows"]
    except (OSError, ValueError, KeyError):
        return None
    for r in rows:
        if (r.get("unit") == unit and r.get("format") == _label(fmt)
                and r.get("rounding") == fmt.rounding):
            return r
    return None


def unit_row(unit: str, fmt: FPFormat, *, allow_json: bool = False, run_yosys: bool = True,
             cache_dir=None) -> dict:
    """One unit's synthesis row with a ``source`` field.

    Order: the Yosys cache (``build/synth``); then, with ``allow_json``, the committed
    synthesis report; then (``run_yosys``) a fresh Yosys run.

    Raises
    ------
    LookupError
        When no source has the row.
    """
    try:
        row = synth_row(unit, fmt, cache_dir=cache_dir, cached_only=True)
        row["source"] = "yosys (cached)"
        return row
    except LookupError:
        pass
    if allow_json:
        row = _json_row(unit, fmt)
        if row is not None:
            row = dict(row)
            row["source"] = "docs/results/synthesis.json"
            return row
    if not run_yosys:
        raise LookupError(f"{unit} {fmt}: no cached synthesis result")
    row = synth_row(unit, fmt, cache_dir=cache_dir)
    row["source"] = f"yosys (ran {row['seconds']:.0f} s)"
    return row


def format_cost(fmt: FPFormat, *, allow_json: bool = False, cache_dir=None) -> dict:
    """Composed resources of the ray-triangle unit at ``fmt`` (see the module docstring).

    Returns
    -------
    dict
        ``format``, ``rounding``, the :data:`RESOURCES` of the unit, ``device_fraction``,
        ``units_fit``, the per-operator rows' figures and their ``sources``.
    """
    mul = unit_row("fp-mul", fmt, allow_json=allow_json, cache_dir=cache_dir)
    add = unit_row("fp-add", fmt, allow_json=allow_json, cache_dir=cache_dir)
    out = {"format": _label(fmt), "rounding": fmt.rounding, "basis": f"{RT_MULS} fp-mul + "
           f"{RT_ADDS} fp-add"}
    for k in RESOURCES:
        out[k] = RT_MULS * int(mul.get(k, 0)) + RT_ADDS * int(add.get(k, 0))
    frac = max(out["dsp48"] / DEVICE["dsp48"], out["slices_est"] / DEVICE["slices"])
    out["device_fraction"] = frac
    out["units_fit"] = int(1.0 // frac) if frac > 0 else 0
    out["fp_mul"] = {k: mul.get(k) for k in RESOURCES + ("path_cells",)}
    out["fp_add"] = {k: add.get(k) for k in RESOURCES + ("path_cells",)}
    out["sources"] = sorted({mul["source"], add["source"]})
    return out


def synth_checks(rounding: str = "rtz", *, full: bool = False, cache_dir=None) -> dict:
    """Synthesis checks of issue 6 at FP24: the multiplier's DSP48 (target exactly 1) and the
    plane-sphere tester's (target at most 3), synthesised through the cache (Yosys runs when
    the cache has no result). With ``full``, also the synthesised ray-triangle unit when a
    cached or committed row exists (never run here: it takes minutes), to compare with the
    composed cost.
    """
    fmt = FP24.with_rounding(rounding)
    out = {}
    for unit in ("fp-mul", "plane-sphere-tester"):
        r = unit_row(unit, fmt, cache_dir=cache_dir)
        out[unit] = {"format": "FP24", "rounding": rounding, "source": r["source"],
                     **{k: r[k] for k in RESOURCES + ("path_cells", "latency")}}
    if full:
        try:
            r = unit_row("ray-triangle", fmt, allow_json=True, run_yosys=False,
                         cache_dir=cache_dir)
            out["ray-triangle"] = {"format": "FP24", "rounding": rounding, "source": r["source"],
                                   **{k: r[k] for k in RESOURCES + ("path_cells", "latency")}}
        except LookupError:
            pass
    return out


def _json_unit_rows(unit: str, path=SYNTH_JSON) -> list:
    try:
        return [r for r in json.loads(Path(path).read_text())["rows"] if r.get("unit") == unit]
    except (OSError, ValueError, KeyError):
        return []


def device_unit(fmt: FPFormat, fmt_cost: dict | None = None, *, fp24_cost: dict | None = None,
                path=SYNTH_JSON) -> dict:
    """Resources of the device unit at ``fmt`` and how many fit on one XC4VSX35 (module
    docstring). ``fmt_cost``, ``fp24_cost``: :func:`format_cost` of ``fmt`` and of FP24 at
    the same rounding (computed when not given).

    Returns
    -------
    dict
        ``dsp48``, ``slices_est``, ``bram``, ``basis`` (``synthesised`` or ``estimated``),
        ``units``, ``binding``, ``limits``, ``units_with_margin``, ``rows``, ``cols``,
        ``testers``, ``clocks_mhz``.

    Raises
    ------
    LookupError
        When ``docs/results/synthesis.json`` has no intersection unit at FP24 and this
        rounding.
    """
    label, rnd = _label(fmt), fmt.rounding
    rows = _json_unit_rows("intersection-unit", path)
    iu = next((r for r in rows if r.get("format") == "FP24" and r.get("rounding") == rnd
               and r.get("options", {}).get("rows", DEVICE_ROWS) == DEVICE_ROWS
               and r.get("options", {}).get("cols", DEVICE_COLS) == DEVICE_COLS), None)
    if iu is None:
        raise LookupError(f"{_label(FP24)}/{rnd}: no synthesised intersection unit in "
                          f"{path} (raplas-hdl synth intersection-unit)")
    need = {k: int(iu[k]) for k in ("dsp48", "slices_est", "bram")}
    if label == "FP24" and fmt.exp_bits == 7 and fmt.man_bits == 16:
        basis = "synthesised"
    else:
        basis = "estimated"
        mine = fmt_cost or format_cost(fmt, allow_json=True)
        ref = fp24_cost or format_cost(FP24.with_rounding(rnd), allow_json=True)
        for k in ("dsp48", "slices_est"):
            d_mul = int(mine["fp_mul"][k]) - int(ref["fp_mul"][k])
            d_add = int(mine["fp_add"][k]) - int(ref["fp_add"][k])
            need[k] += ((RT_MULS + DEVICE_TESTERS * TESTER_MULS) * d_mul
                        + (RT_ADDS + DEVICE_TESTERS * TESTER_ADDS) * d_add)
        need["bram"] = math.ceil(need["bram"] * fmt.width / FP24.width)
    cap = capacity([{"unit": "intersection-unit", "format": label, "rounding": rnd, **need}],
                   label, rnd, clocks_mhz=CLOCKS_MHZ)
    return {"format": label, "rounding": rnd, "basis": basis, **need,
            "source": f"{rel_path(path)} (intersection-unit FP24/{rnd}, rows {DEVICE_ROWS}, "
                      f"cols {DEVICE_COLS})", "rows": DEVICE_ROWS, "cols": DEVICE_COLS,
            "testers": DEVICE_TESTERS, "units": int(cap["units"]),
            "binding": cap["binding"], "limits": cap["limits"],
            "units_with_margin": int(cap["units_with_margin"]), "clocks_mhz": dict(CLOCKS_MHZ)}


def rel_path(path) -> str:
    """``path`` relative to the project's folder where it lies inside it (results name the
    project's files, not a machine's)."""
    root = Path(__file__).resolve().parents[2]
    try:
        return str(Path(path).resolve().relative_to(root))
    except ValueError:
        return str(path)
