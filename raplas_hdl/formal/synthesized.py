"""A unit's synthesised netlist as an SMT-LIB model, to prove it equal to its RTL.

A proof of the emitted Verilog (:mod:`.netlist`) says nothing about what synthesis made of
it. Here the same Verilog goes through a real synthesis flow, and the mapped netlist, its
cells replaced by Yosys's simulation models of them, becomes a second transition system
that :func:`.miter.equivalence_miter` compares with the RTL's:

``ecp5``
    :func:`raplas_hdl.pnr.ecp5.synthesize_ecp5`: ``synth_ecp5``, then the register packing
    of :mod:`raplas_hdl.pnr.dsp_registers`: exactly the netlist ``raplas-hdl pnr`` places.
    Cells from ``+/ecp5/cells_sim.v`` (``LUT4``, ``CCU2C``, ``TRELLIS_FF``, ``PFUMX``...) and,
    since Yosys ships ``MULT18X18D`` as a black box only,
    :func:`~raplas_hdl.pnr.dsp_registers.mult18x18d_sim_model` (which refuses any register
    setting it does not cover).
``xc4v``
    :data:`raplas_hdl.synth.yosys.SCRIPT`: ``synth_xilinx -family xc4v -flatten``, the
    netlist behind ``raplas-hdl synth``'s Virtex-4 figures. Cells from
    ``+/xilinx/cells_sim.v`` (``LUT*``, ``MUXCY``, ``XORCY``, ``FD*``, ``DSP48``).

Then, for both::

    proc; flatten; opt -full; rename TOP TOP_FLOW; dffunmap; opt_clean; write_smt2 -stbv -wires

``opt -full`` folds the cells' parameters and constant mode inputs into their logic (the
``DSP48`` model's operation multiplexers read ``P`` in modes a multiplier never selects: a
combinational loop until they are folded away) and resolves the models' ``x`` defaults, as
Yosys's own synthesis would. The multiplier's significand product is then cut on both
sides with :func:`.cut.cut_products` (``guarded``: a DSP block multiplies its input
registers in its own width, zero above the significand in every reachable state).
"""

from __future__ import annotations

import hashlib
import subprocess
from pathlib import Path

from ..pnr.dsp_registers import mult18x18d_sim_model
from ..synth.yosys import SCRIPT, yosys_command
from .netlist import Netlist, yosys_version

__all__ = ["FLOWS", "synthesized", "FLATTEN"]

#: Synthesis flows a unit's netlist is proved for.
FLOWS = ("ecp5", "xc4v")

#: Yosys's cell models per flow (read after the netlist's black boxes are deleted).
_MODELS = {"ecp5": "read_verilog -D NO_INCLUDES +/ecp5/cells_sim.v; read_verilog mult18.v; ",
           "xc4v": "read_verilog -lib +/xilinx/cells_xtra.v; read_verilog +/xilinx/cells_sim.v; "}

#: The script from a netlist JSON to its SMT-LIB model; ``{models}``, ``{top}``, ``{name}``.
FLATTEN = ("read_json {json}; delete =A:blackbox; {models}hierarchy -top {top}; proc; "
           "flatten; opt -full; rename {top} {name}; dffunmap; opt_clean; "
           "write_smt2 -stbv -wires net.part.smt2")


def _run(script: str, work: Path, timeout: float, what: str) -> None:
    proc = subprocess.run(yosys_command() + ["-q", "-l", "flatten.log", "-p", script],
                          cwd=work, capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        log = (work / "flatten.log").read_text() if (work / "flatten.log").exists() else ""
        tail = "\n".join((log or proc.stderr or proc.stdout).splitlines()[-10:])
        raise RuntimeError(f"yosys failed on {what} ({work}): {tail}")


def _synth_json(net: Netlist, flow: str, work: Path, timeout: float) -> str:
    """Synthesise ``net``'s Verilog; the netlist JSON's name, relative to ``work``."""
    if flow == "ecp5":
        # lazy: pnr.ecp5 loads importlib.metadata (~10-20 ms) for the ECP5 flow only
        from ..pnr.ecp5 import synthesize_ecp5

        syn = synthesize_ecp5(net.verilog, net.top, base=work, timeout=timeout)
        (syn.work / "mult18.v").write_text(mult18x18d_sim_model())
        return str(syn.work.relative_to(work) / "net.json")
    (work / "top.v").write_text(net.verilog)
    if not (work / "net.json").exists():
        _run(SCRIPT.format(top=net.top), work, timeout, f"synth_xilinx of {net.top}")
    return "net.json"


def synthesized(net: Netlist, flow: str, *, timeout: float = 600) -> Netlist:
    """``net``'s Verilog synthesised by ``flow`` (one of :data:`FLOWS`), as a model named
    ``<top>_<flow>`` (cached beside ``net``'s work files).

    Raises
    ------
    ValueError
        For an unknown flow.
    RuntimeError
        If Yosys fails (with the tail of its log).
    """
    if flow not in FLOWS:
        raise ValueError(f"flow must be one of {', '.join(FLOWS)}, not {flow!r}")
    name = f"{net.top}_{flow}"
    digest = hashlib.sha256("\n".join([net.verilog, FLATTEN, _MODELS[flow],
                                       yosys_version()]).encode()).hexdigest()[:12]
    work = net.workdir / f"{flow}-{digest}"
    work.mkdir(parents=True, exist_ok=True)
    smt = work / "net.smt2"
    if not smt.exists():
        rel = Path(_synth_json(net, flow, work, timeout))
        where = work / rel.parent
        _run(FLATTEN.format(json=rel.name, models=_MODELS[flow], top=net.top, name=name),
             where, timeout, f"the {flow} netlist of {net.top}")
        (where / "net.part.smt2").replace(smt)
    return Netlist(unit=net.unit, top=name, fmt=net.fmt, stages=net.stages,
                   latency=net.latency, verilog=net.verilog, smt2=smt.read_text(),
                   workdir=work)
