"""Prove an FP unit's emitted Verilog equal to the contract, for all inputs.

:func:`prove` runs one proof and returns a :class:`ProofResult`. The methods:

``direct`` (``fp-add``; also ``fp-mul``, where it does not close at FP24)
    The unit unrolled over its latency (:mod:`.miter`) against the contract of
    :mod:`.reference`: the FloatingPoint-theory form for ``rtz`` and ``rne`` (and the
    multiplier's ``chop``), the bit-vector form for the ``chop`` adder.
``cut`` (``fp-mul``, the default there)
    The unit against the bit-vector form of the multiplier's contract, with the
    significand product on both sides cut to one uninterpreted function of its operands
    (:mod:`.cut`): no multiplier reasoning. A direct proof against the FloatingPoint
    theory does not close (z3 and bitwuzla: unknown after 120-150 s at FP24, one stage).
``control`` (both units)
    Not the datapath but the stall and reset behaviour (:mod:`.control`): a stall holds
    every register, ``rst`` clears every valid bit, the outputs depend on the registers
    alone. With the datapath proof this covers any pattern of ``en``.
``sby`` (both units)
    The port-level consequences of ``control`` checked by a second tool, SymbiYosys
    (:mod:`.sby`): a stall changes no output, ``rst`` clears ``o_valid``.
``chain`` (``fp-mul``)
    Two proofs, both with the product cut: the ``stages``-stage unit equals its
    1-stage form (the same datapath with the inner registers as wires), and the 1-stage
    form equals the contract. Proved only if both are.
``netlist-ecp5``, ``netlist-xc4v`` (every unit)
    Not the contract but synthesis: the unit's netlist after ``synth_ecp5`` (and the DSP
    register packing: what ``raplas-hdl pnr`` places) or ``synth_xilinx -family xc4v``
    equals its RTL, for every input (:mod:`.synthesized`; the multiplier's product cut on
    both sides). With the RTL's own proof, the netlist meets the contract.

The ``virtex4`` target (``fp-add``: shifts and add in two ``DSP48``; ``fp-mul``: the product
in one) is proved the same way, ``direct`` and ``cut`` (:data:`TARGET_METHODS`), with the
primitives replaced by Yosys's simulation models (:data:`.netlist.SCRIPTS`); the DSP48
multiplies in its own 18-bit width, so its product is cut *guarded* (:mod:`.cut`).

What every method assumes: ``en`` = 1 and ``rst`` = 0 on every cycle of the unrolling,
any register contents before it (:mod:`.miter`). The proof covers ``o``, ``flags`` and
``o_valid`` for every ``a``, ``b`` (and ``sub``, ``i_valid``).

A counterexample found with the product cut is run again on the uncut model and the
contract's bit-vector form, with the real product: only if they differ there is it
reported. Otherwise (the cut's product was no product) the uncut miter is searched
directly, real multipliers on both sides: a wrong design usually gives a counterexample
quickly even where a proof would not close; if not, the result is ``unknown``.

A counterexample is decoded (:func:`describe`): the operands in hex and as numbers, the
RTL's result, the reference's and the golden model's (:mod:`raplas_hdl.fp.model`), so that
one sees which side is wrong.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import z3

from ..fp.format import FLAG_NAMES, PRESETS, FPFormat, check_format
from .composition import prove_composition
from .control import PROPERTIES, control_goal
from .cut import count_products, cut_products, product_function
from .miter import contract_miter, equivalence_miter, unroll, violation
from .netlist import netlist
from .sby import run_sby
from .solve import SOLVER, solve
from .synthesized import synthesized

__all__ = ["ProofResult", "prove", "describe", "UNITS", "METHODS", "NETLIST_METHODS",
           "TARGETS", "TARGET_METHODS", "ONE_STAGE", "default_stages", "format_label"]

#: unit -> (operation of the reference, default method).
UNITS = {"fp-add": ("add", "direct"), "fp-mul": ("mul", "cut"), "fp-le": ("le", "direct"),
         "fp-lt": ("lt", "direct"), "fp-neg": ("neg", "direct"),
         "ray-triangle": (None, "composition")}

#: Methods each unit takes.
NETLIST_METHODS = ("netlist-ecp5", "netlist-xc4v")
METHODS = {"fp-add": ("direct", "control", "sby", *NETLIST_METHODS),
           "fp-mul": ("cut", "chain", "direct", "control", "sby", *NETLIST_METHODS),
           "fp-le": ("direct", *NETLIST_METHODS), "fp-lt": ("direct", *NETLIST_METHODS),
           "fp-neg": ("direct", *NETLIST_METHODS), "ray-triangle": ("composition",)}

#: The methods of the ``virtex4`` target, per unit (the units without one take no target).
TARGET_METHODS = {"fp-add": ("direct",), "fp-mul": ("cut",)}

#: Unit targets.
TARGETS = ("generic", "virtex4")

#: The units of one register stage (no ``stages`` option).
ONE_STAGE = ("fp-le", "fp-lt", "fp-neg")

#: Counterexamples of a netlist's product cut checked with the real product before the
#: answer is "unknown" (each one that is no counterexample is excluded and the cut asked
#: again).
CUT_RETRIES = 8


@dataclass
class ProofResult:
    """One proof and how it ended.

    Attributes
    ----------
    unit, format, rounding : str
        ``format`` is the preset name (``FP24``) or ``eXmY``.
    stages : int
    target : str
        ``generic`` or ``virtex4``.
    result : str
        ``proved``, ``counterexample`` or ``unknown``.
    solver : str
    seconds : float
        Yosys, building and solving, wall clock.
    method : str
        How it was proved (for a chain, its links).
    steps : list of dict
        Each solver call: what it proved, result, seconds.
    counterexample : dict or None
        Input and output values (see :func:`describe`).
    reason : str
        Why a result is ``unknown``.
    """

    unit: str
    format: str
    rounding: str
    stages: int
    target: str
    result: str
    solver: str
    seconds: float
    method: str
    steps: list = field(default_factory=list)
    counterexample: dict | None = None
    reason: str = ""

    def as_dict(self) -> dict:
        return asdict(self)


def format_label(fmt: FPFormat) -> str:
    """``FP24`` for a preset, ``e4m3`` otherwise (no rounding)."""
    base = fmt.with_rounding("rtz")
    return next((k for k, v in PRESETS.items() if v == base),
                f"e{fmt.exp_bits}m{fmt.man_bits}")


def default_stages(unit: str, fmt: FPFormat) -> int:
    """The default stage count of ``unit`` in ``fmt`` (the RTL's own, from its measured step
    delays: :mod:`raplas_hdl.rtl.step_delays`; never a copy of it); 1 for the comparisons
    and ``neg``."""
    # lazy: the RTL loads Amaranth; importing raplas_hdl.formal (the z3 side) needs none
    from ..rtl.fp_add import default_add_stages
    from ..rtl.fp_mul import default_mul_stages

    if unit in ONE_STAGE:
        return 1
    if unit == "ray-triangle":
        # its operations' stage counts (each the unit's default); the proof is of the
        # wiring around them
        return 0
    return (default_add_stages if unit == "fp-add" else default_mul_stages)(fmt)


def _check(unit, method):
    if unit not in UNITS:
        raise ValueError(f"unit must be one of {', '.join(UNITS)}, not {unit!r}")
    method = method or UNITS[unit][1]
    if method not in METHODS[unit]:
        raise ValueError(f"{unit} is proved by method {' or '.join(METHODS[unit])}, "
                         f"not {method!r}")
    return method


def _cut(goal, fmt, f=None, guarded=False):
    f = product_function(fmt.man_bits + 1) if f is None else f
    goal, count = cut_products(goal, f, guarded)
    if count == 0:
        raise RuntimeError("no significand product found to cut")
    return goal


def _confirm(u, op, values, timeout):
    """Run the uncut model and the contract on a counterexample's inputs.

    Returns the real values (``in.*``, ``rtl.*``, ``ref.*``) if the RTL and the contract
    really differ there, else ``None`` (the counterexample needed a product that is not
    one, so it says nothing).
    """
    pins = [v == values[f"in.{k}"] for k, v in u.inputs.items() if f"in.{k}" in values]
    differs, watch = violation(u, op, bitvector=op == "mul")
    run = solve(z3.And(*u.assumptions, *pins, differs), timeout, watch)
    return run.values if run.result == "counterexample" else None


def prove(unit: str, fmt: FPFormat, stages: int | None = None, *, method: str | None = None,
          timeout: float = 300, cwd: Path | str = ".", mutate=None,
          target: str = "generic", mode: str = "paper") -> ProofResult:
    """Prove ``unit`` (``fp-add``, ``fp-mul``, ``fp-le``, ``fp-lt`` or ``fp-neg``) against
    the contract.

    Parameters
    ----------
    unit : str
    fmt : FPFormat
    stages : int, optional
        Default: the registry's default for the unit.
    method : str, optional
        ``direct`` (``fp-add``), ``cut``, ``chain`` or ``direct`` (``fp-mul``), ``control``
        or ``sby`` (both: stall and reset instead of the datapath); default:
        ``direct`` for the adder, ``cut`` for the multiplier.
    timeout : float
        Seconds for each solver call.
    cwd : path
        Where ``build/formal/`` goes.
    mutate : callable, optional
        ``str -> str`` applied to the unit's Verilog (negative controls; for a chain, to
        the ``stages``-stage unit only).
    target : str
        ``generic`` or ``virtex4`` (``fp-add`` and ``fp-mul``, methods
        :data:`TARGET_METHODS`).
    mode : str
        ``ray-triangle`` only: the unit's mode (:data:`.composition.MODES`).

    Raises
    ------
    ValueError
        For an unknown unit, method or target, or a stage count the unit does not take.
    """
    fmt = check_format(fmt)
    method = _check(unit, method)
    if target not in TARGETS:
        raise ValueError(f"target must be one of {', '.join(TARGETS)}, not {target!r}")
    if target != "generic" and method not in TARGET_METHODS.get(unit, ()):
        raise ValueError(f"{unit} --target {target} is proved by method "
                         f"{' or '.join(TARGET_METHODS.get(unit, ())) or 'none'}, "
                         f"not {method!r}")
    if unit in ONE_STAGE and stages not in (None, 1):
        raise ValueError(f"{unit} has one register stage, not {stages}")
    stages = default_stages(unit, fmt) if stages is None else stages
    op = UNITS[unit][0]
    t0 = time.monotonic()
    if mode != "paper" and unit != "ray-triangle":
        raise ValueError(f"{unit} has no mode (only ray-triangle), not {mode!r}")
    if method == "composition":
        return _prove_composition(fmt, mode, timeout, cwd, t0)
    if method == "sby":
        result, seconds, detail = run_sby(unit, fmt, stages, timeout=timeout, cwd=cwd,
                                          mutate=mutate)
        return ProofResult(
            unit=unit, format=format_label(fmt), rounding=fmt.rounding, stages=stages,
            target="generic", result=result, solver="SymbiYosys (smtbmc z3)",
            seconds=round(time.monotonic() - t0, 3),
            method="sby: a stall keeps o/flags/o_valid, rst clears o_valid (k-induction)",
            steps=[{"proves": "sby: stall and reset at the ports", "result": result,
                    "seconds": round(seconds, 3)}],
            reason="" if result == "proved" else detail)
    if method in NETLIST_METHODS:
        return _prove_netlist(unit, fmt, stages, method, timeout, cwd, mutate, t0)
    net = netlist(unit, fmt, stages, cwd=cwd, mutate=mutate, target=target)
    u = unroll(net) if method != "control" else None
    steps = []
    if method == "control":
        links = [(f"control: {p}", control_goal(net, p), {}) for p in PROPERTIES]
        described = "control: " + ", ".join(PROPERTIES)
    elif method == "chain":
        one = unroll(netlist(unit, fmt, 1, tag="s1", cwd=cwd))
        f = product_function(fmt.man_bits + 1)
        eq_watch = {**{f"in.{k}": v for k, v in u.inputs.items()},
                    **{f"rtl.{k}": v for k, v in u.outputs.items()}}
        c_goal, c_watch = contract_miter(one, op, bitvector=True)
        links = [(f"{stages}-stage == 1-stage (product cut)",
                  _cut(equivalence_miter(u, one), fmt, f), eq_watch),
                 ("1-stage == contract (product cut)", _cut(c_goal, fmt, f), c_watch)]
        described = f"chain: {links[0][0]}; {links[1][0]}"
    else:
        goal, watch = contract_miter(u, op, bitvector=method == "cut")
        if method == "cut":
            goal = _cut(goal, fmt, guarded=target != "generic")
        described = ("cut: product as one uninterpreted function, bit-vector contract"
                     + (" (guarded: the DSP48's 18-bit operands)" if target != "generic"
                        else "")
                     if method == "cut" else
                     "direct: " + ("bit-vector chop contract" if fmt.rounding == "chop" and
                                   op == "add" else
                                   "bit-vector contract (rule 6)" if op == "neg" else
                                   "FloatingPoint contract (fpa2bv)"))
        links = [(described, goal, watch)]
    result, reason, cex = "proved", "", None
    for name, goal, watch in links:
        run = solve(goal, timeout, watch)
        steps.append({"proves": name, "result": run.result, "seconds": round(run.seconds, 3)})
        if run.result != "proved":
            result, reason = run.result, run.reason
            if run.result == "counterexample" and method in ("cut", "chain"):
                # the cut product may be no product: check, else search with the real one
                cex = _confirm(u, op, run.values, timeout)
                if cex is None:
                    differs, watch = violation(u, op, bitvector=True)
                    again = solve(z3.And(*u.assumptions, differs), timeout, watch)
                    steps.append({"proves": "contract with the real product (the cut's "
                                  "counterexample was not one)", "result": again.result,
                                  "seconds": round(again.seconds, 3)})
                    # proved here: the cut was too coarse, the uncut proof is a proof
                    result, reason, cex = again.result, again.reason, again.values or None
            elif run.result == "counterexample" and method != "control":
                cex = run.values
            break
    return ProofResult(unit=unit, format=format_label(fmt), rounding=fmt.rounding,
                       stages=stages, target=target, result=result, solver=SOLVER,
                       seconds=round(time.monotonic() - t0, 3), method=described, steps=steps,
                       counterexample=cex, reason=reason)


def composition_method(mode: str) -> str:
    """The method's name in a record (``composition``; ``composition (conservative)``), so
    that the two modes' rows of a table differ."""
    return "composition" if mode == "paper" else f"composition ({mode})"


