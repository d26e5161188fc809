"""On-chip reduction: result traffic with and without it, and pairs the any-hit early-out
saves, on real render passes through the FP24 golden model.

Each scene is rendered through the model backend (:func:`raplas_hdl.host.reduction_passes.
recorded_runs`): every pass the renderer hands the unit (primary tiles, and the soft-shadow
bundles of every early-out round the host already runs) is kept with its window. Each pass's
runs then go through the model's ``run_runs`` twice, without and with
``UnitConfig.reduce``:

- without: one ``RESULT`` beat per issued pair (one ``empty`` beat for a run without pairs);
- with: one ``ANSWER`` beat per ray with an answer (one ``empty`` beat for a run without);

bits = beats x the record's width for the pass's unit configuration. The reduced answers are
checked against the host's choice on the unreduced stream, ray for ray (``host_choice``),
and the count of rays where they differ is reported (expected 0). Early-out: pairs of an
any-hit run issued after their ray's first accepted hit (``early_out_saving``, the saving of
an early-out without latency; the RTL saves at most this, ``tests/rtl/test_reduction_unit.py``).

With ``--certified`` each scene is also rendered in ``certified`` mode and its passes go
through the certified unit (``UnitConfig(mode="certified")``): without the reduction one
``RESULT_CERTIFIED`` beat per pair (its ``outcome``); with it the run's uncertain pairs
(``outcome`` 2) and its answers (``outcome`` 1). Reported: result beats, answer and uncertain
beats, traffic saved (bits), uncertain pairs as a share of the pairs, and the rays where the
host's certified resolution of the reduced stream differs from that of the unreduced one
(``resolve_streams``): in the triangle (expected 0), or only in ``t`` (where the unreduced
stream had a second hit whose float64 interval overlaps the answer's, the host computed the
exact ``t``; the reduced stream lacks it and the host takes the interval's midpoint), with
the largest relative difference of ``t``.

With ``--rtl icarus|verilator`` the shadow passes of the first scene at ``--rtl-size`` also
go through the reduced unit's Verilog in a live simulation
(:class:`raplas_hdl.sim.drive.unit_harness.UnitSession`): its answers must equal the model's, and
its ``pairs_issued`` gives the early-out's real saving beside the zero-latency bound.

Usage::

    python benchmarks/bench_reduction.py [--scenes cornell,stanford-bunny,showcase]
        [--size 128x128] [--shadow 3x3] [--certified] [--rtl verilator] [--rtl-size 32x32]
        [--out docs/results/reduction.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from raplas_hdl.host.reduction_passes import (host_choice, pass_runs, recorded_runs,  # noqa: E402
                                              resolve_streams)
from raplas_hdl.host.render import RenderSettings  # noqa: E402
from raplas_hdl.model.intersection import run_runs  # noqa: E402
from raplas_hdl.model.records import OUTCOME_UNCERTAIN, answer_record, result_record  # noqa: E402
from raplas_hdl.model.reduction import early_out_saving  # noqa: E402


def _pair(text):
    a, b = text.lower().split("x")
    return int(a), int(b)


def _both_ways(backend, passes):
    """Per recorded pass: ``(rec, config, runs, unreduced, reduced, result bits, answer
    bits)``, its runs through the model without and with the reduction."""
    for rec in passes:
        cfg = backend.config(rec.batch.rows, rec.batch.cols)
        red_cfg = replace(cfg, reduce=True)
        runs = pass_runs(backend, rec, cfg)
        yield (rec, cfg, runs, run_runs(cfg, backend.scene_memory, runs),
               run_runs(red_cfg, backend.scene_memory, runs), result_record(cfg).bind(cfg).size,
               answer_record(red_cfg).bind(red_cfg).size)


def measure(scene: str, size, shadow, rows: int, cols: int) -> dict:
    t0, c0 = time.perf_counter(), time.process_time()
    settings = RenderSettings(width=size[0], height=size[1], rows=rows, cols=cols,
                              shadow_rows=shadow[0], shadow_cols=shadow[1], progress=False)
    backend, passes = recorded_runs(scene, settings)
    out = {}
    for kind in ("primary", "shadow"):
        out[kind] = dict.fromkeys(("runs", "rays", "pairs", "beats", "bits", "answers",
                                   "answer_beats", "answer_bits", "early_out_pairs",
                                   "differs"), 0)
    for rec, cfg, runs, plain, reduced, rw, aw in _both_ways(backend, passes):
        row = out["shadow" if rec.any_hit else "primary"]
        red_cfg = replace(cfg, reduce=True)
        for run, (beats, ctr), (ans, _) in zip(runs, plain, reduced):
            row["runs"] += 1
            row["rays"] += int(run.bundle.enable.sum())
            row["pairs"] += ctr["pairs_issued"]
            row["beats"] += beats.size
            row["bits"] += beats.size * rw
            row["answer_beats"] += ans.size
            row["answer_bits"] += ans.size * aw
            got = np.full(cfg.n_rays, -1)
            if not ans["empty"][0]:
                got[ans["ray_id"].astype(np.int64)] = ans["tri_id"]
                row["answers"] += ans.size
            tri, _ = host_choice(cfg, beats, run.bundle)
            row["differs"] += int(np.count_nonzero((got >= 0) != (tri >= 0)) if rec.any_hit
                                  else np.count_nonzero(got != tri))
            row["early_out_pairs"] += early_out_saving(red_cfg, beats, run.bundle)
        row["beat_bits"], row["answer_beat_bits"] = rw, aw
    for row in out.values():
        row["result_bits_per_answer_bit"] = row["bits"] / max(1, row["answer_bits"])
        row["traffic_saved"] = 1.0 - row["answer_bits"] / max(1, row["bits"])
        row["early_out_fraction"] = row["early_out_pairs"] / max(1, row["pairs"])
    out["wall_s"] = time.perf_counter() - t0
    out["cpu_s"] = time.process_time() - c0
    return out


def measure_certified(scene: str, size, shadow, rows: int, cols: int) -> dict:
    """The certified unit's traffic with and without the reduction on ``scene``'s passes."""
    t0, c0 = time.perf_counter(), time.process_time()
    settings = RenderSettings(width=size[0], height=size[1], rows=rows, cols=cols,
                              shadow_rows=shadow[0], shadow_cols=shadow[1], progress=False)
    backend, passes = recorded_runs(scene, settings, mode="certified")
    out = {}
    for kind in ("primary", "shadow"):
        out[kind] = dict.fromkeys(("runs", "pairs", "uncertain_pairs", "beats", "bits",
                                   "answer_beats", "uncertain_beats", "answer_bits",
                                   "tri_differs", "t_differs", "t_max_rel"), 0)
    for rec, _, _, plain, reduced, rw, aw in _both_ways(backend, passes):
        row = out["shadow" if rec.any_hit else "primary"]
        for (beats, ctr), (ans, _) in zip(plain, reduced):
            row["runs"] += 1
            row["pairs"] += ctr["pairs_issued"]
            row["uncertain_pairs"] += int((beats["outcome"] == OUTCOME_UNCERTAIN).sum())
            row["beats"] += beats.size
            row["bits"] += beats.size * rw
            unc = int((ans["outcome"] == OUTCOME_UNCERTAIN).sum())
            row["uncertain_beats"] += unc
            row["answer_beats"] += ans.size - unc
            row["answer_bits"] += ans.size * aw
        tri_p, t_p = resolve_streams(backend, rec, [b for b, _ in plain])
        tri_r, t_r = resolve_streams(backend, rec, [a for a, _ in reduced])
        row["tri_differs"] += int(np.count_nonzero(tri_p != tri_r))
        t_diff = (tri_p == tri_r) & (tri_p >= 0) & (t_p != t_r)
        row["t_differs"] += int(np.count_nonzero(t_diff))
        if t_diff.any():
            rel = np.abs(t_p[t_diff] - t_r[t_diff]) / np.abs(t_p[t_diff])
            row["t_max_rel"] = max(row["t_max_rel"], float(rel.max()))
        row["beat_bits"], row["answer_beat_bits"] = rw, aw
    for row in out.values():
        row["traffic_saved"] = 1.0 - row["answer_bits"] / max(1, row["bits"])
        row["uncertain_fraction"] = row["uncertain_pairs"] / max(1, row["pairs"])
    out["wall_s"] = time.perf_counter() - t0
    out["cpu_s"] = time.process_time() - c0
    return out


def _table(results: dict, head, cells) -> str:
    """A Markdown table: ``scene``, ``pass`` and ``head``; ``cells(row)`` gives a row's."""
    lines = ["| " + " | ".join(("scene", "pass") + tuple(head)) + " |",
             "|" + "---|" * (len(head) + 2)]
    for scene, res in results.items():
        for kind in ("primary", "shadow"):
            lines.append("| " + " | ".join([scene, kind] + cells(res[kind])) + " |")
    return "\n".join(lines)


