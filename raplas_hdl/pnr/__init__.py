"""Place and route on a Lattice ECP5 with the YoWASP tools (``raplas-hdl pnr``).

:mod:`.tools` finds the tools, :mod:`.ecp5` runs synthesis and nextpnr (cached per netlist
and seed), :mod:`.report` reads their reports, :mod:`.steps` measures the delay of each
combinational step of a pipelined unit for :func:`raplas_hdl.rtl.pipeline.place_registers`.
Only :mod:`.steps` imports Amaranth.
"""
