# amaranth: UnusedElaboratable=no
"""The ray-triangle unit's output FIFO in block RAM (issue 15, item 4).

:class:`raplas_hdl.rtl.ram.BlockRAMFIFO` is a first-word-fall-through FIFO on a memory with a
synchronous read port, marked for block RAM; the ray-triangle unit uses it with the DSP48
adders (``bram_fifo``). Checked here:

* every cycle in Amaranth's simulator, against a list model: the head word and ``r_rdy``
  (a word written into an empty FIFO shows two edges after its write), ``level`` and
  ``w_rdy``, with random writes and reads, full and empty stretches;
* which units use it, the errors for a bad option, the generic target's Verilog without it;
* Yosys maps it (the FIFO shape in the whole unit: 133 bits, 47 words) to ``RAMB16`` and no
  LUT RAM;
* the forms whose write is not gated by the level (the unit's writer holds credits:
  :class:`~raplas_hdl.rtl.ram.CreditSyncFIFO`, ``BlockRAMFIFO(credits=True)``) equal the gated
  ones (Amaranth's ``SyncFIFO``, ``BlockRAMFIFO``) on every port in every cycle, behind a
  writer that never writes into a full FIFO; and a write into a full one is not refused.

(The unit with it against the golden model, with input gaps and output back-pressure:
``tests/rtl/test_dsp48_adder_units.py``.)
"""

import random

import pytest
from amaranth.back import verilog
from amaranth.hdl import Module
from amaranth.lib.fifo import SyncFIFO
from amaranth.sim import Simulator

from raplas_hdl.fp import FP24
from raplas_hdl.rtl.ram import BlockRAMFIFO, CreditSyncFIFO
from raplas_hdl.rtl.ray_triangle import RayTriangleUnit

V4 = "virtex4"


@pytest.mark.parametrize("depth, w_density, r_density", [
    (2, 0.7, 0.5), (5, 0.9, 0.3), (5, 0.4, 0.9), (46, 1.0, 1.0), (46, 0.8, 0.6)])
def test_fifo_against_a_list_model(depth, w_density, r_density):
    dut = BlockRAMFIFO(width=12, depth=depth)
    rng = random.Random(depth * 1000 + int(w_density * 10))
    cycles = 600
    checked = []

    async def testbench(ctx):
        queue = []          # words written, oldest first
        visible = 0         # words of `queue` that have reached the head (model of r_rdy)
        arrived = []        # edges at which written words may show at the head
        n = 0
        for cyc in range(cycles):
            # the model before this edge
            assert ctx.get(dut.level) == len(queue)
            assert ctx.get(dut.w_rdy) == (len(queue) - (1 if visible else 0) < depth - 1)
            assert ctx.get(dut.r_rdy) == bool(visible)
            if visible:
                assert ctx.get(dut.r_data) == queue[0]
            w = ctx.get(dut.w_rdy) and rng.random() < w_density
            r = rng.random() < r_density
            ctx.set(dut.w_en, w)
            ctx.set(dut.w_data, n & 0xFFF)
            ctx.set(dut.r_en, r)
            await ctx.tick()
            popped = bool(r and visible)
            if popped:
                queue.pop(0)
                arrived.pop(0)
                checked.append(1)
                visible -= 1
            if w:
                queue.append(n & 0xFFF)
                arrived.append(cyc + 2)     # two edges after the write edge
                n += 1
            # the head register loads one word when empty or popped, if one has arrived
            if not visible and queue and arrived[0] <= cyc + 1:
                visible = 1
        ctx.set(dut.w_en, 0)

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    sim.run()
    assert len(checked) > cycles // 10


def test_fifo_full_rate():
    """Written every clock and read every clock: one word in, one out, from the third edge."""
    dut = BlockRAMFIFO(width=8, depth=4)
    out = []

    async def testbench(ctx):
        for cyc in range(40):
            ctx.set(dut.w_en, 1)
            ctx.set(dut.w_data, cyc)
            ctx.set(dut.r_en, 1)
            assert ctx.get(dut.w_rdy)
            if ctx.get(dut.r_rdy):
                out.append(ctx.get(dut.r_data))
            await ctx.tick()

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    sim.run()
    assert out == list(range(38))


@pytest.mark.parametrize("bad", [(0, 4), (8, 1)])
def test_fifo_bad_shape(bad):
    with pytest.raises(ValueError, match="block-RAM FIFO"):
        BlockRAMFIFO(width=bad[0], depth=bad[1])


