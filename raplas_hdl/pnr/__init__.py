"""Place and route on a Lattice ECP5 with the YoWASP tools (``raplas-hdl pnr``).

:mod:`.tools` finds the tools, :mod:`.ecp5` runs synthesis and nextpnr (cached per netlist
and seed), :mod:`.report` reads their reports, :mod:`.fit` refuses a design that cannot fit
a device before nextpnr runs, :mod:`.unit` places a registered unit (or N copies of it side by
side), :mod:`.board` writes the ULX3S's ``.lpf`` from amaranth-boards' pins and
:mod:`.bitstream` takes a unit behind the serial wrapper to a ULX3S bitstream.
:mod:`.steps` measures the delay of each combinational step of a pipelined unit for
:func:`raplas_hdl.rtl.pipeline.place_registers`. Only :mod:`.steps` imports Amaranth at
import time (the others build their designs inside their functions).
"""
