"""Unroll a pipeline's SMT-LIB model and state that its outputs equal a reference.

The FP units are feed-forward pipelines: with the clock enable ``en`` = 1 and ``rst`` = 0
on every cycle, the outputs after ``latency`` clock edges are a function of the inputs of
the first cycle alone, whatever the registers held before. :func:`unroll` states exactly
that: free states ``s0 .. sL`` (every register and every input of every cycle free), the
transition relation between neighbours, ``en`` and ``rst`` pinned on cycles ``0 .. L-1``;
the inputs are read in ``s0`` and the outputs in ``sL``. No initial state is assumed, so
the result holds from any register contents.

:func:`contract_miter` is the negation of "outputs equal the contract": unsatisfiable
means proved, and a model is a counterexample. :func:`equivalence_miter` does the same for two
unrolled models fed the same inputs (the chain proofs of :mod:`.chain`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import z3

from .netlist import Netlist
from .reference import reference

__all__ = ["Unrolled", "ports", "unroll", "violation", "contract_miter", "equivalence_miter",
           "DATA_INPUTS"]

#: The inputs that carry an operation (the others are pinned: ``en``, ``rst``; or unused:
#: ``clk``).
DATA_INPUTS = ("a", "b", "sub", "i_valid")

_PORT = re.compile(r"^; yosys-smt2-(input|output) (\S+) (\d+)$", re.M)


@dataclass
class Unrolled:
    """One model unrolled over its latency.

    Attributes
    ----------
    net : Netlist
    inputs : dict
        Port name -> ``BitVec`` of the first cycle (1-bit ports as ``BitVec(1)``).
    outputs : dict
        Port name -> ``BitVec`` after ``latency`` clock edges.
    assumptions : list of z3.BoolRef
        The transition relation, ``en`` = 1, ``rst`` = 0, and the definitions of
        ``inputs`` and ``outputs``.
    """

    net: Netlist
    inputs: dict
    outputs: dict
    assumptions: list


def ports(smt2: str) -> dict:
    """``{name: (direction, width)}`` from Yosys's ``yosys-smt2-input/output`` comments."""
    return {name: (d, int(w)) for d, name, w in _PORT.findall(smt2)}


def _bv_of(top, name, width, state):
    term = f"(|{top}_n {name}| {state})"
    return term if width > 1 else f"(ite {term} #b1 #b0)"


def unroll(net: Netlist, cycles: int | None = None) -> Unrolled:
    """Unroll ``net`` over ``cycles`` clock edges (default: its latency).

    Raises
    ------
    ValueError
        If the model lacks an ``en`` input or ``cycles`` is below 1.
    """
    top = net.top
    cycles = net.latency if cycles is None else cycles
    if cycles < 1:
        raise ValueError(f"cycles must be at least 1, not {cycles}")
    found = ports(net.smt2)
    if "en" not in found:
        raise ValueError(f"{top}: the model has no en input")
    st = [f"|{top}@{i}|" for i in range(cycles + 1)]
    lines = [f"(declare-const {s} |{top}_s|)" for s in st]
    lines += [f"(assert (|{top}_t| {st[i]} {st[i + 1]}))" for i in range(cycles)]
    for i in range(cycles):
        lines.append(f"(assert (|{top}_n en| {st[i]}))")
        if "rst" in found:
            lines.append(f"(assert (not (|{top}_n rst| {st[i]})))")
    names = {}
    for name, (direction, width) in found.items():
        if direction == "input" and name not in DATA_INPUTS:
            continue
        const = f"{top}.{name}"
        state = st[0] if direction == "input" else st[-1]
        lines.append(f"(declare-const |{const}| (_ BitVec {width}))")
        lines.append(f"(assert (= |{const}| {_bv_of(top, name, width, state)}))")
        names[name] = (direction, z3.BitVec(const, width))
    assumptions = list(z3.parse_smt2_string(net.smt2 + "\n" + "\n".join(lines) + "\n"))
    return Unrolled(net=net,
                    inputs={k: v for k, (d, v) in names.items() if d == "input"},
                    outputs={k: v for k, (d, v) in names.items() if d == "output"},
                    assumptions=assumptions)


def violation(u: Unrolled, op: str, *, bitvector: bool = False) -> tuple[z3.BoolRef, dict]:
    """``(differs, watch)``: ``differs`` holds exactly when ``o``, ``flags`` (where the
    operation has them) or ``o_valid`` differ from the contract
    (:func:`.reference.reference`, ``bitvector`` as there); ``watch`` names the terms a
    counterexample reports (``in.*``, ``rtl.*``, ``ref.o``, ``ref.flags``)."""
    i, o = u.inputs, u.outputs
    bits, flags = reference(u.net.fmt, op, i["a"], i.get("b"), i.get("sub"),
                            bitvector=bitvector)
    same = [o["o"] == bits, o["o_valid"] == i["i_valid"]]
    watch = {**{f"in.{k}": v for k, v in i.items()}, **{f"rtl.{k}": v for k, v in o.items()},
             "ref.o": bits}
    if flags is not None:           # the comparisons and neg raise no events
        same.append(o["flags"] == flags)
        watch["ref.flags"] = flags
    return z3.Not(z3.And(*same)), watch


def contract_miter(u: Unrolled, op: str, *, bitvector: bool = False
                   ) -> tuple[z3.BoolRef, dict]:
    """``(goal, watch)``: ``goal`` is satisfiable exactly when some input gives an ``o``,
    ``flags`` or ``o_valid`` that differs from the contract (see :func:`violation`)."""
    differs, watch = violation(u, op, bitvector=bitvector)
    return z3.And(*u.assumptions, differs), watch


def equivalence_miter(left: Unrolled, right: Unrolled) -> z3.BoolRef:
    """Satisfiable exactly when the same data inputs give different outputs."""
    tie = [left.inputs[k] == right.inputs[k] for k in left.inputs]
    same = z3.And(*(left.outputs[k] == right.outputs[k] for k in left.outputs))
    return z3.And(*left.assumptions, *right.assumptions, *tie, z3.Not(same))
