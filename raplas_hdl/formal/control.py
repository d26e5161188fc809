"""Stall and reset: control properties of a pipeline, over its transition relation.

The datapath proof (:mod:`.miter`) pins ``en`` = 1 and ``rst`` = 0. These three
properties cover the rest; each is stated over one step of the SMT-LIB model's transition
relation from *any* state (no unrolling, no initial state, so they hold in every state,
reachable or not):

``hold``
    ``en`` = 0 and ``rst`` = 0: after the clock edge every register holds its value.
``reset``
    ``rst`` = 1: after the edge every valid register is 0, whatever ``en``. The valid
    registers are the 1-bit registers named ``*_valid``; there must be ``latency`` of them
    (one per stage), else the property is refused as vacuous.
``outputs``
    ``o``, ``flags`` and ``o_valid`` are functions of the registers alone: two states with
    the same register contents (any inputs) have the same outputs.

With ``outputs`` and ``hold`` a stall neither changes the outputs nor the registers, so
under any pattern of ``en`` the sequence of register states at the enabled edges is the
stall-free one: the datapath proof then gives, at every cycle, ``o``/``flags`` of the
operation accepted ``latency`` enabled edges earlier and ``o_valid`` equal to its
``i_valid`` (with no reset in between); ``reset`` clears every valid bit.
"""

from __future__ import annotations

import re

import z3

from .netlist import Netlist

__all__ = ["registers", "PROPERTIES", "control_goal"]

#: The properties, in the order they are proved.
PROPERTIES = ("hold", "reset", "outputs")

_REG = re.compile(r"^; yosys-smt2-register (\S+) (\d+)$", re.M)
_OUTPUTS = ("o", "flags", "o_valid")


def registers(smt2: str) -> dict:
    """``{name: width}`` of every register (Yosys's ``yosys-smt2-register`` comments)."""
    return {name: int(w) for name, w in _REG.findall(smt2)}


def control_goal(net: Netlist, prop: str) -> z3.BoolRef:
    """The negation of ``prop`` (one of :data:`PROPERTIES`): unsatisfiable means proved.

    Raises
    ------
    ValueError
        For an unknown property, a model without registers, or (``reset``) a number of
        valid registers other than the latency.
    """
    if prop not in PROPERTIES:
        raise ValueError(f"property must be one of {', '.join(PROPERTIES)}, not {prop!r}")
    top = net.top
    regs = registers(net.smt2)
    if not regs:
        raise ValueError(f"{top}: the model has no registers")

    def n(name, state):
        return f"(|{top}_n {name}| {state})"

    lines = [f"(declare-const |{top}@s| |{top}_s|)", f"(declare-const |{top}@t| |{top}_s|)"]
    s, t = f"|{top}@s|", f"|{top}@t|"
    if prop == "hold":
        lines += [f"(assert (|{top}_t| {s} {t}))", f"(assert (not {n('en', s)}))",
                  f"(assert (not {n('rst', s)}))"]
        same = " ".join(f"(= {n(r, t)} {n(r, s)})" for r in regs)
        lines.append(f"(assert (not (and {same} true)))")
    elif prop == "reset":
        valid = [r for r, w in regs.items() if w == 1 and r.endswith("_valid")]
        if len(valid) != net.latency:
            raise ValueError(f"{top}: {len(valid)} valid registers for a latency of "
                             f"{net.latency}")
        lines += [f"(assert (|{top}_t| {s} {t}))", f"(assert {n('rst', s)})"]
        cleared = " ".join(f"(not {n(r, t)})" for r in valid)
        lines.append(f"(assert (not (and {cleared} true)))")
    else:
        lines += [f"(assert (= {n(r, s)} {n(r, t)}))" for r in regs]
        same = " ".join(f"(= {n(o, s)} {n(o, t)})" for o in _OUTPUTS)
        lines.append(f"(assert (not (and {same} true)))")
    return z3.And(*z3.parse_smt2_string(net.smt2 + "\n" + "\n".join(lines) + "\n"))
