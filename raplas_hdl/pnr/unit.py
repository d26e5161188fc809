"""Place and route of a registered unit (``raplas-hdl pnr``), and its JSON and Markdown.

:func:`pnr_unit` builds the unit as ``raplas-hdl verilog`` does (:func:`raplas_hdl.rtl.units.
build_unit`, the same Verilog bytes), runs :func:`.ecp5.run_flow` and returns one JSON-ready
record: the unit, format and options, latency, resources, Fmax per clock over the seeds, the
critical path of the median seed, tool time, the command and the tool versions, so that every
figure can be reproduced. With ``copies`` > 1 the design is that many units side by side
(:class:`raplas_hdl.rtl.copies.Copies`, each on its own ports): how many fit, at what clock.
:func:`write_pnr_report` writes the record as ``<stem>.json`` and ``<stem>.md``
(:func:`report_stem`: ``fp-add``, ``fp-add-x2``, ``fp-add-ulx3s``).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterable
from pathlib import Path

from ..rtl.emit import emit_verilog
from ..rtl.units import UNITS, build_unit
from .ecp5 import PACKAGE, run_flow, synthesize_ecp5
from .fit import check_fit

__all__ = ["pnr_unit", "design", "unit_verilog", "flow_record", "check_copies",
           "write_pnr_report", "markdown", "summary_line", "report_stem", "lut4_fraction"]


def design(unit: str, fmt, options: dict, copies: int = 1) -> tuple:
    """``(component, module, params)`` of ``unit`` built with ``options`` as ``verilog``
    builds it; ``copies`` > 1: that many side by side (module ``<unit>_x<copies>``)."""
    # lazy: rtl.copies loads Amaranth, needed only to build the unit
    from ..rtl.copies import Copies

    spec, comp, opts = build_unit(unit, fmt, **options)
    params = {"exp_bits": fmt.exp_bits, "man_bits": fmt.man_bits, "rounding": fmt.rounding,
              **opts}
    for opt in ("target", "adder"):
        if opt in spec.options:
            params.setdefault(opt, UNITS[unit].options[opt][1])
    if copies == 1:
        return comp, spec.module, params
    comp._MustUse__silence = True          # the first build only names the unit
    return (Copies(lambda: build_unit(unit, fmt, **options)[1], copies),
            f"{spec.module}_x{copies}", {**params, "copies": copies})


def unit_verilog(unit: str, fmt, options: dict, copies: int = 1) -> tuple[str, str, int | None]:
    """``(verilog, module, latency)`` of ``unit`` built with ``options`` as ``verilog`` does
    (``copies`` > 1: :func:`design`'s copies side by side)."""
    comp, module, params = design(unit, fmt, options, copies)
    text, manifest = emit_verilog(comp, module, params)
    return text, module, manifest["latency"]


def lut4_fraction(utilisation: dict) -> float | None:
    """Placed ``TRELLIS_COMB`` (LUT4) over the device's, from nextpnr's utilisation."""
    u = utilisation.get("TRELLIS_COMB")
    return round(u["used"] / u["available"], 5) if u and u["available"] else None


def summary_line(rec: dict) -> str:
    """One line: unit, device, speed, Fmax median (min-max) per clock, LUT4, FF, multipliers
    (with copies: how many, and the device's LUT4 they use)."""
    s = rec["synth"]
    clocks = "; ".join(f"{clk} {f['median']:.1f} MHz (min {f['min']:.1f}, max {f['max']:.1f}, "
                       f"{f['seeds']} seed{'s' if f['seeds'] != 1 else ''})"
                       for clk, f in rec["fmax"].items())
    latency = rec["latency"] if rec["latency"] is not None else "n/a"
    copies = rec.get("copies", 1)
    what = f" x{copies}" if copies > 1 else ""
    line = (f"{rec['unit']} {rec['format']}{what}: {rec['device']} speed {rec['speed']}: "
            f"{clocks}; latency {latency}; LUT4 {s['lut4']}, carry {s['carry']}, FF {s['ff']}, "
            f"MULT18X18D {s['mult18']}, EBR {s['ebr']}")
    if copies > 1 and rec.get("lut4_fraction") is not None:
        line += f"; {copies} copies placed, {rec['lut4_fraction']:.1%} of the device's LUT4"
    return line


def flow_record(unit: str, module: str, fmt, options: dict, latency, flow, *, emit_s: float,
                device: str, speed: int, freq: float, seeds: list, command: str,
                copies: int = 1, out_of_context: bool = True) -> dict:
    """The JSON-ready record of a :class:`.ecp5.FlowResult` (module docstring)."""
    med = flow.median_seed()
    run = flow.runs[med]
    rec = {
        "unit": unit, "module": module, "format": fmt.name, "rounding": fmt.rounding,
        "options": options, "latency": latency, "copies": copies,
        "device": device, "package": PACKAGE, "speed": speed, "freq_target": freq,
        "seeds": seeds, "out_of_context": out_of_context,
        "synth": flow.synth,
        "utilisation": run["utilisation"],
        "lut4_fraction": lut4_fraction(run["utilisation"]),
        "fmax": flow.fmax,
        "fmax_per_seed": {str(s): r["fmax"] for s, r in flow.runs.items()},
        "median_seed": med,
        "critical_path": run["critical_path"],
        "seconds": {"emit": round(emit_s, 2), **flow.seconds,
                    "per_seed": {str(s): r["seconds"] for s, r in flow.runs.items()}},
        "cached_seeds": [s for s, r in flow.runs.items() if r["cached"]],
        "tools": flow.tools,
        "command": command,
        "work": flow.work,
    }
    rec["summary"] = summary_line(rec)
    return rec


def pnr_unit(unit: str, fmt, options: dict, *, device: str = "LFE5U-85F", speed: int = 6,
             freq: float = 100.0, seeds: Iterable[int] = (1, 2, 3), use_cache: bool = True,
             progress: Callable[[str], None] | None = None, command: str | None = None,
             base: Path | None = None, copies: int = 1,
             timing_weight: int | None = None, router: str | None = None) -> dict:
    """Place and route ``unit`` (``copies`` of it side by side) and return the record
    (module docstring). ``ValueError`` when the synthesised design cannot fit ``device``.
    ``timing_weight``: nextpnr's placer timing weight, ``router`` its router (its defaults
    when None)."""
    t0 = time.monotonic()
    if progress:
        progress(f"{unit}: building the Verilog" + (f" ({copies} copies)" if copies > 1 else ""))
    options = {k: v for k, v in options.items() if v is not None}
    what = f"{unit}" + (f" x{copies}" if copies > 1 else "")
    check_copies(unit, fmt, options, copies, device, what, base=base, use_cache=use_cache,
                 progress=progress)
    text, module, latency = unit_verilog(unit, fmt, options, copies)
    emit_s = time.monotonic() - t0
    seeds = list(seeds)
    flow = run_flow(text, module, device=device, speed=speed, freq=freq, seeds=seeds,
                    use_cache=use_cache, base=base, progress=progress,
                    check=lambda counts: check_fit(counts, device, what),
                    timing_weight=timing_weight, router=router)
    rec = flow_record(unit, module, fmt, options, latency, flow, emit_s=emit_s,
                      device=device, speed=speed, freq=freq, seeds=seeds, copies=copies,
                      command=command or pnr_command(unit, fmt, options, device, speed, freq,
                                                  len(seeds), copies,
                                                  timing_weight=timing_weight,
                                                  router=router))
    rec["placer_timing_weight"] = timing_weight
    rec["router"] = router or "router1"
    return rec


def check_copies(unit: str, fmt, options: dict, copies: int, device: str, what: str, *,
                 io: int = 0, base: Path | None = None, use_cache: bool = True,
                 progress: Callable[[str], None] | None = None) -> None:
    """With ``copies`` > 1: ``ValueError`` when ``copies`` times one unit's synthesis (the
    single unit's netlist, cached with its own runs) already exceeds ``device``, before the
    copies are synthesised together."""
    if copies == 1:
        return
    text, module, _ = unit_verilog(unit, fmt, options)
    one = synthesize_ecp5(text, module, base=base, use_cache=use_cache, progress=progress)
    check_fit({k: v * copies for k, v in one.counts.items()}, device, what, io=io)


def pnr_command(unit, fmt, options, device, speed, freq, n, copies=1, bitstream=False,
             timing_weight=None, router=None) -> str:
    parts = ["raplas-hdl pnr", unit, "--format", fmt.name]
    for k, v in sorted(options.items()):
        flag = "--" + k.replace("_", "-")
        parts += [flag] if v is True else [flag, str(v)]
    parts += ["--device", device, "--speed", str(speed)]
    if not bitstream:
        parts += ["--freq", f"{freq:g}"]
    parts += ["--seeds", str(n)]
    if copies > 1:
        parts += ["--copies", str(copies)]
    if bitstream:
        parts.append("--bitstream")
    if timing_weight is not None:
        parts += ["--placer-timing-weight", str(timing_weight)]
    if router is not None:
        parts += ["--router", router]
    return " ".join(parts)


def markdown(rec: dict) -> str:
    """The record as a Markdown report."""
    s, u = rec["synth"], rec["utilisation"]
    copies = rec.get("copies", 1)
    bit = rec.get("bitstream")
    what = f"`{rec['unit']}`" + (f", {copies} copies side by side," if copies > 1 else "")
    if bit and "pll" in bit:
        what += f" (the board design: UARTBone bridge, board top, PLL) on the {bit['board']},"
        context = (f"In context: every port placed by `{bit['lpf_name']}` (below), clock "
                   f"{bit['clock']} from the PLL at {bit['pll']['f_out_mhz']:g} MHz (the "
                   f"board's 25 MHz oscillator times {bit['pll']['clkfb_div']} over "
                   f"{bit['pll']['clki_div']}; place and route aimed at "
                   f"{rec['freq_target']:g} MHz), router {rec.get('router', 'router1')}")
    elif bit:
        what += f" behind the serial wrapper on the {bit['board']},"
        context = (f"In context: every port placed by `{bit['lpf_name']}` (below), clock "
                   f"{bit['clock']} constrained to {rec['freq_target']:g} MHz (the board's "
                   "oscillator)")
    else:
        context = f"Out of context (ports unplaced), target {rec['freq_target']:g} MHz"
    out = [f"# {what} placed and routed on {rec['device']} ({rec['package']}), "
           f"speed {rec['speed']}", "",
           f"`{rec['command']}`", "",
           f"Format {rec['format']}, options {json.dumps(rec['options']) or '{}'}, latency "
           + (f"{rec['latency']} cycles" if rec["latency"] is not None else "n/a")
           + f". {context}, seeds {', '.join(map(str, rec['seeds']))}.",
           "", "| clock | Fmax median | min | max |", "|---|--:|--:|--:|"]
    for clk, f in rec["fmax"].items():
        out.append(f"| {clk} | **{f['median']:.1f} MHz** | {f['min']:.1f} | {f['max']:.1f} |")
    out += ["", "| resource (synth_ecp5) | count |", "|---|--:|"]
    for name, key in (("LUT4", "lut4"), ("carry (CCU2C)", "carry"), ("FF", "ff"),
                      ("MULT18X18D", "mult18"), ("ALU54B", "alu54"), ("EBR (DP16KD)", "ebr"),
                      ("distributed RAM (DPR16X4)", "dram")):
        out.append(f"| {name} | {s[key]:,} |")
    if u:
        out += ["", f"| placed (nextpnr, seed {rec['median_seed']}) | used | of | fraction |",
                "|---|--:|--:|--:|"]
        for k, v in u.items():
            if v["used"]:
                out.append(f"| {k} | {v['used']:,} | {v['available']:,} | "
                           f"{v['used'] / v['available']:.2%} |")
    cp = rec["critical_path"]
    if cp:
        out += ["", f"Critical path (seed {rec['median_seed']}): `{cp['start']}` -> "
                    f"`{cp['end']}`, {cp['total_ns']:.2f} ns = {cp['logic_ns']:.2f} logic + "
                    f"{cp['routing_ns']:.2f} routing + {cp['clk_to_q_ns']:.2f} clock-to-out "
                    f"+ {cp['setup_ns']:.2f} setup, {cp['cells']} cells; signals: "
                    + " -> ".join(f"`{x}`" for x in cp["signals"])]
    if bit:
        out += ["", f"Bitstream: `{bit['path']}`, {bit['bytes']:,} bytes (yowasp-ecppack, "
                    f"seed {bit['seed']}, {bit['ecppack_seconds']:.1f} s); sha256 "
                    f"`{bit['sha256'][:16]}...`.", "",
                "| port | site | from | IOBUF |", "|---|---|---|---|"]
        for port, p in bit["pins"].items():
            out.append(f"| {port} | {p['site']} | {p['from']} | "
                       + " ".join(f"{k}={v}" for k, v in p["attrs"].items()) + " |")
        if "svf" in bit:
            out += ["", f"SVF: `{bit['svf']}`, {bit['svf_bytes']:,} bytes. UART "
                        f"{bit['baud']:,.0f} baud (divisor {bit['divisor']}; asked "
                        f"{bit['baud_asked']:,}). Load: `openFPGALoader -b ulx3s "
                        f"{Path(bit['path']).name}`."]
        w = bit.get("wrapper")
        if w is not None:
            out += ["", f"Serial words: {w['in_bits']} bits in, {w['out_bits']} bits out, "
                        "bit 0 first (`raplas_hdl/rtl/serial_wrapper.py`).", "",
                    "| input field | bits | | output field | bits |", "|---|--:|---|---|--:|"]
            ins, outs = w["in_fields"], w["out_fields"]
            for i in range(max(len(ins), len(outs))):
                a = ins[i] if i < len(ins) else None
                b = outs[i] if i < len(outs) else None
                out.append(f"| {a[0] if a else ''} | {_bits(a)} | | {b[0] if b else ''} | "
                           f"{_bits(b)} |")
    sec = rec["seconds"]
    out += ["", f"Tool time: synthesis {sec['synthesis']:.1f} s"
                f"{' (cached)' if sec.get('synthesis_cached') else ''}, place and route "
                f"{sec['place_and_route']:.1f} s over {len(rec['seeds'])} seeds. Tools: "
                + ", ".join(f"{k} {v}" for k, v in rec["tools"].items()) + ".", ""]
    return "\n".join(out)


def _bits(field) -> str:
    if not field:
        return ""
    _, off, width = field
    return f"{off}" if width == 1 else f"{off}-{off + width - 1}"


def report_stem(rec: dict) -> str:
    """The report's file name stem: the unit, ``-x<copies>``, ``-<board>`` for a bitstream."""
    stem = rec["unit"]
    if rec.get("copies", 1) > 1:
        stem += f"-x{rec['copies']}"
    if rec.get("bitstream"):
        stem += "-" + rec["bitstream"]["board"].lower()
    return stem


def write_pnr_report(rec: dict, out_dir) -> list[Path]:
    """Write ``<stem>.json`` and ``<stem>.md`` (:func:`report_stem`) into ``out_dir``;
    returns the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = report_stem(rec)
    jpath, mpath = out_dir / f"{stem}.json", out_dir / f"{stem}.md"
    jpath.write_text(json.dumps(rec, indent=1, sort_keys=True) + "\n")
    mpath.write_text(markdown(rec))
    return [jpath, mpath]
