"""cocotb testbench: the DSP48 multiplier and the inferred one side by side, every cycle.

The top (built in ``tests/rtl/test_dsp48.py``) has inputs ``a``, ``b``, ``en`` and outputs
``p_dsp`` (:class:`raplas_hdl.rtl.dsp48.DSP48Mul`) and ``p_ref``
(:class:`raplas_hdl.rtl.dsp48.PipelinedMul`). The TB applies the vectors of
``RAPLAS_TB_IN`` (an ``.npz`` with ``a``, ``b``, ``en``: one entry per cycle) and writes the
outputs seen after each rising edge to ``RAPLAS_TB_OUT`` (``p_dsp``, ``p_ref``, as
Python-int strings because they can exceed 64 bits). The pytest side compares.
"""

from __future__ import annotations

import os

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import FallingEdge, ReadOnly, RisingEdge

CLOCK_NS = 10


@cocotb.test()
async def test_vectors(dut):
    vec = np.load(os.environ["RAPLAS_TB_IN"])
    a, b, en = (vec[k].tolist() for k in ("a", "b", "en"))
    Clock(dut.clk, CLOCK_NS, unit="ns").start()
    dut.rst.value = 1
    dut.a.value = 0
    dut.b.value = 0
    dut.en.value = 0
    for _ in range(2):
        await RisingEdge(dut.clk)
    await FallingEdge(dut.clk)
    dut.rst.value = 0
    p_dsp, p_ref = [], []
    for i in range(len(a)):
        dut.a.value = int(a[i])
        dut.b.value = int(b[i])
        dut.en.value = int(en[i])
        await RisingEdge(dut.clk)
        await ReadOnly()
        p_dsp.append(str(int(dut.p_dsp.value)))
        p_ref.append(str(int(dut.p_ref.value)))
        await FallingEdge(dut.clk)
    np.savez(os.environ["RAPLAS_TB_OUT"], p_dsp=np.array(p_dsp), p_ref=np.array(p_ref))