def certified_table(results: dict) -> str:
    head = ("runs", "pairs", "uncertain pairs", "result beats", "answer beats",
            "uncertain beats", "MB unreduced", "MB reduced", "traffic saved", "tri_id differs",
            "t differs (largest relative)")
    return _table(results, head, lambda r: [
        f"{r['runs']:,}", f"{r['pairs']:,}",
        f"{r['uncertain_pairs']:,} ({100 * r['uncertain_fraction']:.3f} %)",
        f"{r['beats']:,}", f"{r['answer_beats']:,}", f"{r['uncertain_beats']:,}",
        f"{r['bits'] / 8e6:.2f}", f"{r['answer_bits'] / 8e6:.3f}",
        f"{100 * r['traffic_saved']:.1f} %", f"{r['tri_differs']}",
        f"{r['t_differs']} ({r['t_max_rel']:.1e})"])


def measure_rtl(scene: str, size, shadow, rows: int, cols: int, sim: str) -> dict:
    """Shadow passes of ``scene`` through the reduced unit's RTL: answers against the model,
    pairs issued with the hardware early-out against the model's (no early-out) and the
    zero-latency bound."""
    import resource

    from raplas_hdl.sim.drive.unit_harness import UnitSession

    def children():
        ru = resource.getrusage(resource.RUSAGE_CHILDREN)
        return ru.ru_utime + ru.ru_stime

    t0, c0, k0 = time.perf_counter(), time.process_time(), children()
    settings = RenderSettings(width=size[0], height=size[1], rows=rows, cols=cols,
                              shadow_rows=shadow[0], shadow_cols=shadow[1], progress=False)
    backend, passes = recorded_runs(scene, settings)
    row = dict.fromkeys(("runs", "answers", "answers_differing", "model_pairs", "rtl_pairs",
                         "bound_pairs_saved", "cycles"), 0)
    sessions = {}
    try:
        for rec in passes:
            if not rec.any_hit:
                continue
            cfg = replace(backend.config(rec.batch.rows, rec.batch.cols), reduce=True)
            runs = pass_runs(backend, rec, cfg)
            if cfg not in sessions:
                sessions[cfg] = UnitSession(sim, cfg, backend.scene_memory)
            got = sessions[cfg].run(runs)
            plain = run_runs(replace(cfg, reduce=False), backend.scene_memory, runs)
            want = run_runs(cfg, backend.scene_memory, runs)
            for run, (ans, ctr), (ref, rctr), (beats, _) in zip(runs, got, want, plain):
                row["runs"] += 1
                row["answers"] += int(np.count_nonzero(ref["empty"] == 0))
                row["answers_differing"] += int(ans.size != ref.size or
                                                np.count_nonzero(ans != ref))
                row["model_pairs"] += rctr["pairs_issued"]
                row["rtl_pairs"] += ctr["pairs_issued"]
                row["bound_pairs_saved"] += early_out_saving(cfg, beats, run.bundle)
                row["cycles"] += ctr["cycles"]
    finally:
        for s in sessions.values():
            s.close()
    row["rtl_pairs_saved"] = row["model_pairs"] - row["rtl_pairs"]
    row.update(scene=scene, size=list(size), simulator=sim,
               wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - c0,
               simulator_cpu_s=children() - k0)
    return row


