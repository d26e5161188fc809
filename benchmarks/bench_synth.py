"""Synthesis table of issue 6, point 3: every unit through Yosys ``synth_xilinx -family xc4v``.

Runs the FP adder and multiplier at FP16/FP20/FP24/FP32 x rtz/rne/chop, the plane-sphere
tester, the 4x4 plane-sphere array, the ray-triangle unit and the intersection unit at the
formats given by ``--big-formats`` (FP24 by default) and all roundings, and the significand
multiplier as DSP48 primitives against the inferred one (point 4), then writes
``docs/results/synthesis.json`` and ``docs/synthesis.md`` (the table beside the paper's and
the XC4VSX35 capacity). The DSP48 option rows also hold the FP adder with
``target="virtex4"`` (two DSP48, issue 15 point 1) beside the generic one at every format
that fits (FP16, FP20, FP24) and rounding. Results are cached under ``build/synth/``: a
re-run only synthesises what changed.

``--capacity`` (issue 15, point 4) instead synthesises the parts of every configuration of
:mod:`raplas_hdl.synth.capacity` (xc4v generic and virtex4, xc7 generic: the arrays with 8
and 4 testers, the ray-triangle unit, whole units for the rest and the validation), taking
rows already in ``docs/results/synthesis.json`` as they are, composes the table with the
pairs per cycle of ``docs/results/throughput.json``, writes ``docs/results/capacity.json``
and replaces the section "Capacity per configuration" of ``docs/synthesis.md``.

Usage::

    python benchmarks/bench_synth.py [--big-formats FP24 FP16 ...] [--roundings rtz ...]
                                     [--units ...] [--no-cache]
    python benchmarks/bench_synth.py --capacity [--cached-only] [--throughput FILE]
    python benchmarks/bench_synth.py --capacity --ecp5-only
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from raplas_hdl.fp import PRESETS, ROUNDINGS, parse_format  # noqa: E402
from raplas_hdl.synth.report import build_report, dsp48_option_rows, write_report  # noqa: E402

FP_UNITS = ("fp-add", "fp-mul")
BIG_UNITS = ("plane-sphere-tester", "plane-sphere", "ray-triangle", "intersection-unit")
RUN_ORDER = ("plane-sphere-tester", "ray-triangle", "intersection-unit", "plane-sphere",
             "fp-mul", "fp-add")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--formats", nargs="+", default=list(PRESETS),
                   help="formats of the FP units (default FP16 FP20 FP24 FP32)")
    p.add_argument("--big-formats", nargs="+", default=["FP24"],
                   help="formats of the tester, arrays and units (default FP24)")
    p.add_argument("--roundings", nargs="+", default=list(ROUNDINGS),
                   help="roundings (default rtz rne chop)")
    p.add_argument("--big-roundings", nargs="+", default=None,
                   help="roundings of the tester, arrays and units (default: --roundings)")
    p.add_argument("--cached-only", action="store_true",
                   help="report only what build/synth/ already holds (no Yosys run)")
    p.add_argument("--units", nargs="+", default=list(RUN_ORDER),
                   help="units to run, in this order (default all, the big ones first)")
    p.add_argument("--no-cache", action="store_true", help="synthesise everything again")
    p.add_argument("--no-dsp48-option", action="store_true",
                   help="skip the DSP48-primitive multiplier and adder rows (issue 6 "
                        "point 4, issue 15 point 1)")
    p.add_argument("--md", default=str(ROOT / "docs" / "synthesis.md"))
    p.add_argument("--json", default=str(ROOT / "docs" / "results" / "synthesis.json"))
    p.add_argument("--ecp5-only", action="store_true",
                   help="with --capacity: only the ECP5 rows again, from docs/results/pnr.json "
                        "(the Xilinx rows of capacity.json as they are; no Yosys run)")
    p.add_argument("--capacity", action="store_true",
                   help="the capacity per configuration (issue 15) only")
    p.add_argument("--throughput", default=str(ROOT / "docs" / "results" / "throughput.json"))
    p.add_argument("--capacity-json", default=str(ROOT / "docs" / "results" / "capacity.json"))
    args = p.parse_args(argv)
    if args.capacity:
        return capacity_main(args)

    def fmts(names, roundings):
        return [parse_format(n).with_rounding(r) for n in names for r in roundings]

    big_roundings = args.big_roundings or args.roundings
    formats = {u: fmts(args.formats, args.roundings) if u in FP_UNITS
               else fmts(args.big_formats, big_roundings) for u in args.units}
    t0 = time.monotonic()
    report = build_report(args.units, formats, use_cache=not args.no_cache,
                          cached_only=args.cached_only, progress=lambda line: print(line, flush=True))
    command = "python benchmarks/bench_synth.py" + (" " + " ".join(argv or sys.argv[1:])
                                                   if (argv or sys.argv[1:]) else "")
    if not args.no_dsp48_option:
        report["dsp48_option"] = dsp48_option_rows(
            [parse_format(n) for n in args.formats], adder_roundings=args.roundings,
            use_cache=not args.no_cache,
            cached_only=args.cached_only, progress=lambda line: print(line, flush=True))
    report["command"] = command
    report["wall_seconds"] = round(time.monotonic() - t0, 1)
    for path in write_report(report, args.md, args.json, command=command):
        print(f"wrote {path}")
    for cap in report["capacity"]:
        print(f"capacity {cap['format']}/{cap['rounding']}: {cap['units']} unit(s) "
              f"(limits {cap['limits']}), {cap['ratio_vs_paper']:.2f}x the paper's pairs/s")
    for m in report["missing"]:
        print(f"missing: {m['unit']} ({m['reason']})")
    return 0


def _write_capacity_section(md: Path, lines: list) -> None:
    """Replace the section "Capacity per configuration" of ``md`` by ``lines``."""
    text = md.read_text()
    head = "## Capacity per configuration (issue 15)"
    if head in text:
        before, rest = text.split(head, 1)
        i = rest.find("\n## ")
        after = rest[i + 1:] if i >= 0 else ""
    else:
        before, after = text.rstrip("\n") + "\n\n", ""
    md.write_text(before + "\n".join(lines) + "\n" + ("\n" + after if after else ""))


def capacity_main(args) -> int:
    """``--capacity``: gather the parts, compose, validate, write JSON and the md section."""
    import json
    import os
    import resource

    from raplas_hdl.cli.synth import CAPACITY_TRIANGLES
    from raplas_hdl.fp import FP24
    from raplas_hdl.synth.capacity import (build_capacity, gather, load_throughput,
                                           render_capacity)

    from raplas_hdl.synth.capacity_ecp5 import ecp5_rows, load_pnr_runs

    t0, c0 = time.monotonic(), time.process_time()
    fmt = FP24
    tp = load_throughput(args.throughput)
    pnr = ROOT / "docs" / "results" / "pnr.json"
    if args.ecp5_only:
        # the Xilinx rows as they are; the ECP5 rows again from the place-and-route results
        cap = json.loads(Path(args.capacity_json).read_text())
        cap.update(ecp5=ecp5_rows(load_pnr_runs(pnr), tp, fmt),
                   ecp5_source=os.path.relpath(pnr, ROOT))
        Path(args.capacity_json).write_text(json.dumps(cap, indent=1, sort_keys=True,
                                                       default=str) + "\n")
        _write_capacity_section(Path(args.md), render_capacity(cap, worst_path=WORST_PATH_CELLS))
        print(f"wrote the ECP5 rows into {args.capacity_json} and {args.md}")
        return 0
    earlier = json.loads(Path(args.json).read_text())["rows"] if Path(args.json).exists() else []
    found = gather(fmt, rows=earlier, cached_only=args.cached_only,
                   progress=lambda line: print(line, flush=True))
    cap = build_capacity(fmt, found["rows"], tp, CAPACITY_TRIANGLES,
                         pnr_runs=load_pnr_runs(pnr) if pnr.exists() else None,
                         pnr_source=os.path.relpath(pnr, ROOT))
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    cap.update(missing=found["missing"], throughput_file=os.path.relpath(args.throughput, ROOT),
               command="python benchmarks/bench_synth.py --capacity"
                       + (" --cached-only" if args.cached_only else ""),
               wall_seconds=round(time.monotonic() - t0, 1),
               cpu_seconds=round(time.process_time() - c0 + children.ru_utime
                                 + children.ru_stime, 1),
               yosys_seconds={f"{u} {dict(o)} {f}": r.get("seconds")
                              for (u, o, f), r in found["rows"].items()})
    Path(args.capacity_json).write_text(json.dumps(cap, indent=1, sort_keys=True,
                                                   default=str) + "\n")
    md = Path(args.md)
    _write_capacity_section(md, render_capacity(cap, worst_path=WORST_PATH_CELLS))
    print(f"wrote {args.capacity_json} and {md}")
    for m in found["missing"]:
        print(f"missing: {m}")
    return 0


#: Today's worst unit at FP24 (the longest combinational path, cells): the ray-triangle and
#: intersection units in rtz (docs/synthesis.md, Units).
WORST_PATH_CELLS = 40


if __name__ == "__main__":
    sys.exit(main())
