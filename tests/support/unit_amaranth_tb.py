"""Amaranth-simulator testbench of the intersection unit (used by
``rtl/test_unit_amaranth.py`` and ``rtl/test_reduction_unit.py``).

:func:`simulate_runs` loads a scene, then runs ``[(BundleMemory, sphere_ids[, keep_all])]``: the
next run's bundle is written into the other bank while the current run goes (the
double-buffered Plane and Ray Memory), a run that reuses the previous bundle rewrites only
its enable bits, and ``o`` sees random back-pressure. Every cycle it asserts that the pair
FIFO is within its depth and its overflow flag is clear.
"""

from __future__ import annotations

import numpy as np
from amaranth.sim import Simulator

from raplas_hdl.model.records import CMD, COUNTERS, output_record
from raplas_hdl.sim.drive.unit_driver import encode_runs


def simulate_runs(unit, scene, runs, *, seed=0, ready_density=0.7, overlap=False,
                  max_cycles=200_000, vcd=None):
    """Results and counters per run, as :func:`raplas_hdl.sim.drive.unit_driver.run_runs`
    gives them."""
    cfg = unit.config
    stim = encode_runs(cfg, scene, runs, overlap=overlap)
    n_runs = len(runs)
    rng = np.random.default_rng(seed)
    state = {"done": 0, "beats": [], "run_of_beat": [], "max_level": 0, "cycles": 0}
    counters = [None] * n_runs
    # the ports' payloads as integers, packed and unpacked with the model's records
    cmd, result, ctrs = CMD.bind(cfg), output_record(cfg).bind(cfg), COUNTERS.bind(cfg)
    last_bit = result["last"].offset

    async def write(ctx, addrs, datas):
        for a, d in zip(addrs.tolist(), datas.tolist()):
            ctx.set(unit.wr_en, 1)
            ctx.set(unit.wr_addr, a)
            ctx.set(unit.wr_data, d)
            await ctx.tick()
        ctx.set(unit.wr_en, 0)

    async def wait_done(ctx, n):
        while state["done"] < n:
            await ctx.tick()

    async def read_counters(ctx, k):
        await ctx.tick()
        value = ctrs.unpack(ctx.get(unit.counters.as_value()))
        counters[k] = {n: int(value[n]) for n in COUNTERS.names}
        ctx.set(unit.clear, 1)
        await ctx.tick()
        ctx.set(unit.clear, 0)

    async def driver(ctx):
        await write(ctx, stim["scene_addr"], stim["scene_data"])
        banks = stim["run_bank"]
        offs = stim["run_offsets"]
        for k in range(n_runs):
            earlier = [j for j in range(k) if banks[j] == banks[k]]
            if earlier:
                await wait_done(ctx, earlier[-1] + 1)
            await write(ctx, stim["run_addr"][offs[k]:offs[k + 1]],
                        stim["run_data"][offs[k]:offs[k + 1]])
            if not overlap and k:
                await wait_done(ctx, k)
                await read_counters(ctx, k - 1)
            ctx.set(unit.cmd.payload.as_value(),
                    cmd.pack({"first": stim["run_first"][k], "count": stim["run_count"][k],
                              "bank": banks[k], "indirect": stim["run_indirect"][k],
                              "keep_all": stim["run_keep_all"][k]}))
            ctx.set(unit.cmd.valid, 1)
            await ctx.tick().until(unit.cmd.ready)
            ctx.set(unit.cmd.valid, 0)
        await wait_done(ctx, n_runs)
        await read_counters(ctx, n_runs - 1)

    async def collector(ctx):
        while True:
            ready = int(rng.random() < ready_density)
            ctx.set(unit.o.ready, ready)
            _, _, valid, payload, level, ovf = await ctx.tick().sample(
                unit.o.valid, unit.o.payload.as_value(), unit.fifo_level, unit.fifo_overflow)
            state["cycles"] += 1
            assert state["cycles"] < max_cycles, "simulation timed out"
            assert level <= cfg.fifo_depth, "pair FIFO above its depth"
            assert not ovf, "pair FIFO overflow"
            state["max_level"] = max(state["max_level"], int(level))
            if valid and ready:
                state["beats"].append(payload)
                state["run_of_beat"].append(state["done"])
                if payload >> last_bit & 1:
                    state["done"] += 1

    sim = Simulator(unit)
    sim.add_clock(1e-6)
    sim.add_testbench(driver)
    sim.add_testbench(collector, background=True)
    if vcd:
        with sim.write_vcd(vcd):
            sim.run()
    else:
        sim.run()
    beats = result.unpack(state["beats"])
    rob = np.array(state["run_of_beat"])
    out = []
    for k in range(n_runs):
        c = counters[k]
        if c is not None:
            c["_max_fifo_level"] = state["max_level"]
        out.append((beats[rob == k], c))
    return out
