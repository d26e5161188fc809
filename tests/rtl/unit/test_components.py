"""The intersection unit's stages (:mod:`raplas_hdl.rtl.unit`), each alone in Amaranth's
simulator against its model counterpart.

Every stage reads its memories through read ports that a background testbench serves as a
synchronous RAM (:func:`serve`); stream drivers hold ``valid`` until the transfer, and
collectors apply random back-pressure. The whole unit against the model:
``rtl/test_unit_amaranth.py`` (Amaranth), ``rtl/test_unit_cocotb.py`` (Icarus, Verilator).
"""

import numpy as np
import pytest
from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.fifo import SyncFIFOBuffered
from amaranth.sim import Simulator

from raplas_hdl.fp import FPFormat
from raplas_hdl.model.intersection import enumerate_pairs
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.memory_image import bundle_writes, run_list_writes, scene_writes
from raplas_hdl.model.records import (CMD, COUNTERS, PAIR, PLANE, RAY, RESULT, RT_RESULT,
                                      TRIANGLE)
from raplas_hdl.rtl.unit.feeder import SphereFeeder
from raplas_hdl.rtl.unit.fetch import RecordFetch
from raplas_hdl.rtl.unit.framing import EVENTS_LAYOUT, EventCounters, ResultFraming
from raplas_hdl.rtl.unit.memories import MEMORIES, WriteDecoder, memory_geometry
from raplas_hdl.rtl.unit.selector import PairSelector
from raplas_hdl.rtl.unit.streams import job_layout, mask_layout, sphere_layout, tag_layout
from raplas_hdl.sim.drive.unit_driver import random_bundle, random_scene
from tests.support.unit_scenes import model_runs, scene_and_runs

CFG = UnitConfig(fmt=FPFormat(5, 6), rows=2, cols=3, testers=2, tris_per_sphere=3,
                 max_triangles=32, max_spheres=24, fifo_depth=4)


# -- testbench helpers --------------------------------------------------------------------------
def serve(port, words):
    """A background testbench: ``port`` (a stage's read port) reads ``words`` as a
    synchronous RAM does (the word at the address of the last clock with ``en``)."""
    async def ram(ctx):
        async for _, _, addr, en in ctx.tick().sample(port.addr, port.en):
            if en:
                ctx.set(port.data, int(words[addr]) if addr < len(words) else 0)
    return ram


async def wait_until(ctx, done, limit=5000):
    """Clock until ``done()`` holds; fail after ``limit`` cycles (a stage that stopped)."""
    for _ in range(limit):
        if done():
            return
        await ctx.tick()
    raise AssertionError(f"no progress in {limit} cycles")


async def put(ctx, stream, payload):
    """Offer ``payload`` on ``stream``, ``valid`` held until the transfer."""
    ctx.set(stream.payload.as_value(), payload)
    ctx.set(stream.valid, 1)
    await ctx.tick().until(stream.ready)
    ctx.set(stream.valid, 0)


def collector(stream, out, rng, density, *extra):
    """A background testbench: random ``ready``; appends each payload taken to ``out``
    (with the values of ``extra`` in that cycle when given)."""
    async def get(ctx):
        while True:
            ready = int(rng.random() < density)
            ctx.set(stream.ready, ready)
            _, _, valid, payload, *more = await ctx.tick().sample(
                stream.valid, stream.payload.as_value(), *extra)
            if valid and ready:
                out.append((int(payload), *map(int, more)) if extra else int(payload))
    return get


def run_sim(top, testbench, *background):
    sim = Simulator(top)
    sim.add_clock(1e-6, if_exists=True)      # (none for a combinational stage)
    sim.add_testbench(testbench)
    for bench in background:
        sim.add_testbench(bench, background=True)
    sim.run()


def pack(layout, **values):
    """An integer of an Amaranth ``StructLayout`` from field values (absent fields 0)."""
    return sum((int(values.get(name, 0)) & ((1 << f.width) - 1)) << f.offset
               for name, f in layout)


def unpack(layout, value):
    return {name: int(value) >> f.offset & ((1 << f.width) - 1) for name, f in layout}


def lanes(rows, width):
    """Words of lanes of ``width`` bits, lane k = column k (a record memory's word)."""
    rows = np.asarray(rows, np.uint64).reshape(len(rows), -1)
    return [sum(int(v) << (k * width) for k, v in enumerate(row)) for row in rows]


