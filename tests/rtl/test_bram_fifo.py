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
  LUT RAM.

(The unit with it against the golden model, with input gaps and output back-pressure:
``tests/rtl/test_dsp48_adder_units.py``.)
"""

import random

import pytest
from amaranth.back import verilog
from amaranth.sim import Simulator

from raplas_hdl.fp import FP24
from raplas_hdl.rtl.ram import BlockRAMFIFO
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
