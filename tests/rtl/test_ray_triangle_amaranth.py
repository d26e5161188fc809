# amaranth: UnusedElaboratable=no
"""RayTriangleUnit in Amaranth's simulator against the golden model, every output bit.

Each check streams vectors of all stress families plus special patterns, and pairs with
known per-operation event counts, through the unit with a gap-free burst first (one pair
per clock, result after ``latency`` cycles) and then random gaps and back-pressure, and
compares every field of every result (the per-pair event counts included), in order,
with :func:`raplas_hdl.model.ray_triangle.intersect`.
"""

import random

import numpy as np
import pytest
from amaranth.hdl import Fragment
from amaranth.sim import Simulator

from raplas_hdl.fp import FP24, FPFormat
from raplas_hdl.model.stress_cases import vectors
from raplas_hdl.rtl.ray_triangle import EVENTS, RayTriangleUnit
from tests.support.ray_triangle import (NAMES, compare, event_pairs, expected, pack_inputs,
                                        unpack_outputs)


def run_unit(dut, payloads, burst, idle, stall, seed):
    """Drive ``payloads`` (the first ``burst`` without gaps or stalls); returns results,
    the cycle of each acceptance and of each result, and i.ready/o.ready independence."""
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    got, t_in, t_out = [], [], []
    state = {"cycle": 0, "coupled": 0}
    n = len(payloads)

    async def driver(ctx):
        # stream rule: a raised valid (and its payload) stays until the transfer; the
        # idle inserter draws a gap only between pairs
        rng = random.Random(seed)
        i, valid = 0, False
        while i < n:
            if not valid:
                valid = i < burst or rng.random() >= idle
            ctx.set(dut.i.valid, int(valid))
            ctx.set(dut.i.payload.as_value(), payloads[i])
            _, _, ready = await ctx.tick().sample(dut.i.ready)
            if ready and valid:
                t_in.append(state["cycle"])
                i += 1
                valid = False
        ctx.set(dut.i.valid, 0)

    async def monitor(ctx):
        rng = random.Random(seed + 1)
        while len(got) < n and state["cycle"] < 40 * n + 500:
            take = len(got) < burst or rng.random() >= stall
            # i.ready must not depend on o.ready within a cycle
            ctx.set(dut.o.ready, 1 - int(take))
            r0 = ctx.get(dut.i.ready)
            ctx.set(dut.o.ready, int(take))
            state["coupled"] += int(r0 != ctx.get(dut.i.ready))
            _, _, valid, payload = await ctx.tick().sample(dut.o.valid,
                                                            dut.o.payload.as_value())
            if valid and take:
                got.append(payload)
                t_out.append(state["cycle"])
            state["cycle"] += 1
        for _ in range(6):          # nothing more may come out
            ctx.set(dut.o.ready, 1)
            _, _, valid = await ctx.tick().sample(dut.o.valid)
            assert not valid, "the unit produced more results than it took pairs"

    sim.add_testbench(driver)
    sim.add_testbench(monitor)
    sim.run()
    return got, t_in, t_out, state["coupled"]


def check_unit(fmt, mode, count, seed, idle=0.3, stall=0.4, burst=30):
    dut = RayTriangleUnit(fmt, mode=mode)
    vec = vectors(fmt, count, seed)
    # after the burst, pairs with known event counts (several operations per event)
    ev, want = event_pairs(fmt)
    vec = {k: np.concatenate([vec[k], ev[i]]) for i, k in enumerate(NAMES)}
    count = len(vec["o"])
    rng = np.random.default_rng(seed)
    ray_ids = rng.integers(0, 1 << 16, count)
    tri_ids = rng.integers(0, 1 << 16, count)
    got, t_in, t_out, coupled = run_unit(dut, pack_inputs(fmt, vec, ray_ids, tri_ids), burst,
                                         idle, stall, seed)
    assert coupled == 0, "i.ready changed with o.ready in the same cycle"
    assert len(got) == count, f"{len(got)} results for {count} pairs"
    # the gap-free burst: one pair per clock, each result exactly `latency` cycles later
    assert t_in[:burst] == list(range(t_in[0], t_in[0] + burst))
    assert [b - a for a, b in zip(t_in[:burst], t_out[:burst])] == [dut.latency] * burst
    exp = expected(fmt, vec, ray_ids, tri_ids, mode)
    compare(unpack_outputs(fmt, got), exp)
    counts = np.stack([exp[f"n_{e}"] for e in EVENTS], axis=1)[-len(want):]
    assert np.array_equal(counts, want)
    return exp


def test_paper_fp24_rtz():
    exp = check_unit(FP24, "paper", 64, seed=1)
    assert exp["hit"].sum() >= 5          # the vectors exercise both outcomes


def test_conservative_fp24_chop():
    exp = check_unit(FP24.with_rounding("chop"), "conservative", 64, seed=2)
    assert 5 <= exp["hit"].sum() < 64


@pytest.mark.parametrize("kwargs, latency", [
    ({}, 5 * 6 + 2 * 4 + 3),           # FP24 rtz: adders of 6 stages, multipliers of 4
    ({"mode": "conservative"}, 6 * 6 + 2 * 4 + 3),
    ({"add_stages": 2, "mul_stages": 2}, 5 * 2 + 2 * 2 + 3),
])
def test_latency_matches_schedule(kwargs, latency):
    unit = RayTriangleUnit(FP24, **kwargs)
    Fragment.get(unit, None)            # elaborates (the schedule asserts itself)
    assert unit.latency == latency


@pytest.mark.parametrize("kwargs, word", [
    ({"mode": "fast"}, "mode"),
    ({"ray_id_bits": 0}, "ray_id_bits"),
    ({"tri_id_bits": 65}, "tri_id_bits"),
    ({"add_stages": 0}, "add_stages"),
    ({"mode": "conservative", "margin_scale": -1}, "margin_scale"),
])
def test_bad_parameters(kwargs, word):
    with pytest.raises(ValueError, match=word):
        RayTriangleUnit(FP24, **kwargs)


def test_conservative_needs_fraction_bits():
    with pytest.raises(ValueError, match="man_bits"):
        RayTriangleUnit(FPFormat(4, 3), mode="conservative")