def scene_words(cfg, scene):
    """Sphere Memory, triangle counts, triangle lists and Triangle Memory, as words."""
    w = cfg.fmt.width
    tlist = np.zeros(cfg.max_spheres * cfg.tris_per_sphere, np.int64)
    for s in range(scene.n_spheres):
        n = int(scene.tri_counts[s])
        tlist[s * cfg.tris_per_sphere:][:n] = scene.tri_lists[s, :n]
    tri = TRIANGLE.bind(cfg).pack({"v0": scene.v0, "e1": scene.e1, "e2": scene.e2,
                                   "n": scene.n})
    return {"sphere": lanes(np.column_stack([scene.centres, scene.radii]), w),
            "count": [int(c) for c in scene.tri_counts], "tlist": tlist.tolist(),
            "tri": tri}


def bundle_words(cfg, bundles):
    """Plane Memory, Ray Memory and the enable bits of ``bundles`` (bank 0, bank 1)."""
    planes = sum((PLANE.bind(cfg).pack({"nx": b.plane_n[:, 0], "ny": b.plane_n[:, 1],
                                        "nz": b.plane_n[:, 2], "p": b.plane_p})
                  for b in bundles), [])
    rays = sum((RAY.bind(cfg).pack({"o": b.ray_o, "d": b.ray_d}) for b in bundles), [])
    return {"plane": planes, "ray": rays,
            "enable": np.concatenate([b.enable for b in bundles]).astype(int).tolist()}


@pytest.fixture(scope="module")
def scene():
    return random_scene(CFG, 24, seed=3, empty_spheres=2)


@pytest.fixture(scope="module")
def bundles():
    return [random_bundle(CFG, seed=4, disable=0.3), random_bundle(CFG, seed=5, disable=0.3)]


