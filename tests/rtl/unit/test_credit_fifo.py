"""CreditFIFO equals Amaranth's SyncFIFOBuffered cycle for cycle behind a writer that holds
credits (as the record fetch and the sphere feeder do), and a write beyond the credits is
where the two part (the guard the credits make unnecessary). A banked CreditFIFO equals one
bank."""

import random

import pytest
from amaranth.hdl import Module, Signal
from amaranth.lib.fifo import SyncFIFOBuffered
from amaranth.sim import Simulator

from raplas_hdl.rtl.unit.credit_fifo import CreditFIFO


def _run(depth, cycles, seed, p_write, p_read, honour_credits=True, banks=1):
    """Drive both FIFOs with the same writes and reads; return the cycles where they differ
    (``valid``, ``payload`` of the head, ``level``, ``w_ready``)."""
    m = Module()
    m.submodules.ref = ref = SyncFIFOBuffered(width=8, depth=depth)
    m.submodules.dut = dut = CreditFIFO(width=8, depth=depth, banks=banks)
    w_valid, w_data, r_ready = Signal(), Signal(8), Signal()
    m.d.comb += [ref.w_en.eq(w_valid), ref.w_data.eq(w_data), ref.r_en.eq(r_ready),
                 dut.w_stream.valid.eq(w_valid), dut.w_stream.payload.eq(w_data),
                 dut.r_stream.ready.eq(r_ready)]
    rng = random.Random(seed)
    diffs = []

    async def bench(ctx):
        credit, freed = depth, 0
        for cyc in range(cycles):
            write = rng.random() < p_write and (credit > 0 or not honour_credits)
            ctx.set(w_valid, write)
            ctx.set(w_data, rng.randrange(256))
            ctx.set(r_ready, rng.random() < p_read)
            got = [ctx.get(x) for x in (dut.r_stream.valid, dut.level, dut.w_stream.ready)]
            want = [ctx.get(x) for x in (ref.r_rdy, ref.level, ref.w_rdy)]
            if got[0]:
                got.append(ctx.get(dut.r_stream.payload))
                want.append(ctx.get(ref.r_data))
            if got != want:
                diffs.append(cyc)
            took = ctx.get(ref.r_rdy) and ctx.get(r_ready)
            credit += freed - write         # a credit comes back a cycle after the read
            freed = int(took)
            await ctx.tick()

    sim = Simulator(m)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return diffs


@pytest.mark.parametrize("depth,banks", [(3, 1), (4, 1), (5, 1), (16, 1), (3, 3), (5, 2),
                                         (16, 8)])
def test_credit_fifo_equals_sync_fifo_buffered_behind_credits(depth, banks):
    for seed, (pw, pr) in enumerate([(0.9, 0.9), (0.9, 0.3), (0.4, 0.8), (1.0, 1.0)]):
        assert _run(depth, 600, seed, pw, pr, banks=banks) == [], (depth, pw, pr)


def test_writes_beyond_the_credits_are_where_the_two_part():
    # a writer that ignores its credits overfills: SyncFIFOBuffered refuses the write,
    # CreditFIFO takes it (the record fetch's overflow flag is what would report it)
    assert _run(3, 200, 7, 1.0, 0.2, honour_credits=False) != []


def test_depth_below_three_is_refused():
    with pytest.raises(ValueError, match="at least 3 words, not 2"):
        CreditFIFO(width=8, depth=2)


@pytest.mark.parametrize("banks", [0, 9])
def test_banks_beyond_the_width_are_refused(banks):
    with pytest.raises(ValueError, match=f"of 8 bits takes 1 to 8 banks, not {banks}"):
        CreditFIFO(width=8, depth=4, banks=banks)