def _prove_composition(fmt, mode, timeout, cwd, t0) -> ProofResult:
    """The ray-triangle unit's wiring in ``mode``, its operations uninterpreted functions
    (:mod:`.composition`); a counterexample names the claims that fail."""
    res = prove_composition(fmt, mode=mode, timeout=timeout, cwd=cwd)
    cex = {f"fails.{k}": 1 for k in res.get("differs", ())} or None
    return ProofResult(
        unit="ray-triangle", format=format_label(fmt), rounding=fmt.rounding, stages=0,
        target="generic", result=res["result"], solver=res["solver"],
        seconds=round(time.monotonic() - t0, 3),
        method=(f"{composition_method(mode)}: {res['ops']} operations as uninterpreted "
                "functions"
                + (f", {res['bound_ops']} bound operations cut" if res.get("bound_ops") else "")
                + f", {res['cycles']} cycles unrolled"),
        steps=res["steps"],
        counterexample=cex, reason=res.get("reason", ""))


def _prove_netlist(unit, fmt, stages, method, timeout, cwd, mutate, t0) -> ProofResult:
    """The synthesised netlist equals the RTL (:mod:`.synthesized`). ``mutate`` changes the
    Verilog that is synthesised, not the RTL it is compared with: a synthesis that did not
    do what the RTL says."""
    flow = method.split("-", 1)[1]
    rtl = unroll(netlist(unit, fmt, stages, cwd=cwd))
    src = netlist(unit, fmt, stages, cwd=cwd, mutate=mutate, tag="src") if mutate else rtl.net
    gate = unroll(synthesized(src, flow, timeout=timeout))
    miter = equivalence_miter(rtl, gate)
    goal = miter
    described = f"netlist-{flow}: the {flow} netlist == the RTL"
    if unit == "fp-mul":
        goal, count = cut_products(goal, product_function(fmt.man_bits + 1), guarded=True)
        if count == 0:
            raise RuntimeError("no significand product found to cut")
        described += " (product cut)"
    watch = {**{f"in.{k}": v for k, v in rtl.inputs.items()},
             **{f"rtl.{k}": v for k, v in rtl.outputs.items()},
             **{f"net.{k}": v for k, v in gate.outputs.items()}}
    run = solve(goal, timeout, watch)
    steps = [{"proves": described, "result": run.result, "seconds": round(run.seconds, 3)}]
    result, reason, cex = run.result, run.reason, run.values or None
    per = None              # products per side: counted once, on the first spurious pick
    for _ in range(CUT_RETRIES if unit == "fp-mul" else 0):
        if run.result != "counterexample":
            break
        # the cut product may be no product: the same inputs with the real one
        pins = z3.And(*[v == run.values[f"in.{k}"] for k, v in rtl.inputs.items()])
        again = solve(z3.And(miter, pins), timeout, watch)
        steps.append({"proves": "the same inputs with the real product", "result":
                      again.result, "seconds": round(again.seconds, 3)})
        if again.result == "counterexample":
            result, reason, cex = again.result, again.reason, again.values
            break
        result, cex = "unknown", None
        reason = "the cut's counterexample needs a product that is not one"
        if per is None:
            per = [count_products(z3.And(*side.assumptions)) for side in (rtl, gate)]
        if per[1] > per[0]:
            reason += (f" (the netlist forms each product from {per[1] // per[0]} "
                       "DSP partial products, which the cut does not join into one)")
            break
        if again.result != "proved":
            break
        # those inputs agree with the real product: ask the cut again without them (the
        # solver may pick any of the cut's counterexamples, a real one among them or not)
        goal = z3.And(goal, z3.Not(pins))
        run = solve(goal, timeout, watch)
        steps.append({"proves": f"{described}, those inputs excluded", "result": run.result,
                      "seconds": round(run.seconds, 3)})
        if run.result != "counterexample":
            result, reason = run.result, run.reason
    return ProofResult(unit=unit, format=format_label(fmt), rounding=fmt.rounding,
                       stages=stages, target="generic", result=result, solver=SOLVER,
                       seconds=round(time.monotonic() - t0, 3), method=described, steps=steps,
                       counterexample=cex, reason=reason)


