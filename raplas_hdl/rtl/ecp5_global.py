"""An ECP5 global buffer (``DCCA``): a high-fanout net onto the clock network.

nextpnr promotes only clocks to the ECP5's global network by itself; any other net a
design puts through a ``DCCA`` is routed on a global too, down to each user's pin, instead
of through the general routing. The board design puts its reset there: a synchronised
reset reaches some 9,000 flip-flops' ``LSR`` pins (the default 8 x 8 certified build), a
net that otherwise takes general routing wires all over the device (whether that build's
routing converges did not turn on it: ``docs/board-top.md``).

:class:`ECP5GlobalBuffer` is the instance: ``i`` in, ``o`` out, always enabled. Like
:class:`~raplas_hdl.rtl.ecp5_pll.ECP5PLL` it is a primitive (Yosys' ``synth_ecp5`` keeps
it, nextpnr places it): the Amaranth simulator cannot run it, and the simulated board
(:mod:`raplas_hdl.rtl.serial_board`) has none.
"""

from amaranth.hdl import Instance, Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

__all__ = ["ECP5GlobalBuffer"]


class ECP5GlobalBuffer(wiring.Component):
    """``o`` is ``i`` through a ``DCCA`` (a global clock buffer, clock enable tied high).

    Members
    -------
    i : In(1)
    o : Out(1)
    """

    def __init__(self):
        super().__init__({"i": In(1), "o": Out(1)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.dcca = Instance("DCCA", i_CLKI=self.i, i_CE=1, o_CLKO=self.o)
        return m
