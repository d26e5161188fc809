"""cocotb testbench: delay lines in ``SRL16E`` beside flip-flop ones, every cycle.

The top (built in ``tests/rtl/test_srl16.py``) has inputs ``i`` and ``en`` and one output per
delay line. The TB applies the vectors of ``RAPLAS_TB_IN`` (an ``.npz`` with ``i`` and
``en``: one entry per cycle) and writes the value of every output named in
``RAPLAS_TB_PORTS`` (comma-separated), seen after each rising edge, to ``RAPLAS_TB_OUT`` (an
``.npz`` with one array per port). The pytest side compares them with a list model.
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
    data, en = vec["i"].tolist(), vec["en"].tolist()
    ports = os.environ["RAPLAS_TB_PORTS"].split(",")
    Clock(dut.clk, CLOCK_NS, unit="ns").start()
    dut.rst.value = 1
    dut.i.value = 0
    dut.en.value = 0
    for _ in range(2):
        await RisingEdge(dut.clk)
    await FallingEdge(dut.clk)
    dut.rst.value = 0
    seen = {p: [] for p in ports}
    for x, e in zip(data, en):
        dut.i.value = int(x)
        dut.en.value = int(e)
        await RisingEdge(dut.clk)
        await ReadOnly()
        for p in ports:
            seen[p].append(int(getattr(dut, p).value))
        await FallingEdge(dut.clk)
    np.savez(os.environ["RAPLAS_TB_OUT"], **{p: np.array(v, dtype=np.int64)
                                             for p, v in seen.items()})