# -- write decoder -----------------------------------------------------------------------------
def test_write_decoder_fills_the_memory_image(scene, bundles):
    """The model's writes (scene, both banks, a run list, and writes beyond a memory or
    field) leave the memories holding the model's records."""
    cfg = CFG
    dut = WriteDecoder(cfg)
    ids = np.array([5, 1, 1, 7])
    parts = [scene_writes(cfg, scene), bundle_writes(cfg, bundles[0], 0),
             bundle_writes(cfg, bundles[1], 1), run_list_writes(cfg, ids, 1),
             (np.array([0x1000_0000 | (cfg.max_spheres << 4), 0x0000_000C, 0x3000_0004]),
              np.array([9, 9, 9]))]   # a sphere index, a triangle field, a plane field
    addrs = np.concatenate([p[0] for p in parts]).tolist()
    datas = np.concatenate([p[1] for p in parts]).tolist()
    geometry = memory_geometry(cfg)
    mems = {k: [0] * depth for k, (_, depth, _) in geometry.items()}
    plane_writes = []

    async def bench(ctx):
        for a, d in zip(addrs, datas):
            ctx.set(dut.wr_en, 1)
            ctx.set(dut.wr_addr, a)
            ctx.set(dut.wr_data, d)
            for key, (width, _, lane) in geometry.items():
                port = getattr(dut, key)
                en, addr, data = ctx.get(port.en), ctx.get(port.addr), ctx.get(port.data)
                for k in range(width // lane):
                    if en >> k & 1:
                        mask = ((1 << lane) - 1) << (k * lane)
                        mems[key][addr] = mems[key][addr] & ~mask | data & mask
            plane_writes.append(ctx.get(dut.plane_written))
            await ctx.delay(1e-6)

    run_sim(dut, bench)
    want = scene_words(cfg, scene)
    want.update(bundle_words(cfg, bundles))
    for key, words in want.items():
        assert mems[key][:len(words)] == list(words), f"{MEMORIES[key]} differs"
    assert mems["rlist"][cfg.max_spheres:][:ids.size] == ids.tolist()
    # the stray writes wrote nothing
    assert not any(mems["sphere"][scene.n_spheres:]) and not any(mems["rlist"][:cfg.max_spheres])
    region, bank = np.array(addrs) >> 28, np.array(addrs) >> 27 & 1
    is_plane = (region == 3) & ((np.array(addrs) >> 4 & 0x7FFFFF) < cfg.n_planes)
    assert plane_writes == np.where(is_plane, 1 << bank, 0).tolist()


# -- sphere feeder -----------------------------------------------------------------------------
def test_feeder_sends_the_runs_spheres_and_loads_stale_planes(scene, bundles):
    """Each run's spheres in order (direct, or from the bank's run list), then its marker;
    the bank's planes copied into the array before a run whose planes are stale (another
    bank, or rewritten by the host), and only when the run before has left the array. The
    ``spheres`` event fires once per sphere, never for a marker."""
    cfg, rng = CFG, np.random.default_rng(7)
    dut = SphereFeeder(cfg, capacity=16)
    top = Module()
    top.submodules.dut = dut
    # the array as a sink of no latency: a sphere leaves it as it enters
    top.d.comb += dut.retired.eq(dut.o.valid & dut.o.ready)
    lists = [rng.integers(0, scene.n_spheres, 9), rng.permutation(scene.n_spheres)[:5]]
    rlist = np.zeros(2 * cfg.max_spheres, np.int64)
    for b, ids in enumerate(lists):
        rlist[b * cfg.max_spheres:][:ids.size] = ids
    # (first, count, bank, indirect, keep_all, the host writes a plane of this bank first)
    runs = [(2, 6, 0, 0, 0, None), (0, 9, 0, 1, 1, None), (0, 5, 1, 1, 0, None),
            (4, 0, 1, 0, 0, 0), (7, 3, 1, 0, 0, 1), (1, 2, 0, 0, 0, None),
            (3, 3, 0, 0, 1, 0)]
    loaded = [0, 2, 4, 5, 6]          # the runs that load planes, and their banks:
    words = scene_words(cfg, scene)
    planes = bundle_words(cfg, bundles)["plane"]
    cmd = CMD.bind(cfg)
    spheres, plane_log, taken, counted = [], [], [], []

    async def bench(ctx):
        for k, (first, count, bank, ind, keep, dirty) in enumerate(runs):
            if dirty is not None:
                # the host rewrites a bank's planes only when its runs have left
                await wait_until(ctx, lambda: len(taken) >= sum(r[1] + 1 for r in runs[:k]))
                ctx.set(dut.plane_written, 1 << dirty)
                await ctx.tick()
                ctx.set(dut.plane_written, 0)
            await put(ctx, dut.cmd, cmd.pack({"first": first, "count": count, "bank": bank,
                                              "indirect": ind, "keep_all": keep}))
        await wait_until(ctx, lambda: len(taken) >= sum(r[1] + 1 for r in runs))

    async def watch(ctx):
        cycle = 0
        async for _, _, en, addr, data, valid, ready, event in ctx.tick().sample(
                dut.pw_en, dut.pw_addr, dut.pw_data.as_value(), dut.o.valid, dut.o.ready,
                dut.spheres):
            counted.append(int(event))
            if en:
                plane_log.append((cycle, int(addr), int(data)))
            if valid and ready:
                taken.append(cycle)
            cycle += 1

    run_sim(top, bench, serve(dut.rlist, rlist), serve(dut.sphere, words["sphere"]),
            serve(dut.plane, planes), watch,
            collector(dut.o, spheres, rng, 0.6))
    tags, sph = tag_layout(cfg), sphere_layout(cfg)
    out = iter(spheres)
    assert sum(counted) == sum(r[1] for r in runs)
    for first, count, bank, ind, keep, _ in runs:
        ids = lists[bank][first:first + count] if ind else np.arange(first, first + count)
        for s in [*ids, None]:
            payload = next(out)
            tag = unpack(tags, unpack(sph, payload)["id"])
            assert (tag["marker"], tag["bank"], tag["keep_all"]) == (s is None, bank, keep)
            if s is not None:
                assert tag["sphere"] == s
                assert payload >> sph["c"].offset == words["sphere"][s]
    assert next(out, None) is None
    want = [(k, planes[runs[r][2] * cfg.n_planes + k]) for r in loaded
            for k in range(cfg.n_planes)]
    assert [(a, d) for _, a, d in plane_log] == want
    # drain rule: every sphere of the runs before a load has left before its first plane
    for j, r in enumerate(loaded):
        first_cycle = plane_log[j * cfg.n_planes][0]
        assert sum(c < first_cycle for c in taken) == sum(x[1] + 1 for x in runs[:r])


# -- pair selector ----------------------------------------------------------------------------
@pytest.mark.parametrize("bank", [0, 1])
def test_selector_matches_enumerate_pairs(scene, bundles, bank):
    """The jobs of a run, expanded into their pairs, are the model's pair enumeration
    (:func:`~raplas_hdl.model.intersection.enumerate_pairs`); the skipped pairs agree; a
    keep-all sphere takes every ray; the marker comes last."""
    cfg, rng = CFG, np.random.default_rng(11 + bank)
    dut = PairSelector(cfg)
    n = 14
    ids = rng.integers(0, scene.n_spheres, n)
    rows = rng.random((n, cfg.rows)) < 0.5
    cols = rng.random((n, cfg.cols)) < 0.6
    keep = rng.random(n) < 0.2
    tags, masks, jl = tag_layout(cfg), mask_layout(cfg), job_layout(cfg)
    jobs, skipped = [], []

    def bits(flags):
        return sum(int(f) << k for k, f in enumerate(flags))

    async def bench(ctx):
        for k in range(n):
            tag = pack(tags, sphere=ids[k], bank=bank, keep_all=keep[k])
            await put(ctx, dut.i, pack(masks, id=tag, row_mask=bits(rows[k]),
                                       col_mask=bits(cols[k])))
        await put(ctx, dut.i, pack(masks, id=pack(tags, marker=1, bank=bank)))
        await wait_until(ctx, lambda: jobs and unpack(jl, jobs[-1])["marker"])

    async def watch_skips(ctx):
        async for _, _, v in ctx.tick().sample(dut.skipped):
            skipped.append(int(v))

    words = scene_words(cfg, scene)
    run_sim(dut, bench, serve(dut.count, words["count"]),
            serve(dut.enable, bundle_words(cfg, bundles)["enable"]),
            collector(dut.o, jobs, rng, 0.5), watch_skips)
    rays, tris = [], []
    for job in map(lambda j: unpack(jl, j), jobs[:-1]):
        s, ntris = job["sid"], job["ntris"]
        assert (job["bank"], job["marker"]) == (bank, 0) and ntris == scene.tri_counts[s]
        rays += [job["ray"]] * ntris
        tris += scene.tri_lists[s, :ntris].tolist()
    ray_ids, tri_ids, skip = enumerate_pairs(
        cfg, rows | keep[:, None], cols | keep[:, None], scene.tri_counts[ids],
        scene.tri_lists[ids], bundles[bank].enable)
    assert rays == ray_ids.tolist() and tris == tri_ids.tolist()
    assert sum(skipped) == skip > 0
    assert len(rays) > 10


# -- record fetch ------------------------------------------------------------------------------
class FetchAndFifo(wiring.Component):
    """The record fetch in front of a ``depth``-entry pair FIFO, as a lane wires them: ``o``
    is the FIFO's read side, the FIFO's reads give the fetch its credits back."""

    def __init__(self, cfg, depth):
        self.fetch = RecordFetch(cfg, depth=depth)
        self._depth = depth
        super().__init__({name: member for name, member in self.fetch.signature.members.items()
                          if name != "freed"})

    def elaborate(self, platform):
        m = Module()
        m.submodules.fetch = fetch = self.fetch
        m.submodules.fifo = fifo = SyncFIFOBuffered(width=fetch.o.payload.shape().size,
                                                    depth=self._depth)
        for name in ("i", "tlist", "tri", "ray"):
            wiring.connect(m, wiring.flipped(getattr(self, name)), getattr(fetch, name))
        wiring.connect(m, fetch.o, fifo.w_stream)
        wiring.connect(m, fifo.r_stream, wiring.flipped(self.o))
        m.d.comb += [fetch.freed.eq(fifo.r_stream.valid & fifo.r_stream.ready),
                     self.overflow.eq(fetch.overflow)]
        return m


@pytest.mark.parametrize("depth", [3, 5, 16])
def test_fetch_pairs_carry_the_model_records(scene, bundles, depth):
    """Each job's triangles in list order, each pair with its ray's and triangle's records
    (the model's ``PAIR``); a marker job gives one pair with the marker bit. The pair FIFO
    behind is read at random: the credits keep every pair (no overflow) at any depth."""
    cfg, rng = CFG, np.random.default_rng(13)
    dut = FetchAndFifo(cfg, depth)
    jl, rb = job_layout(cfg), cfg.ray_id_bits
    jobs = [(int(rng.integers(0, cfg.n_rays)), int(s), int(rng.integers(0, 2)))
            for s in rng.choice(np.nonzero(scene.tri_counts)[0], 10)]
    pairs = []

    async def bench(ctx):
        for ray, s, b in jobs:
            await put(ctx, dut.i, pack(jl, ray=ray, sid=s, bank=b,
                                       ntris=scene.tri_counts[s]))
        await put(ctx, dut.i, pack(jl, ray=3, sid=1, marker=1))
        await wait_until(ctx, lambda: pairs and pairs[-1] >> rb & 1)
        assert not ctx.get(dut.overflow)

    words = scene_words(cfg, scene)
    words.update(bundle_words(cfg, bundles))
    run_sim(dut, bench, serve(dut.tlist, words["tlist"]), serve(dut.tri, words["tri"]),
            serve(dut.ray, words["ray"]), collector(dut.o, pairs, rng, 0.5))
    layout = PAIR.bind(cfg, ray_id_bits=rb + 1)
    want = []
    for ray, s, b in jobs:
        t = scene.tri_lists[s, :scene.tri_counts[s]]
        r = np.full(t.size, ray)
        want += layout.pack({"ray_id": r, "tri_id": t, "o": bundles[b].ray_o[r],
                             "d": bundles[b].ray_d[r], "v0": scene.v0[t], "e1": scene.e1[t],
                             "e2": scene.e2[t], "n": scene.n[t]})
    assert pairs[:-1] == want
    assert pairs[-1] & ((1 << (rb + 1)) - 1) == 3 | 1 << rb


# -- result framing and counters -------------------------------------------------------------
def test_framing_gives_the_models_result_stream():
    """The model's results of every run of :func:`tests.support.unit_scenes.scene_and_runs`,
    each run followed by its marker, come out as the model's result stream (``last`` on each run's
    last beat, one ``empty`` beat for a run without pairs); the counted events are those
    of the results taken."""
    cfg, rng = CFG, np.random.default_rng(17)
    scene, runs = scene_and_runs(cfg, 24, seed=5)
    ref = model_runs(cfg, scene, runs)
    rt = RT_RESULT.bind(cfg, ray_id_bits=cfg.ray_id_bits + 1)
    inputs, events = [], np.zeros(4, np.int64)
    for beats, _ in ref:
        real = beats[beats["empty"] == 0]
        n_ev = rng.integers(0, 35, (real.size, 3))
        if real.size:
            inputs += rt.pack({**{k: real[k] for k in ("ray_id", "tri_id", "hit", "t", "u",
                                                        "v", "det", "flags")},
                               "n_overflow": n_ev[:, 0], "n_underflow": n_ev[:, 1],
                               "n_invalid": n_ev[:, 2]})
        events += [int(real["hit"].sum()), *n_ev.sum(axis=0)]
        # the marker: its other fields are ignored
        inputs.append((int(rng.integers(0, 1 << 62)) << (cfg.ray_id_bits + 1)
                       | 1 << cfg.ray_id_bits) & ((1 << rt.size) - 1))
    dut = ResultFraming(cfg)
    out = []
    counted = np.zeros(4, np.int64)

    async def bench(ctx):
        for word in inputs:
            await put(ctx, dut.i, word)
        last = RESULT.bind(cfg)["last"].offset
        await wait_until(ctx, lambda: sum(b >> last & 1 for b in out) >= len(ref))

    async def watch_events(ctx):
        async for _, _, ev in ctx.tick().sample(dut.events.as_value()):
            counted[:] += list(unpack(EVENTS_LAYOUT, ev).values())

    run_sim(dut, bench, collector(dut.o, out, rng, 0.5), watch_events)
    want = sum((RESULT.bind(cfg).pack(beats) for beats, _ in ref), [])
    assert out == want
    assert counted.tolist() == events.tolist()
    assert counted[0] == sum(c["hits"] for _, c in ref) > 0


def test_event_counters_add_wrap_and_clear():
    """Each counter adds its increment every cycle, modulo 2**32; ``clear`` zeroes all."""
    cfg, rng = CFG, np.random.default_rng(19)
    dut = EventCounters(cfg)
    layout = COUNTERS.bind(cfg)
    names = COUNTERS.names
    steps = [(rng.integers(0, 1 << 32, len(names)) * (rng.random(len(names)) < 0.5),
              rng.random() < 0.1) for _ in range(60)]

    async def bench(ctx):
        model = np.zeros(len(names), np.uint64)
        for inc, clear in steps:
            ctx.set(dut.inc.as_value(), layout.pack(dict(zip(names, inc))))
            ctx.set(dut.clear, int(clear))
            await ctx.tick()
            model = np.zeros_like(model) if clear else \
                (model + inc.astype(np.uint64)) % np.uint64(1 << 32)
            got = layout.unpack(ctx.get(dut.counters.as_value()))
            assert [int(got[k]) for k in names] == model.tolist()

    run_sim(dut, bench)
