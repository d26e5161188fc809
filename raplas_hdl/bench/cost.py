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
"""

from __future__ import annotations

import json
from pathlib import Path

from ..fp import FPFormat
from ..synth.report import DEVICE

__all__ = ["RT_MULS", "RT_ADDS", "RESOURCES", "SYNTH_JSON", "unit_row", "format_cost",
           "synth_checks"]

#: Operators of the ray-triangle unit.
RT_MULS, RT_ADDS = 18, 15
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
    from ..synth.report import synth_row

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
    from ..fp import FP24

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
