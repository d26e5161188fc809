"""Place and route of a registered unit (``raplas-hdl pnr``), and its JSON and Markdown.

:func:`pnr_unit` builds the unit as ``raplas-hdl verilog`` does (:func:`raplas_hdl.rtl.units.
build_unit`, the same Verilog bytes), runs :func:`.ecp5.run_flow` and returns one JSON-ready
record: the unit, format and options, latency, resources, Fmax per clock over the seeds, the
critical path of the median seed, tool time, the command and the tool versions, so that every
figure can be reproduced. :func:`write_pnr_report` writes it as ``<unit>.json`` and
``<unit>.md``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterable
from pathlib import Path

from .ecp5 import PACKAGE, run_flow

__all__ = ["pnr_unit", "unit_verilog", "write_pnr_report", "markdown", "summary_line"]


def unit_verilog(unit: str, fmt, options: dict) -> tuple[str, str, int | None]:
    """``(verilog, module, latency)`` of ``unit`` built with ``options`` as ``verilog`` does."""
    from ..rtl.emit import emit_verilog
    from ..rtl.units import UNITS, build_unit

    spec, comp, opts = build_unit(unit, fmt, **options)
    params = {"exp_bits": fmt.exp_bits, "man_bits": fmt.man_bits, "rounding": fmt.rounding,
              **opts}
    for opt in ("target", "adder"):
        if opt in spec.options:
            params.setdefault(opt, UNITS[unit].options[opt][1])
    text, manifest = emit_verilog(comp, spec.module, params)
    return text, spec.module, manifest["latency"]


def summary_line(rec: dict) -> str:
    """One line: unit, device, speed, Fmax median (min-max) per clock, LUT4, FF, multipliers."""
    s = rec["synth"]
    clocks = "; ".join(f"{clk} {f['median']:.1f} MHz (min {f['min']:.1f}, max {f['max']:.1f}, "
                       f"{f['seeds']} seed{'s' if f['seeds'] != 1 else ''})"
                       for clk, f in rec["fmax"].items())
    latency = rec["latency"] if rec["latency"] is not None else "n/a"
    return (f"{rec['unit']} {rec['format']}: {rec['device']} speed {rec['speed']}: {clocks}; "
            f"latency {latency}; LUT4 {s['lut4']}, carry {s['carry']}, FF {s['ff']}, "
            f"MULT18X18D {s['mult18']}, EBR {s['ebr']}")


def pnr_unit(unit: str, fmt, options: dict, *, device: str = "LFE5U-85F", speed: int = 6,
             freq: float = 100.0, seeds: Iterable[int] = (1, 2, 3), use_cache: bool = True,
             progress: Callable[[str], None] | None = None, command: str | None = None,
             base: Path | None = None) -> dict:
    """Place and route ``unit`` and return the record (module docstring)."""
    t0 = time.monotonic()
    if progress:
        progress(f"{unit}: building the Verilog")
    options = {k: v for k, v in options.items() if v is not None}
    text, module, latency = unit_verilog(unit, fmt, options)
    emit_s = time.monotonic() - t0
    seeds = list(seeds)
    flow = run_flow(text, module, device=device, speed=speed, freq=freq, seeds=seeds,
                    use_cache=use_cache, base=base, progress=progress)
    med = flow.median_seed()
    run = flow.runs[med]
    rec = {
        "unit": unit, "module": module, "format": fmt.name, "rounding": fmt.rounding,
        "options": options, "latency": latency,
        "device": device, "package": PACKAGE, "speed": speed, "freq_target": freq,
        "seeds": seeds, "out_of_context": True,
        "synth": flow.synth,
        "utilisation": run["utilisation"],
        "fmax": flow.fmax,
        "fmax_per_seed": {str(s): r["fmax"] for s, r in flow.runs.items()},
        "median_seed": med,
        "critical_path": run["critical_path"],
        "seconds": {"emit": round(emit_s, 2), **flow.seconds,
                    "per_seed": {str(s): r["seconds"] for s, r in flow.runs.items()}},
        "cached_seeds": [s for s, r in flow.runs.items() if r["cached"]],
        "tools": flow.tools,
        "command": command or _command(unit, fmt, options, device, speed, freq, len(seeds)),
        "work": flow.work,
    }
    rec["summary"] = summary_line(rec)
    return rec


def _command(unit, fmt, options, device, speed, freq, n) -> str:
    parts = ["raplas-hdl pnr", unit, "--format", fmt.name]
    for k, v in sorted(options.items()):
        flag = "--" + k.replace("_", "-")
        parts += [flag] if v is True else [flag, str(v)]
    parts += ["--device", device, "--speed", str(speed), "--freq", f"{freq:g}", "--seeds", str(n)]
    return " ".join(parts)


def markdown(rec: dict) -> str:
    """The record as a Markdown report."""
    s, u = rec["synth"], rec["utilisation"]
    out = [f"# `{rec['unit']}` placed and routed on {rec['device']} ({rec['package']}), "
           f"speed {rec['speed']}", "",
           f"`{rec['command']}`", "",
           f"Format {rec['format']}, options {json.dumps(rec['options']) or '{}'}, latency "
           f"{rec['latency']} cycles. Out of context (ports unplaced), target "
           f"{rec['freq_target']:g} MHz, seeds {', '.join(map(str, rec['seeds']))}.", "",
           "| clock | Fmax median | min | max |", "|---|--:|--:|--:|"]
    for clk, f in rec["fmax"].items():
        out.append(f"| {clk} | **{f['median']:.1f} MHz** | {f['min']:.1f} | {f['max']:.1f} |")
    out += ["", "| resource (synth_ecp5) | count |", "|---|--:|"]
    for name, key in (("LUT4", "lut4"), ("carry (CCU2C)", "carry"), ("FF", "ff"),
                      ("MULT18X18D", "mult18"), ("ALU54B", "alu54"), ("EBR (DP16KD)", "ebr"),
                      ("distributed RAM (DPR16X4)", "dram")):
        out.append(f"| {name} | {s[key]:,} |")
    if u:
        out += ["", "| placed (nextpnr) | used | of |", "|---|--:|--:|"]
        for k, v in u.items():
            if v["used"]:
                out.append(f"| {k} | {v['used']:,} | {v['available']:,} |")
    cp = rec["critical_path"]
    if cp:
        out += ["", f"Critical path (seed {rec['median_seed']}): `{cp['start']}` -> "
                    f"`{cp['end']}`, {cp['total_ns']:.2f} ns = {cp['logic_ns']:.2f} logic + "
                    f"{cp['routing_ns']:.2f} routing + {cp['clk_to_q_ns']:.2f} clock-to-out "
                    f"+ {cp['setup_ns']:.2f} setup, {cp['cells']} cells; signals: "
                    + " -> ".join(f"`{x}`" for x in cp["signals"])]
    sec = rec["seconds"]
    out += ["", f"Tool time: synthesis {sec['synthesis']:.1f} s"
                f"{' (cached)' if sec.get('synthesis_cached') else ''}, place and route "
                f"{sec['place_and_route']:.1f} s over {len(rec['seeds'])} seeds. Tools: "
                + ", ".join(f"{k} {v}" for k, v in rec["tools"].items()) + ".", ""]
    return "\n".join(out)


def write_pnr_report(rec: dict, out_dir) -> list[Path]:
    """Write ``<unit>.json`` and ``<unit>.md`` into ``out_dir``; returns the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = rec["unit"]
    jpath, mpath = out_dir / f"{stem}.json", out_dir / f"{stem}.md"
    jpath.write_text(json.dumps(rec, indent=1, sort_keys=True) + "\n")
    mpath.write_text(markdown(rec))
    return [jpath, mpath]