def test_which_ray_triangle_units_use_it():
    assert not RayTriangleUnit(FP24).bram_fifo
    assert not RayTriangleUnit(FP24, multiplier=V4).bram_fifo
    on, off = RayTriangleUnit(FP24, adder=V4), RayTriangleUnit(FP24, adder=V4, bram_fifo=False)
    assert on.bram_fifo and not off.bram_fifo
    assert (on.latency, on.fifo_depth) == (off.latency + 1, off.fifo_depth + 1)
    gen = RayTriangleUnit(FP24, bram_fifo=True)
    assert gen.latency == RayTriangleUnit(FP24).latency + 1
    text = verilog.convert(on, name="rt", emit_src=False)
    assert text.count('ram_style = "block"') == 1
    assert 'ram_style' not in verilog.convert(RayTriangleUnit(FP24), name="rt", emit_src=False)


@pytest.mark.parametrize("bad", [1, 0, "yes"])
def test_bad_bram_fifo_names_the_option(bad):
    with pytest.raises(ValueError, match="bram_fifo"):
        RayTriangleUnit(FP24, adder=V4, bram_fifo=bad)


def test_yosys_maps_it_to_block_ram(tmp_path):
    from raplas_hdl.synth.yosys import synthesize

    f = BlockRAMFIFO(width=133, depth=47)
    ports = [f.w_data, f.w_en, f.w_rdy, f.r_data, f.r_en, f.r_rdy, f.level]
    text = verilog.convert(f, name="bf", ports=ports, emit_src=False)
    r = synthesize(text, "bf", cache_dir=tmp_path)
    assert r.bram == 4 and r.lutram == 0           # 133 bits in four 512 x 36 RAMB16
    assert "RAMB16" in r.cells_by_type


_PORTS = ("w_rdy", "r_rdy", "r_data", "level")


def _pair(kind, depth):
    """The credit form and its gated reference, ``kind`` "sync" or "bram"."""
    if kind == "sync":
        return CreditSyncFIFO(width=10, depth=depth), SyncFIFO(width=10, depth=depth)
    return (BlockRAMFIFO(width=10, depth=depth, credits=True),
            BlockRAMFIFO(width=10, depth=depth))


@pytest.mark.parametrize("kind", ["sync", "bram"])
@pytest.mark.parametrize("depth, w_density, r_density", [
    (2, 0.8, 0.4), (5, 0.9, 0.3), (7, 0.5, 0.8), (47, 1.0, 0.9)])
def test_credit_fifos_equal_the_gated_ones_behind_a_credit_writer(kind, depth, w_density,
                                                                  r_density):
    dut, ref = _pair(kind, depth)
    m = Module()
    m.submodules.dut, m.submodules.ref = dut, ref
    rng = random.Random(depth * 7919 + int(w_density * 100) + len(kind))
    seen = {"full": 0, "read": 0}

    async def testbench(ctx):
        for cyc in range(800):
            for name in _PORTS:
                got, want = ctx.get(getattr(dut, name)), ctx.get(getattr(ref, name))
                if name == "r_data" and not ctx.get(ref.r_rdy):
                    continue                    # no head word: the data is not a result
                assert got == want, f"cycle {cyc}: {name} {got} != {want}"
            # the writer holds a credit for a free word: it writes only while one is free
            w = ctx.get(ref.w_rdy) and rng.random() < w_density
            r = rng.random() < r_density
            seen["full"] += not ctx.get(ref.w_rdy)
            seen["read"] += r and ctx.get(ref.r_rdy)
            data = rng.getrandbits(10)
            for f in (dut, ref):
                ctx.set(f.w_en, w)
                ctx.set(f.w_data, data)
                ctx.set(f.r_en, r)
            await ctx.tick()

    sim = Simulator(m)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    sim.run()
    assert seen["read"] > 100 and (seen["full"] > 0 or r_density > w_density)


@pytest.mark.parametrize("kind", ["sync", "bram"])
def test_a_credit_fifo_does_not_refuse_a_write_when_full(kind):
    """The write enable is ``w_en`` alone: a write into a full FIFO is taken (and overwrites
    a word), where the gated FIFO refuses it. The unit's credits keep it from happening."""
    dut, ref = _pair(kind, 3)
    m = Module()
    m.submodules.dut, m.submodules.ref = dut, ref
    levels = []

    async def testbench(ctx):
        for n in range(6):
            for f in (dut, ref):
                ctx.set(f.w_en, 1)
                ctx.set(f.w_data, n)
            await ctx.tick()
            levels.append((ctx.get(dut.level), ctx.get(ref.level)))

    sim = Simulator(m)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    sim.run()
    assert levels[-1][1] == 3 and levels[-1][0] != 3


def test_credit_sync_fifo_bad_shape():
    with pytest.raises(ValueError, match="credit FIFO"):
        CreditSyncFIFO(width=4, depth=0)