def _flags(value):
    names = [n for bit, n in sorted(FLAG_NAMES.items()) if value & bit]
    return ",".join(names) or "-"


def _show(fmt, bits):
    # lazy: the golden model loads numba, only to describe a counterexample
    from ..fp import model

    return f"0x{bits:0{(fmt.width + 3) // 4}x} ({float(model.decode(bits, fmt))!r})"


def describe(res: ProofResult, fmt: FPFormat) -> list[str]:
    """A counterexample as lines: operands, RTL, reference and golden model results."""
    # lazy: the golden model loads numba, only to describe a counterexample
    from ..fp import model

    c = res.counterexample
    if not c:
        return []
    if res.unit in ONE_STAGE:
        return _describe_one_stage(res, fmt, c)
    a, b = c["in.a"], c["in.b"]
    sub = c.get("in.sub", 0)
    op = "-" if sub else ("+" if res.unit == "fp-add" else "*")
    lines = [f"  a        = {_show(fmt, a)}", f"  b        = {_show(fmt, b)}",
             f"  op       = a {op} b, i_valid={c.get('in.i_valid', 0)}"]
    if "rtl.o" in c:
        lines.append(f"  RTL      = {_show(fmt, c['rtl.o'])} flags {_flags(c['rtl.flags'])}"
                     f" o_valid={c['rtl.o_valid']}")
    if "net.o" in c:
        lines.append(f"  netlist  = {_show(fmt, c['net.o'])} flags {_flags(c['net.flags'])}"
                     f" o_valid={c['net.o_valid']}")
    if "ref.o" in c:
        lines.append(f"  contract = {_show(fmt, c['ref.o'])} flags {_flags(c['ref.flags'])}")
    fn = model.mul if res.unit == "fp-mul" else model.sub if sub else model.add
    gb, gf = fn(a, b, fmt, flags=True)
    lines.append(f"  golden   = {_show(fmt, int(gb))} flags {_flags(int(gf))}")
    return lines


