# amaranth: UnusedElaboratable=no
"""The serial wrapper of the ULX3S bitstream delivers the unit's results (Amaranth simulator).

The testbench is the host: it drives ``clk_25mhz`` as the board's oscillator, shifts an FP
adder's operands in on ``sdi`` with ``sclk`` edges a few clocks apart (as a host's GPIO
would, with no timing relation to the clock), pulses ``load`` and shifts the result out on
``sdo``. The sums are compared with the golden model (:func:`raplas_hdl.fp.model.add`,
``model.sub``), bits and flags; two copies side by side (:class:`~raplas_hdl.rtl.copies.
Copies`) are wrapped the same way and each gives its own sum.
"""

import numpy as np
import pytest
from amaranth.sim import Simulator

from raplas_hdl.fp import FP24, model
from raplas_hdl.rtl.copies import Copies
from raplas_hdl.rtl.fp_add import FPAdd
from raplas_hdl.rtl.fp_mul import FPMul
from raplas_hdl.rtl.serial_wrapper import SYNC_CYCLES, SerialWrapper

#: Clocks the host holds each pin level (more than the synchronisers' SYNC_CYCLES).
HOLD = SYNC_CYCLES + 1

#: The oscillator's period (25 MHz); the host changes its pins at falling clock edges.
PERIOD = 40e-9


def run_host(wrapper, words):
    """Send each input word, load it, read the output word; returns the output words."""
    got = []
    load_cycles = (wrapper.latency or 0) + SYNC_CYCLES + 2

    async def oscillator(ctx):
        while True:
            ctx.set(wrapper.clk_25mhz, 0)
            await ctx.delay(PERIOD / 2)
            ctx.set(wrapper.clk_25mhz, 1)
            await ctx.delay(PERIOD / 2)

    async def host(ctx):
        async def hold(n=HOLD):
            await ctx.delay(n * PERIOD)

        async def shift(bit_in):
            """One sclk period: ``sdo`` read before the rising edge, ``sdi`` set before it."""
            out = ctx.get(wrapper.sdo)
            ctx.set(wrapper.sdi, bit_in)
            await hold()
            ctx.set(wrapper.sclk, 1)
            await hold()
            ctx.set(wrapper.sclk, 0)
            await hold()
            return out

        ctx.set(wrapper.rst, 1)
        await hold()
        ctx.set(wrapper.rst, 0)
        await hold(4)
        n_in, n_out = wrapper.in_bits, wrapper.out_bits
        for k, word in enumerate(words + [0]):      # the last shift-in reads the last result
            bits_out = 0
            for i in range(max(n_in, n_out if k else 0)):
                bit = ctx.get(wrapper.sdo)
                if i < n_out:
                    bits_out |= bit << i
                await shift((word >> i) & 1 if i < n_in else 0)
            if k:
                got.append(bits_out)
            if k == len(words):
                break
            ctx.set(wrapper.load, 1)
            await hold(load_cycles)
            ctx.set(wrapper.load, 0)
            await hold()

    sim = Simulator(wrapper)
    sim.add_process(oscillator)
    sim.add_testbench(host)
    sim.run_until(PERIOD * (len(words) + 1) * (3 * HOLD * (wrapper.in_bits + 8) + 60))
    assert len(got) == len(words), f"{len(got)} results read of {len(words)}"
    return got


def _operands(n, seed=0):
    rng = np.random.default_rng(seed)
    exps = rng.integers(FP24.bias - 6, FP24.bias + 6, size=(2, n), dtype=np.uint32)
    fr = rng.integers(0, FP24.man_mask + 1, size=(2, n), dtype=np.uint32)
    sign = rng.integers(0, 2, size=(2, n), dtype=np.uint32) << np.uint32(FP24.width - 1)
    vals = sign | (exps << np.uint32(FP24.man_bits)) | fr
    # one special case: an infinity minus itself (invalid), and a cancellation to zero
    vals[:, 0] = [FP24.inf, FP24.inf]
    vals[:, 1] = [FP24.one, FP24.one]
    return vals[0], vals[1]


def test_wrapper_delivers_fp_add_sums_and_differences():
    w = SerialWrapper(FPAdd(FP24))
    assert (w.in_bits, w.out_bits) == (51, 28)
    a, b = _operands(4)
    sub = np.array([1, 1, 0, 1], dtype=np.uint32)
    words = [w.pack({"a": int(x), "b": int(y), "sub": int(s), "i_valid": 1, "en": 1})
             for x, y, s in zip(a, b, sub)]
    got = [w.unpack(o) for o in run_host(w, words)]
    add_bits, add_fl = model.add(a, b, FP24, flags=True)
    sub_bits, sub_fl = model.sub(a, b, FP24, flags=True)
    want, want_fl = np.where(sub == 1, sub_bits, add_bits), np.where(sub == 1, sub_fl, add_fl)
    for i, g in enumerate(got):
        assert g["o_valid"] == 1
        assert (g["o"], g["flags"]) == (int(want[i]), int(want_fl[i])), (
            f"op {i}: a={a[i]:#x} b={b[i]:#x} sub={sub[i]}: got {g['o']:#x}/{g['flags']}, "
            f"model {int(want[i]):#x}/{int(want_fl[i])}")
    assert got[0]["flags"] != 0 and got[1]["o"] == 0          # inf - inf; one - one


def test_wrapper_of_two_copies_gives_each_copy_s_result():
    w = SerialWrapper(Copies(lambda: FPMul(FP24), 2))
    a, b = _operands(4, seed=1)
    word = w.pack({"u0__a": int(a[2]), "u0__b": int(b[2]), "u0__i_valid": 1, "u0__en": 1,
                   "u1__a": int(a[3]), "u1__b": int(b[3]), "u1__i_valid": 1, "u1__en": 1})
    (out,) = run_host(w, [word])
    g = w.unpack(out)
    want, want_fl = model.mul(a[2:], b[2:], FP24, flags=True)
    assert (g["u0__o"], g["u0__flags"], g["u0__o_valid"]) == (int(want[0]), int(want_fl[0]), 1)
    assert (g["u1__o"], g["u1__flags"], g["u1__o_valid"]) == (int(want[1]), int(want_fl[1]), 1)


def test_wrapper_refuses_bad_units_and_words():
    from raplas_hdl.rtl.board_top import BoardTop

    with pytest.raises(ValueError, match="its own clock port 'clk'"):
        SerialWrapper(BoardTop(max_triangles=16, max_spheres=4))
    with pytest.raises(ValueError, match="Component"):
        SerialWrapper(object())
    w = SerialWrapper(FPAdd(FP24))
    with pytest.raises(ValueError, match="not an input port"):
        w.pack({"o": 1})
    with pytest.raises(ValueError, match="does not fit its 1 bit"):
        w.pack({"sub": 2})
    with pytest.raises(ValueError, match="copies must be an integer from 1"):
        Copies(lambda: FPAdd(FP24), 0)
