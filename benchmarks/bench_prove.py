"""Proof table of issue 23: every FP unit proved against the contract, with times.

Runs :func:`raplas_hdl.formal.prove` on ``fp-add`` and ``fp-mul`` at FP16, FP20, FP24 and
FP32 in rtz, rne and chop at the registry's default stage count, the comparisons and
negation (``fp-le``, ``fp-lt``, ``fp-neg``: one stage, no rounding) at each format, then
every stage count
of both units at FP24 rtz, the multiplier's chain at every format (rtz), and the
multiplier's direct proof against the FloatingPoint contract at FP24 rtz, 1 stage (the
one the cut replaces; expected: unknown), and the stall/reset properties (``control``, and
their port-level form with SymbiYosys, ``sby``) of both units at every format (rtz,
default stages), and every unit's synthesised netlists (``netlist-ecp5``, ``netlist-xc4v``:
``synth_ecp5`` with the DSP register packing, ``synth_xilinx -family xc4v``) against its RTL
at every format and rounding, and the ``virtex4`` target of both units (DSP48 through Yosys's
model of it) at every format and rounding it takes (significands of at most 17 bits),
and the ray-triangle unit by composition (paper, conservative and certified mode, FP16 and
FP24: its wiring around its operations as uninterpreted functions;
:mod:`raplas_hdl.formal.composition`).
One solver call at a time, each bounded by ``--timeout`` (a composition proof by at least
an hour). Each record notes the 1-minute load average before and after it (the machine is
shared).

Then the intersection unit's stream stages with SymbiYosys
(:mod:`raplas_hdl.formal.streams`). Writes ``docs/results/proofs.json`` (merged by unit,
format, rounding, stages, method, target, so a partial run updates its rows; the stream
stages under ``streams``) and the tables between the markers of ``docs/formal.md``.

Usage::

    python benchmarks/bench_prove.py [--timeout 300] [--formats FP16 FP24 ...]
                                     [--only-missing] [--units ray-triangle ...]
    python benchmarks/bench_prove.py --stages credit-fifo sync-fifo-buffered
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from raplas_hdl.fp import PRESETS, ROUNDINGS, parse_format  # noqa: E402
from raplas_hdl.formal import default_stages, prove  # noqa: E402
from raplas_hdl.formal.prove import (  # noqa: E402
    NETLIST_METHODS, ONE_STAGE, UNITS, composition_method)
from raplas_hdl.formal.streams import STAGES, check_stage  # noqa: E402
from raplas_hdl.rtl.fp_add import ADD_STEPS  # noqa: E402
from raplas_hdl.rtl.fp_mul import MUL_STEPS  # noqa: E402

JSON = ROOT / "docs" / "results" / "proofs.json"
DOC = ROOT / "docs" / "formal.md"
BEGIN, END = "<!-- proofs:begin -->", "<!-- proofs:end -->"
S_BEGIN, S_END = "<!-- streams:begin -->", "<!-- streams:end -->"
MAX_STAGES = {"fp-add": len(ADD_STEPS), "fp-mul": len(MUL_STEPS)}
#: The least solver time a composition proof gets, whatever ``--timeout`` says: 445 to
#: 1,207 s at FP16 and FP24 (one solver call each, docs/formal.md).
COMPOSITION_TIMEOUT = 3600.0


def _default(unit, name, rounding):
    return default_stages(unit, parse_format(name).with_rounding(rounding))


def plan(formats):
    """``(unit, format name, rounding, stages, method, target, mode)`` in run order, cheap
    ones first (``mode``: the ray-triangle unit's)."""
    jobs = []
    for name in formats:
        for unit in ("fp-mul", "fp-add"):
            for rnd in ROUNDINGS:
                jobs.append((unit, name, rnd, _default(unit, name, rnd), None))
        jobs.append(("fp-mul", name, "rtz", _default("fp-mul", name, "rtz"), "chain"))
        jobs += [(unit, name, "rtz", 1, None) for unit in ONE_STAGE]
        for unit in ("fp-mul", "fp-add"):
            jobs.append((unit, name, "rtz", _default(unit, name, "rtz"), "control"))
            jobs.append((unit, name, "rtz", _default(unit, name, "rtz"), "sby"))
        for method in NETLIST_METHODS:
            for unit in ("fp-mul", "fp-add"):
                jobs += [(unit, name, rnd, _default(unit, name, rnd), method)
                         for rnd in ROUNDINGS]
            jobs += [(unit, name, "rtz", 1, method) for unit in ONE_STAGE]
        if name in ("FP16", "FP24"):
            # the ray-triangle unit's wiring around its operations
            jobs += [("ray-triangle", name, "rtz", 0, None, "generic", mode)
                     for mode in ("paper", "conservative", "certified")]
        if PRESETS[name].man_bits <= 16:
            for unit in ("fp-mul", "fp-add"):
                jobs += [(unit, name, rnd, _default(unit, name, rnd), None, "virtex4")
                         for rnd in ROUNDINGS]
    for unit in ("fp-mul", "fp-add"):
        for n in range(1, MAX_STAGES[unit] + 1):
            if n != _default(unit, "FP24", "rtz"):
                jobs.append((unit, "FP24", "rtz", n, None))
    jobs.append(("fp-mul", "FP24", "rtz", 1, "direct"))
    jobs = [j if len(j) == 7 else (*j, "paper") if len(j) == 6 else (*j, "generic", "paper")
            for j in jobs]
    # the slow ones last
    return sorted(jobs, key=lambda j: (j[1] == "FP32", j[4] == "direct"))


def key(r):
    return (r["unit"], r["format"], r["rounding"], r["stages"], r["method"].split(":")[0],
            r.get("target", "generic"))


def load():
    return json.loads(JSON.read_text())["proofs"] if JSON.exists() else []


def load_streams():
    return json.loads(JSON.read_text()).get("streams", []) if JSON.exists() else []


def stream_table(rows):
    lines = ["| stage | what | result | how | seconds | load |", "|---|---|---|---|---:|---|"]
    for r in sorted(rows, key=lambda r: r["stage"]):
        how = "; ".join(st["proves"].split(": ", 1)[1] for st in r["steps"])
        lines.append(f"| {r['stage']} | {r['what']} | {r['result']} | {how} | "
                     f"{r['seconds']:.1f} | {r['load'][0]:.1f} / {r['load'][1]:.1f} |")
    return "\n".join(lines)


def _between(text, begin, end, body):
    if begin not in text or end not in text:
        return text
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    return f"{head}{begin}\n{body}\n{end}{tail}"


def table(rows):
    lines = ["| unit | target | format | rounding | stages | method | result | seconds | "
             "solver s | load |", "|---|---|---|---|---|---|---|---:|---:|---|"]
    order = {n: i for i, n in enumerate(PRESETS)}
    for r in sorted(rows, key=lambda r: (r["unit"], r.get("target", "generic"),
                                         order.get(r["format"], 9), r["rounding"],
                                         r["stages"], r["method"])):
        solver = sum(s["seconds"] for s in r["steps"])
        lines.append(f"| {r['unit']} | {r.get('target', 'generic')} | {r['format']} | "
                     f"{r['rounding']} | {r['stages']} | "
                     f"{r['method'].split(':')[0]} | {r['result']} | {r['seconds']:.1f} | "
                     f"{solver:.1f} | {r['load'][0]:.1f} / {r['load'][1]:.1f} |")
    return "\n".join(lines)


def write(rows, streams=None):
    streams = load_streams() if streams is None else streams
    JSON.parent.mkdir(parents=True, exist_ok=True)
    meta = {"machine": f"{platform.machine()}, {os.cpu_count()} cores (shared)",
            "python": platform.python_version(), "written": time.strftime("%Y-%m-%d %H:%M UTC",
                                                                           time.gmtime()),
            "load": "1-minute load average before / after each proof"}
    JSON.write_text(json.dumps({"meta": meta, "proofs": rows, "streams": streams}, indent=1,
                               sort_keys=True) + "\n")
    if DOC.exists():
        text = _between(DOC.read_text(), BEGIN, END, table(rows))
        DOC.write_text(_between(text, S_BEGIN, S_END, stream_table(streams)))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--timeout", type=float, default=300.0, help="seconds per solver call")
    p.add_argument("--formats", nargs="+", default=list(PRESETS), help="default: all presets")
    p.add_argument("--units", nargs="+", choices=list(UNITS), default=None,
                   help="only these units (default all; no stream stage then, unless "
                        "--stages)")
    p.add_argument("--only-missing", action="store_true",
                   help="skip the rows proofs.json already has")
    p.add_argument("--stages", nargs="+", choices=list(STAGES), default=None,
                   help="check only these stream stages (no FP proof)")
    args = p.parse_args(argv)
    rows = {key(r): r for r in load()}
    for unit, name, rnd, stages, method, target, mode in ([] if args.stages else
                                                           plan(args.formats)):
        if args.units and unit not in args.units:
            continue
        fmt = PRESETS[name].with_rounding(rnd)
        label = method or UNITS[unit][1]
        k = (unit, name, rnd, stages,
             composition_method(mode) if label == "composition" else label, target)
        if args.only_missing and k in rows:
            continue
        before = os.getloadavg()[0]
        timeout = (max(args.timeout, COMPOSITION_TIMEOUT) if label == "composition"
                   else args.timeout)
        res = prove(unit, fmt, stages, method=method, timeout=timeout, cwd=ROOT,
                    target=target, mode=mode)
        rec = {**res.as_dict(), "load": [round(before, 2), round(os.getloadavg()[0], 2)]}
        rows[key(rec)] = rec
        print(f"{unit:12} {target:7} {name:5} {rnd:4} s{stages} {k[4]:6} {res.result:14} "
              f"{res.seconds:7.1f} s  load {rec['load']}", flush=True)
        write(list(rows.values()))
    streams = {r["stage"]: r for r in load_streams()}
    for stage in args.stages or ([] if args.units else STAGES):
        if args.only_missing and stage in streams:
            continue
        before = os.getloadavg()[0]
        rec = check_stage(stage, timeout=args.timeout, cwd=ROOT)
        streams[stage] = {**rec, "load": [round(before, 2), round(os.getloadavg()[0], 2)]}
        print(f"{stage:16} {rec['result']:14} {rec['seconds']:7.1f} s", flush=True)
        write(list(rows.values()), list(streams.values()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