def table(results: dict) -> str:
    head = ("runs", "pairs", "result beats", "bits", "answer beats", "bits", "traffic saved",
            "early-out pairs saved", "answers differing from host")
    return _table(results, head, lambda r: [
        f"{r['runs']:,}", f"{r['pairs']:,}", f"{r['beats']:,}", f"{r['bits'] / 8e6:.2f} MB",
        f"{r['answer_beats']:,}", f"{r['answer_bits'] / 8e6:.3f} MB",
        f"{100 * r['traffic_saved']:.1f} %",
        f"{r['early_out_pairs']:,} ({100 * r['early_out_fraction']:.1f} %)", f"{r['differs']}"])


def save(doc: dict, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1) + "\n")
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="cornell,stanford-bunny,showcase")
    ap.add_argument("--size", type=_pair, default=(128, 128))
    ap.add_argument("--shadow", type=_pair, default=(3, 3))
    ap.add_argument("--tile", type=_pair, default=(8, 8))
    ap.add_argument("--certified", action="store_true",
                    help="also the certified unit's traffic (its rows in 'certified')")
    ap.add_argument("--paper", action=argparse.BooleanOptionalAction, default=True,
                    help="the paper-mode rows (--no-paper: the certified rows only)")
    ap.add_argument("--rtl", choices=("icarus", "verilator"), default=None)
    ap.add_argument("--rtl-size", type=_pair, default=(32, 32))
    ap.add_argument("--out", default="build/reduction/reduction.json")
    args = ap.parse_args(argv)
    results, certified = {}, None
    for scene in args.scenes.split(",") if args.paper else ():
        results[scene] = measure(scene, args.size, args.shadow, *args.tile)
        print(f"{scene}: {results[scene]['wall_s']:.1f} s wall, "
              f"{results[scene]['cpu_s']:.1f} s CPU", flush=True)
    if results:
        print(table(results))
    if args.certified:
        certified = {}
        for scene in args.scenes.split(","):
            certified[scene] = measure_certified(scene, args.size, args.shadow, *args.tile)
            print(f"{scene} certified: {certified[scene]['wall_s']:.1f} s wall, "
                  f"{certified[scene]['cpu_s']:.1f} s CPU", flush=True)
        print(certified_table(certified))
    rtl = None
    if args.rtl:
        rtl = measure_rtl(args.scenes.split(",")[0], args.rtl_size, args.shadow, *args.tile,
                          args.rtl)
        print(f"RTL ({args.rtl}), {rtl['scene']} {rtl['size'][0]}x{rtl['size'][1]} shadow "
              f"passes: {rtl['runs']} runs, {rtl['answers']} answers, "
              f"{rtl['answers_differing']} runs differing from the model; pairs issued "
              f"{rtl['rtl_pairs']:,} of the model's {rtl['model_pairs']:,} (early-out saved "
              f"{rtl['rtl_pairs_saved']:,}; zero-latency bound {rtl['bound_pairs_saved']:,}); "
              f"{rtl['wall_s']:.0f} s wall, {rtl['cpu_s']:.0f} s CPU here and "
              f"{rtl['simulator_cpu_s']:.0f} s in the simulator")
    what = []
    if results:
        what.append("paper mode (scenes): result traffic with and without the on-chip "
                    "reduction, FP24 model; early-out pairs: the zero-latency bound")
    if certified is not None:
        what.append("certified mode (certified): the certified unit's result beats against "
                    "its answer and uncertain beats, FP24 model; rays whose host resolution "
                    "differs between the two streams")
    doc = {"what": "; ".join(what),
           "size": list(args.size), "shadow": list(args.shadow), "tile": list(args.tile),
           "machine": {"cpus": os.cpu_count(), "load": list(os.getloadavg()),
                       "python": platform.python_version()},
           "scenes": results, "rtl": rtl,
           **({"certified": certified} if certified is not None else {})}
    print(f"wrote {save(doc, Path(args.out))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