def _describe_one_stage(res: ProofResult, fmt: FPFormat, c: dict) -> list[str]:
    """A counterexample of ``fp-le``, ``fp-lt`` or ``fp-neg`` as lines."""
    # lazy: the golden model loads numba, only to describe a counterexample
    from ..fp import model

    a = c["in.a"]
    lines = [f"  a        = {_show(fmt, a)}"]
    if res.unit == "fp-neg":
        lines.append(f"  op       = neg(a), i_valid={c.get('in.i_valid', 0)}")
        show = (lambda v: _show(fmt, v))
        golden = int(model.neg(a, fmt))
    else:
        b = c["in.b"]
        op = res.unit[3:]
        lines += [f"  b        = {_show(fmt, b)}",
                  f"  op       = {op}(a, b), i_valid={c.get('in.i_valid', 0)}"]
        show = str
        golden = int(bool((model.le if op == "le" else model.lt)(a, b, fmt)))
    if "rtl.o" in c:
        lines.append(f"  RTL      = {show(c['rtl.o'])} o_valid={c['rtl.o_valid']}")
    if "net.o" in c:
        lines.append(f"  netlist  = {show(c['net.o'])} o_valid={c['net.o_valid']}")
    if "ref.o" in c:
        lines.append(f"  contract = {show(c['ref.o'])}")
    lines.append(f"  golden   = {show(golden)}")
    return lines
