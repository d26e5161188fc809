"""A placed design's netlist as plain Verilog that Icarus and Verilator simulate.

``synth_ecp5`` writes ECP5 cells (``LUT4``, ``TRELLIS_FF``, ``CCU2C``, ``PFUMX``,
``MULT18X18D``...). :func:`simulation_netlist` reads such a netlist JSON (after
:mod:`.dsp_registers` packing or not) into Yosys together with Yosys's own models of the
cells, flattens it to generic logic and writes it out under a new module name, so that it
can sit in one testbench beside the RTL it came from. ``MULT18X18D``, which Yosys ships only
as a black box, stays an instance: append :func:`.dsp_registers.mult18x18d_sim_model`.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from .tools import yosys_command

__all__ = ["simulation_netlist"]


def simulation_netlist(net_json: Path, top: str, name: str, timeout: float = 600.0) -> str:
    """The netlist ``net_json`` (top module ``top``) as flat Verilog, the top renamed
    ``name``. ``RuntimeError`` with Yosys's output when it fails."""
    net_json = Path(net_json)
    work = net_json.parent
    out = f"{name}.sim.v"
    script = (f"read_json {net_json.name}; delete =A:blackbox; "
              "read_verilog -D NO_INCLUDES +/ecp5/cells_sim.v; "
              f"hierarchy -top {top}; proc; flatten; opt_clean; rename {top} {name}; "
              f"write_verilog -noattr {out}")
    proc = subprocess.run(yosys_command() + ["-q", "-p", script], cwd=work, text=True,
                          capture_output=True, timeout=timeout)
    if proc.returncode != 0:
        tail = "\n".join((proc.stdout + proc.stderr).splitlines()[-10:])
        raise RuntimeError(f"yosys could not flatten {net_json}:\n{tail}")
    return (work / out).read_text()
