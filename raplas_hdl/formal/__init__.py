"""Formal proofs of the FP units against the arithmetic contract (``docs/formal.md``).

One idea per module: :mod:`.netlist` (emitted Verilog to an SMT-LIB model with Yosys),
:mod:`.reference` (the contract as SMT terms), :mod:`.concrete` (those terms evaluated on
arrays, to check them against the golden model), :mod:`.miter` (unrolling and the
equality to prove), :mod:`.cut` (the significand product as an uninterpreted function),
:mod:`.solve` (one bounded solver call), :mod:`.control` (stall and reset over the
transition relation), :mod:`.sby` (their port-level form with SymbiYosys),
:mod:`.synthesized` (a unit's synthesised netlist, ECP5 or xc4v, as a model to compare with
its RTL), :mod:`.streams` (the intersection unit's stream stages with SymbiYosys) and
:mod:`.prove` (orchestration and results).

Nothing outside this package and the ``prove`` command imports it: the golden model and
the host never need z3.
"""

from .prove import METHODS, UNITS, ProofResult, default_stages, describe, prove

__all__ = ["prove", "ProofResult", "describe", "default_stages", "UNITS", "METHODS"]
