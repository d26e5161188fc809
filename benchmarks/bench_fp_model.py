"""Throughput of the FP golden model against NumPy float32 (issue 2, point 7).

Arrays of 10^6 elements, all cores (numba's thread pool), median of several runs after a
warm-up. The ratio is ``numpy_time / model_time``: the fraction of float32 speed the
model reaches (targets: mul >= 1/2, add >= 1/5). Prints a table and writes JSON to
``docs/results/fp_model_bench.json``.

Usage::

    python benchmarks/bench_fp_model.py [--n 1000000] [--repeats 7] [--out FILE]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numba  # noqa: E402

from raplas_hdl.fp import FP24, FP32  # noqa: E402
from raplas_hdl.fp import model  # noqa: E402

TARGETS = {"add": 1 / 5, "sub": 1 / 5, "mul": 1 / 2}


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def median_time(fn, repeats):
    fn()                                             # warm-up (and compile)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), [float(t) for t in times]


def median_cpu(fn, repeats):
    """Median CPU time of the calling thread (``time.thread_time``) over ``repeats`` runs."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.thread_time()
        fn()
        times.append(time.thread_time() - t0)
    return float(np.median(times))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "..", "docs",
                                                  "results", "fp_model_bench.json"))
    args = ap.parse_args(argv)
    if args.repeats < 5:
        ap.error("--repeats must be at least 5")

    rng = np.random.default_rng(1)
    n = args.n
    # Values over several orders of magnitude, both signs: realistic operand mixes with
    # alignment shifts and cancellations, no specials.
    x = rng.choice([-1.0, 1.0], n) * 2.0 ** rng.uniform(-8, 8, n)
    y = rng.choice([-1.0, 1.0], n) * 2.0 ** rng.uniform(-8, 8, n)
    x32, y32 = x.astype(np.float32), y.astype(np.float32)
    np_ops = {"add": np.add, "sub": np.subtract, "mul": np.multiply}
    np_time = {op: median_time(lambda f=f: f(x32, y32), args.repeats)[0]
               for op, f in np_ops.items()}
    # NumPy's ufuncs run on one thread: their CPU time is their idle-machine wall time.
    np_cpu = {op: median_cpu(lambda f=f: f(x32, y32), args.repeats)
              for op, f in np_ops.items()}

    load_before = os.getloadavg()
    rows = []
    cases = [(op, fmt, False) for op in ("add", "mul")
             for fmt in (FP24, FP24.with_rounding("rne"), FP24.with_rounding("chop"),
                         FP32.with_rounding("rne"))]
    cases += [("sub", FP24, False), ("add", FP24, True), ("mul", FP24, True)]
    for op, fmt, flags in cases:
        a, b = model.encode(x, fmt), model.encode(y, fmt)
        fn = getattr(model, op)
        t, runs = median_time(lambda: fn(a, b, fmt, flags=flags), args.repeats)
        ratio = np_time[op] / t
        rows.append({"op": op, "format": str(fmt), "flags": flags, "n": n,
                     "model_ms": t * 1e3, "numpy_float32_ms": np_time[op] * 1e3,
                     "model_Mops_per_s": n / t / 1e6, "ratio_vs_float32": ratio,
                     "target": TARGETS[op], "meets_target": ratio >= TARGETS[op],
                     "model_best_ms": min(runs) * 1e3,
                     "model_runs_ms": [r * 1e3 for r in runs]})
    # CPU time of one thread: on a shared, loaded machine wall times of the parallel loops
    # mostly measure the scheduler; this is the per-core cost that an idle machine divides
    # by its cores. ``est_ratio_idle`` = numpy time / (1-thread CPU time / threads).
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    for r, (op, fmt, flags) in zip(rows, cases):
        a, b = model.encode(x, fmt), model.encode(y, fmt)
        fn = getattr(model, op)
        cpu = median_cpu(lambda: fn(a, b, fmt, flags=flags), args.repeats)
        r["model_cpu_ms_1thread"] = cpu * 1e3
        r["numpy_float32_cpu_ms"] = np_cpu[op] * 1e3
        r["est_ratio_idle"] = np_cpu[op] / (cpu / threads)
        r["est_meets_target_idle"] = r["est_ratio_idle"] >= TARGETS[op]
    numba.set_num_threads(threads)
    load_after = os.getloadavg()

    result = {
        "benchmark": "fp_model throughput vs numpy float32",
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "machine": {"nproc": os.cpu_count(),
                    "affinity": len(os.sched_getaffinity(0)),
                    "cpu_model": cpu_model(),
                    "numba_threads": numba.get_num_threads(),
                    "numba_threading_layer": numba.threading_layer(),
                    "loadavg_before": load_before, "loadavg_after": load_after,
                    "python": platform.python_version(), "numpy": np.__version__,
                    "numba": numba.__version__},
        "method": f"median of {args.repeats} runs after one warm-up; arrays of {n} elements; "
                  "ratio = numpy float32 time / model time (higher is better), wall times "
                  "on a possibly loaded machine (see loadavg); est_ratio_idle = numpy "
                  "float32 one-thread CPU time / (model one-thread CPU time / threads), "
                  "the ratio an idle machine with these threads would show (NumPy's "
                  "ufuncs are single-threaded); CPU times by time.thread_time",
        "rows": rows,
    }
    print(f"{n} elements, {numba.get_num_threads()} threads, {cpu_model()}, "
          f"load {load_before[0]:.1f} -> {load_after[0]:.1f}")
    print(f"{'op':4} {'format':10} {'flags':5} {'model ms':>9} {'f32 ms':>7} {'Mop/s':>7} "
          f"{'ratio':>6} {'1thr cpu':>8} {'f32 cpu':>7} {'est idle':>8} {'target':>6}")
    for r in rows:
        print(f"{r['op']:4} {r['format']:10} {str(r['flags']):5} {r['model_ms']:9.2f} "
              f"{r['numpy_float32_ms']:7.2f} {r['model_Mops_per_s']:7.1f} "
              f"{r['ratio_vs_float32']:6.3f} {r['model_cpu_ms_1thread']:8.2f} "
              f"{r['numpy_float32_cpu_ms']:7.2f} {r['est_ratio_idle']:8.3f} {r['target']:6.2f}"
              f"{'' if r['meets_target'] else '  wall below target'}"
              f"{'' if r['est_meets_target_idle'] else '  est below target'}")
    out = os.path.abspath(args.out)
    os.makedirs(os.path.dirname(out), exist_ok=True)
    with open(out, "w") as f:
        json.dump(result, f, indent=2)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
