"""The ray-triangle unit's datapath proved by composition (issue 23, item 3).

The FP units are proved one by one (:mod:`.prove`): for every input, each one's ``o`` and
``flags`` after its latency are the contract's, whatever its registers held. What is left
for the ray-triangle unit is its wiring: that its 33 operations (34 in conservative mode)
take the operands the contract's formula gives them, at the cycle they are used, that the
event counts sum their flags, and that the decision combines the results as the contract
says. That is proved here with each operation an *uninterpreted function*:

- the unit is built with a stand-in in place of every ``FPAdd`` and ``FPMul``
  (:meth:`RayTriangleUnit._new_op`): the same ports and latency, its operands carried
  through ``latency`` registers (``arg_a``, ``arg_b``, ``arg_sub``) and its ``o`` and
  ``flags`` free in every cycle (``$anyseq``, through the kept wires ``res`` and
  ``res_flags``);
- Yosys writes the unit as a transition system (:mod:`.netlist`'s script) and it is
  unrolled from a free state: ``rst`` = 0 in every cycle, a pair accepted in the first
  (``i.valid`` and ``i.ready``), ``o.ready`` free;
- in the cycle an operation's result of that pair comes out, its stand-in's ``o`` is
  bound to ``F(arg_a, arg_b)`` and its ``flags`` to ``G(arg_a, arg_b)``, with one
  function pair per kind (``mul``, ``add``, ``sub``, an adder's chosen by the ``arg_sub``
  it took; ``z3.Function``, otherwise unconstrained): every instance of a kind computes
  the same function, as the real units (one module per kind, format and stage count) do;
- the reference is the contract's formula (:mod:`raplas_hdl.model.ray_triangle`'s table:
  every dot product ``(x*x' + y*y') + z*z'``, ``u' = neg(Q.E2)``) over the same functions,
  its comparisons and ``neg`` the contract's (:func:`.reference.reference`), and the
  claim is that the output register (cycle ``decision_cycle + 2``) holds the pair's IDs,
  ``t``, ``u``, ``v``, ``det``, ``hit``, ``flags`` and the three event counts as the
  reference gives them, with its valid bit set.

Unsatisfiable means proved for *every* interpretation of the functions, so in particular
for the proved units: the unit equals the contract's formula on the contract's operations.
The output FIFO behind the register is a stream stage (proved apart, :mod:`.streams`).

Modes: ``paper`` (the default) and ``conservative``, which adds the 34th operation
``w = det - s`` and the widened decision of :mod:`raplas_hdl.model.conservative`: its five
margins are exponent arithmetic on the inputs' fields (:func:`margins_z3`, the model's
:func:`~raplas_hdl.model.conservative.margin_k` as bit vectors, checked against it on
random fields by the tests), and a NaN among ``det, t', u', v', w`` or an overflow flag of
any operation gives a hit. ``certified`` adds ``w`` too and states the outcome (0 miss, 1
hit, 2 uncertain), ``hit`` and ``tight`` from the error bounds the model forms beside the
operations (:mod:`.certified_reference`: the model's bound arithmetic in z3's FloatingPoint
theory, rounding up), in three steps: each of the gateware's bound operators
(:mod:`raplas_hdl.rtl.certified_bound`) rounds up as the model does
(:func:`prove_bound_operator`); with every bound operation a stand-in too, cut one to one
against the model's in the order both apply them, each takes the model's operands (the
claim ``bound_args``: the leaves ``U``, the rounding terms and the input bounds are the
unit's own logic); and the decision from those bounds is the model's. Its claims go to the
solver in three calls (:data:`CERTIFIED_GROUPS`).
"""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import z3
from amaranth.asserts import AnySeq
from amaranth.back import rtlil
from amaranth.hdl import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..fp.format import FLAG_OVERFLOW, FPFormat, check_format
from ..model.conservative import MARGIN_NAMES, margin_constants
from ..model.certified import certified_constants, check_certified_format
from ..rtl.certified_bound import BoundOps
from ..rtl.ray_triangle import RayTriangleUnit, _Timed, input_layout, output_layout
from ..synth.yosys import yosys_command
from .certified_reference import BoundReference, CutBounds, bound_operator_goal
from .miter import ports
from .netlist import WORK_DIR
from .reference import reference
from .solve import SOLVER, solve

__all__ = ["StandIn", "ComposedUnit", "composition_goal", "prove_composition", "TOP",
           "MODES", "margins_z3", "contract", "BoundOperator", "prove_bound_operator"]

#: Keeps a stand-in's operands and results under their names through Yosys's clean-up.
_KEEP = {"keep": 1}

#: ``ackermannize_bv``'s lemma limit: each function is applied about 70 times (the unit's
#: operations and the formula's), some 2,400 lemmas, above z3's default of 1,000.
ACKERMANN_LIMIT = 100_000

#: Module name of the emitted unit.
TOP = "rt_composed"

#: The modes whose datapath the composition states.
MODES = ("paper", "conservative", "certified")


class StandIn(wiring.Component):
    """An operation's ports and latency, its result free: the operands are delayed
    ``latency`` cycles (``arg_a``, ``arg_b``, ``arg_sub``) beside an ``o`` and ``flags``
    that are free in every cycle."""

    def __init__(self, fmt: FPFormat, latency: int, kind: str):
        self._fmt, self.latency, self.kind = fmt, latency, kind
        w = fmt.width
        members = {"a": In(w), "b": In(w), "i_valid": In(1), "en": In(1), "o": Out(w),
                   "flags": Out(3), "o_valid": Out(1)}
        if kind == "add":
            members["sub"] = In(1)
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        w = self._fmt.width
        args = {"a": self.a, "b": self.b}
        if self.kind == "add":
            args["sub"] = self.sub
        for name, value in args.items():
            for k in range(self.latency):
                r = Signal(len(value), name=f"arg_{name}" if k == self.latency - 1
                           else f"arg_{name}_{k}", attrs=_KEEP)
                m.d.sync += r.eq(value)
                value = r
        res, fl = Signal(w, name="res", attrs=_KEEP), Signal(3, name="res_flags", attrs=_KEEP)
        m.d.comb += [res.eq(AnySeq(w)), fl.eq(AnySeq(3)), self.o.eq(res), self.flags.eq(fl),
                     self.o_valid.eq(1)]
        return m


class ComposedUnit(RayTriangleUnit):
    """A :class:`RayTriangleUnit` with a :class:`StandIn` in place of each operation; the
    operations of the last build are listed in :attr:`ops` as ``(name, kind, sub, out
    cycle)`` (``name`` the submodule's: ``mul4``, ``add1``).

    In certified mode each two-stage bound operation (``_bop``: a bound sum or product) is
    a stand-in too: its operands carried two cycles (``bop<n>_a1``, ``bop<n>_b1``) beside a
    free result (``bop<n>_res``), listed in :attr:`bound_ops` as ``(kind, a, b, result,
    out cycle)``. The leaves of the bounds (``U``, the rounding terms, the input bounds)
    and the decision stay the unit's own logic."""

    def _new_op(self, kind):
        real = super()._new_op(kind)
        real._MustUse__silence = True          # built only for its latency
        return StandIn(self._fmt, real.latency, kind)

    def _datapath(self, m, p):
        self.ops = []
        self.bound_ops = []
        return super()._datapath(m, p)

    def _bop(self, m, kind, a, b):
        t = max(a.time, b.time)
        n = len(self.bound_ops)
        w = self._bo.width
        names = []
        for x, tag in ((a, "a"), (b, "b")):
            v = self._at(m, x, t)
            for step in range(2):
                r = Signal(w, name=f"bop{n}_{tag}{step}", attrs=_KEEP)
                m.d.sync += r.eq(v)
                v = r
            names.append(v.name)
        res = Signal(w, name=f"bop{n}_res", attrs=_KEEP)
        m.d.comb += res.eq(AnySeq(w))
        self.bound_ops.append((kind, *names, res.name, t + 2))
        return _Timed(res, t + 2)

    def _op(self, m, kind, a, b, sub=False):
        out = super()._op(m, kind, a, b, sub)
        self.ops.append((f"{kind}{self._n_ops}", kind, bool(sub), out.time))
        return out


def _emit(fmt: FPFormat, mode: str, unit_class) -> tuple[str, ComposedUnit]:
    """The composed unit as RTLIL (its stand-ins' free values are ``$anyseq`` cells, which
    Verilog has no construct for)."""
    unit = unit_class(fmt, mode=mode)
    text = rtlil.convert(unit, name=TOP, emit_src=False)
    return text, unit


def _smt2(text: str, workdir) -> str:
    """Yosys's transition system of the emitted ``text`` (:mod:`.netlist`'s script, with the
    stand-ins' results cut into inputs)."""
    return _yosys_smt2(text, workdir, f"read_rtlil top.il; prep -top {TOP}; flatten; "
                       "expose -input w:*.res w:*.res_flags w:bop*_res; memory_map; "
                       "dffunmap; opt_clean; write_smt2 -stbv -wires top.smt2")


def _yosys_smt2(text: str, workdir, script: str) -> str:
    """``script`` run by Yosys on the RTLIL ``text`` (as ``top.il`` in ``workdir``): the
    SMT-LIB model it writes to ``top.smt2``."""
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "top.il").write_text(text)
    res = subprocess.run([*yosys_command(), "-q", "-p", script], cwd=workdir,
                         capture_output=True, text=True, check=False)
    if res.returncode != 0:
        raise RuntimeError(f"yosys failed: {(res.stderr or res.stdout).strip()[-400:]}")
    return (workdir / "top.smt2").read_text()


def margins_z3(fmt: FPFormat, consts, fields: dict) -> dict:
    """The conservative mode's five margins (``W``-bit patterns, positive) as z3 terms:
    :func:`~raplas_hdl.model.conservative.margin_k` written as bit vectors. ``fields`` maps
    each input vector (``o, d, v0, e1, e2, n``) to the largest biased exponent field of its
    components (an ``E``-bit term); ``consts`` is the
    :class:`~raplas_hdl.model.conservative.MarginConstants` of the unit."""
    E, M = fmt.exp_bits, fmt.man_bits
    iw = E + 8                                   # room for sums of three signed exponents

    def num(v):
        return z3.BitVecVal(v, iw)

    def smax(a, b):
        return z3.If(a > b, a, b)                # signed: z3's > on bit vectors is signed

    ell = {k: z3.ZeroExt(iw - E, f) - num(fmt.bias - 1) for k, f in fields.items()}
    lvo = smax(ell["v0"], ell["o"])
    y = {"det": ell["n"] + ell["d"], "t": ell["n"] + lvo,
         "u": ell["d"] + lvo + ell["e2"], "v": ell["d"] + lvo + ell["e1"],
         "w": ell["d"] + smax(ell["n"], smax(ell["e1"], ell["e2"]) + lvo)}
    emf = fmt.exp_max_field
    out = {}
    for name in MARGIN_NAMES:
        field = num(consts.k_field[name]) + smax(y[name], num(consts.floor[name]))
        kept = z3.Extract(E - 1, 0, smax(field, num(1)))
        finite = z3.Concat(z3.BitVecVal(0, 1), kept, z3.BitVecVal(consts.k_frac[name], M))
        out[name] = z3.If(field >= num(emf), z3.BitVecVal(fmt.inf, fmt.width), finite)
    return out


def contract(fmt, pay, fns, mode="paper", consts=None, bounds=None):
    """The contract's formula in ``mode`` over the functions ``fns`` (kind -> (o, flags)):
    ``(values, flag terms of every operation, hit)``. The operations are listed in the
    order the unit builds them (a dot product's three products, then its two sums; the six
    products of ``Q``, then its three differences; ``w`` last): the order of a list of
    independent operations, not of the formula, which the event counts' proof matches them
    by. ``consts``: the conservative mode's margin constants. In certified mode ``hit`` is
    the pair ``(outcome, tight)``, with the bounds of ``bounds`` (a
    :class:`.certified_reference.BoundReference`, by default the model's own arithmetic;
    a :class:`~.certified_reference.CutBounds` in the proof). ``pay``
    maps each input vector to its three patterns; ``fns`` may be concrete (the tests fold
    the terms with the golden model's operations)."""
    flags = []

    def op(kind, a, b):
        f, g = fns[kind]
        flags.append(g(a, b))
        return f(a, b)

    parts = {}                                   # a dot product's p0, p1, p2, p0 + p1

    def dot(a, b, name):
        p = [op("mul", x, y) for x, y in zip(a, b)]
        s01 = op("add", p[0], p[1])
        parts[name] = (*p, s01)
        return op("add", s01, p[2])

    o, d, v0, e1, e2, n = (pay[k] for k in ("o", "d", "v0", "e1", "e2", "n"))
    t = [op("sub", v0[k], o[k]) for k in range(3)]
    det = dot(n, d, "det")
    tp = dot(n, t, "t")
    prods = [(op("mul", d[a], t[b]), op("mul", d[b], t[a])) for a, b in ((1, 2), (2, 0), (0, 1))]
    q = [op("sub", pc, rc) for pc, rc in prods]
    qe2 = dot(q, e2, "u")
    up = reference(fmt, "neg", qe2, None)[0]
    vp = dot(q, e1, "v")
    s = op("add", up, vp)
    zero = z3.BitVecVal(0, fmt.width)

    def le(a, b):
        return reference(fmt, "le", a, b)[0] == 1

    def lt(a, b):
        return reference(fmt, "lt", a, b)[0] == 1

    values = {"det": det, "t": tp, "u": up, "v": vp}
    if mode == "paper":
        hit = z3.Or(z3.And(lt(zero, det), le(zero, up), le(zero, vp), le(s, det), le(zero, tp)),
                    z3.And(lt(det, zero), le(up, zero), le(vp, zero), le(det, s), le(tp, zero)))
        return values, flags, hit
    w = op("sub", det, s)
    if mode == "certified":
        br = BoundReference(fmt) if bounds is None else bounds
        g = _certified_bounds(br, pay, t, prods, q, parts,
                              {"det": det, "t": tp, "u": qe2, "v": vp, "s": s, "w": w})
        bit = FLAG_OVERFLOW.bit_length() - 1
        overflow = z3.Or(*(z3.Extract(bit, bit, fl) == 1 for fl in flags))
        outcome, tight = br.outcome({"det": det, "t": tp, "u": up, "v": vp, "w": w}, g,
                                    overflow)
        return values, flags, (outcome, tight)
    E, M = fmt.exp_bits, fmt.man_bits

    def field(x):
        return z3.Extract(M + E - 1, M, x)

    def nan(x):
        return z3.And(field(x) == fmt.exp_max_field, z3.Extract(M - 1, 0, x) != 0)

    def maxfield(vec):
        a = z3.If(z3.UGT(field(vec[0]), field(vec[1])), field(vec[0]), field(vec[1]))
        return z3.If(z3.UGT(a, field(vec[2])), a, field(vec[2]))

    mg = margins_z3(fmt, consts, {k: maxfield(pay[k]) for k in ("o", "d", "v0", "e1", "e2",
                                                                 "n")})
    sign = z3.BitVecVal(fmt.sign_bit, fmt.width)
    bit = FLAG_OVERFLOW.bit_length() - 1
    overflow = z3.Or(*(z3.Extract(bit, bit, g) == 1 for g in flags))
    bad = z3.Or(nan(det), nan(tp), nan(up), nan(vp), nan(w), overflow)
    pos = z3.And(le(mg["u"] ^ sign, up), le(mg["v"] ^ sign, vp), le(mg["w"] ^ sign, w),
                 le(mg["t"] ^ sign, tp))
    neg = z3.And(le(up, mg["u"]), le(vp, mg["v"]), le(w, mg["w"]), le(tp, mg["t"]))
    hit = z3.Or(bad, z3.And(le(mg["det"] ^ sign, det), pos), z3.And(le(det, mg["det"]), neg))
    return values, flags, hit


def _certified_bounds(br: BoundReference, pay, t, prods, q, parts, res) -> dict:
    """The bounds of ``det, t', u', v', w`` as the model forms them (its ``pair_bounds``)
    over the formula's operations: ``t``, ``prods``, ``q`` and the dot products' ``parts``
    are their results (patterns), ``res`` the rest (``u`` is ``Q.E2`` before its
    negation, whose bound it shares)."""
    o, d, v0, e1, e2, n = (pay[k] for k in ("o", "d", "v0", "e1", "e2", "n"))
    bv = [br.input_bound(x, False) for x in v0]
    b1, b2, bn = ([br.input_bound(x, True) for x in vec] for vec in (e1, e2, n))

    def dot_b(x, bx, y, by, name):
        p0, p1, p2, s01 = parts[name]
        qb = [br.mul_b(x[c], bx[c], y[c], None if by is None else by[c], pc)
              for c, pc in enumerate((p0, p1, p2))]
        return br.add_b(s01, br.add_b(p0, qb[0], p1, qb[1], s01), p2, qb[2], res[name])

    gt_ = [br.add_b(v0[c], bv[c], o[c], None, t[c]) for c in range(3)]
    g = {"det": dot_b(n, bn, d, None, "det"), "t": dot_b(n, bn, t, gt_, "t")}
    gq = []
    for (a, b), (pc, rc), qc in zip(((1, 2), (2, 0), (0, 1)), prods, q):
        gp = br.mul_b(t[b], gt_[b], d[a], None, pc)           # (U(d_a)) B_t_b + rnd
        gr = br.mul_b(t[a], gt_[a], d[b], None, rc)
        gq.append(br.add_b(pc, gp, rc, gr, qc))
    g["u"] = dot_b(e2, b2, q, gq, "u")
    g["v"] = dot_b(e1, b1, q, gq, "v")
    gs = br.add_b(res["u"], g["u"], res["v"], g["v"], res["s"])
    g["w"] = br.add_b(res["det"], g["det"], res["s"], gs, res["w"])
    return g


def composition_goal(fmt: FPFormat, *, mode: str = "paper", cwd=None,
                     unit_class=ComposedUnit):
    """``(goal, claims, unit, cycles)``: ``goal`` is satisfiable exactly when some pair, some
    register contents and some interpretation of the operations give an output register
    that differs from the contract's formula; ``claims`` names its parts. ``unit_class``:
    a :class:`ComposedUnit` or a subclass (the tests' deliberately wrong units)."""
    fmt = check_format(fmt)
    if mode not in MODES:
        raise ValueError(f"the composition proof states the modes {', '.join(MODES)}, "
                         f"not {mode!r}")
    consts = margin_constants(fmt) if mode == "conservative" else None   # man_bits >= 8

    workdir = (Path(cwd or ".") / WORK_DIR
               / f"composition-{fmt.name}-{mode}-{unit_class.__name__}")
    text, unit = _emit(fmt, mode, unit_class)
    smt2 = _smt2(text, workdir)
    found = ports(smt2)
    n = unit.decision_cycle + 2
    st = [f"|{TOP}@{k}|" for k in range(n + 1)]
    lines = [f"(declare-const {s} |{TOP}_s|)" for s in st]
    lines += [f"(assert (|{TOP}_t| {st[k]} {st[k + 1]}))" for k in range(n)]
    lines += [f"(assert (not (|{TOP}_n rst| {s})))" for s in st[:-1]]
    lines += [f"(assert (|{TOP}_n i__valid| {st[0]}))", f"(assert (|{TOP}_n i__ready| {st[0]}))"]
    def term(name, state, width):
        """A constant equal to ``name`` in ``state`` (1-bit signals as ``BitVec(1)``)."""
        key = f"v{len(lines)}"
        lines.append(f"(declare-const {key} (_ BitVec {width}))")
        read = f"(|{TOP}_n {name}| {state})"
        lines.append(f"(assert (= {key} {read if width > 1 else f'(ite {read} #b1 #b0)'}))")
        return z3.BitVec(key, width)

    w = fmt.width
    pay_w = found["i__payload"][1]
    payload = term("i__payload", st[0], pay_w)
    binds = []
    for name, kind, _, out_t in unit.ops:
        a, b = (term(f"{name}.arg_{x}", st[out_t], w) for x in ("a", "b"))
        sub = term(f"{name}.arg_sub", st[out_t], 1) if kind == "add" else None
        binds.append((kind, sub, a, b, term(f"{name}.res", st[out_t], w),
                      term(f"{name}.res_flags", st[out_t], 3)))
    bound_binds = []
    if mode == "certified":
        bw = unit._bo.width
        for kind, an, bn, rn, out_t in unit.bound_ops:
            bound_binds.append((kind, *(term(x, st[out_t], bw) for x in (an, bn, rn))))
    out_w = len(unit.o.payload.as_value())
    out = term("out", st[n], out_w)
    out_valid = term("out_valid", st[n], 1)
    facts = list(z3.parse_smt2_string(smt2 + "\n" + "\n".join(lines) + "\n"))

    bv = z3.BitVecSort(w)
    fns = {k: (z3.Function(f"{k}_o", bv, bv, bv), z3.Function(f"{k}_flags", bv, bv,
                                                              z3.BitVecSort(3)))
           for k in ("mul", "add", "sub")}
    for kind, sub, a, b, o, fl in binds:
        # an adder's function is chosen by the subtract bit it took, as the netlist has it
        if kind == "add":
            (fa, ga), (fs, gs) = fns["add"], fns["sub"]
            facts += [o == z3.If(sub == 1, fs(a, b), fa(a, b)),
                      fl == z3.If(sub == 1, gs(a, b), ga(a, b))]
        else:
            f, g = fns[kind]
            facts += [o == f(a, b), fl == g(a, b)]

    bounds = None
    if mode == "certified":
        bounds = CutBounds(fmt, unit._bound_variant)
        if bounds.width != unit._bo.width:
            raise AssertionError(f"bound floats of {unit._bo.width} bits in the unit, "
                                 f"{bounds.width} in the reference")

    lay = input_layout(fmt, unit._ray_id_bits, unit._tri_id_bits)

    def field(layout, value, name):
        fld = layout[name]
        return z3.Extract(fld.offset + fld.width - 1, fld.offset, value)

    pay = {}
    for vec in ("o", "d", "v0", "e1", "e2", "n"):
        base = lay[vec].offset
        sub_l = lay[vec].shape
        pay[vec] = [z3.Extract(base + sub_l[c].offset + w - 1, base + sub_l[c].offset, payload)
                    for c in ("x", "y", "z")]
    values, op_flags, hit = contract(fmt, pay, fns, mode, consts, bounds)
    if mode == "certified":
        # the bound operations cut one to one, in the order both build them: the unit's
        # n-th result (canonical) is the formula's n-th, and the claim "bound_args" is that
        # the n-th takes the formula's n-th operands. The gateware's operators are
        # functions of their canonical operands (bound_operator_goal, proved first), so by
        # induction over the list both compute the same bounds.
        ref = bounds.applied
        if [k for k, *_ in ref] != [k for k, *_ in bound_binds]:
            raise AssertionError(f"the unit's {len(bound_binds)} bound operations do not "
                                 f"match the formula's {len(ref)}")
        cn = bounds.canonical
        facts += [cn(r) == v for (_, _, _, r), (_, _, _, v) in zip(bound_binds, ref)]
        bound_args = [z3.And(cn(a) == ra, cn(b) == rb)
                      for (_, a, b, _), (_, ra, rb, _) in zip(bound_binds, ref)]
    olay = output_layout(fmt, unit._ray_id_bits, unit._tri_id_bits,
                         outcome=mode == "certified")
    claims = {k: field(olay, out, k) == v for k, v in values.items()}
    if mode == "certified":
        outcome, tight = hit
        claims["outcome"] = field(olay, out, "outcome") == outcome
        claims["tight"] = (field(olay, out, "tight") == 1) == tight
        hit = outcome == 1
    claims["hit"] = (field(olay, out, "hit") == 1) == hit
    if mode == "certified":
        claims["bound_args"] = z3.And(*bound_args)
    claims["valid"] = out_valid == 1
    for k in ("ray_id", "tri_id"):
        claims[k] = field(olay, out, k) == field(lay, payload, k)
    cw = olay["n_overflow"].width
    # The counts in two steps: each operation's flags are the contract's operation's (the
    # operations matched in the order both build them), and each count is the sum of the
    # operations' flags, summed in the order the unit's operations finish (its running
    # sums). Together: the count is the contract's, a sum whatever the order of its terms.
    # (Stated as one claim, the SAT solver would have to find the matching of 33 terms.)
    if len(op_flags) != len(binds):
        raise AssertionError(f"{len(binds)} operations in the unit, {len(op_flags)} in the "
                             f"contract's formula")
    claims["op_flags"] = z3.And(*(bd[5] == ref for bd, ref in zip(binds, op_flags)))
    order = sorted(range(len(binds)), key=lambda k: (unit.ops[k][3], k))
    for b, ev in enumerate(("overflow", "underflow", "invalid")):
        count = z3.BitVecVal(0, cw)
        for k in order:
            count = count + z3.ZeroExt(cw - 1, z3.Extract(b, b, binds[k][5]))
        claims[f"n_{ev}"] = field(olay, out, f"n_{ev}") == count
        claims[f"flag_{ev}"] = ((z3.Extract(b, b, field(olay, out, "flags")) == 1)
                                == (count != 0))
    return z3.And(*facts, z3.Not(z3.And(*claims.values()))), claims, unit, n


class BoundOperator(wiring.Component):
    """One of the certified unit's bound operators (:class:`~raplas_hdl.rtl.
    certified_bound.BoundOps`: ``add`` is ``add_sum(align(a, b))``, ``mul`` is
    ``mul_round(mul_product(a, b))``) with its two halves joined, for
    :func:`prove_bound_operator` (``ops_class``: ``BoundOps`` or, in the tests, a
    deliberately wrong subclass)."""

    def __init__(self, fmt: FPFormat, k: int, kind: str, ops_class=BoundOps):
        self._ops, self.kind = ops_class(fmt, k), kind
        w = self._ops.width
        super().__init__({"a": In(w), "b": In(w), "o": Out(w)})

    def elaborate(self, platform):
        m = Module()
        ops = self._ops
        a, b = ops.view(self.a), ops.view(self.b)
        if self.kind == "add":
            r = ops.add_sum(m, ops.align(m, a, b))
        else:
            r = ops.mul_round(m, ops.mul_product(m, a, b))
        m.d.comb += self.o.eq(r)
        return m


def prove_bound_operator(fmt: FPFormat, kind: str, *, timeout: float = 600,
                         cwd=None, ops_class=BoundOps) -> dict:
    """Prove that the gateware's bound ``kind`` (``add`` or ``mul``) rounds up as the model
    does, for every pair of operands (:func:`.certified_reference.bound_operator_goal`):
    ``result``, ``seconds`` (and the operands and result of a counterexample)."""
    t0 = time.monotonic()
    unit = BoundOperator(fmt, _bound_k(fmt), kind, ops_class)
    workdir = (Path(cwd or ".") / WORK_DIR
               / f"bound-{kind}-{fmt.name}-{ops_class.__name__}")
    smt2 = _yosys_smt2(rtlil.convert(unit, name="bound_op", emit_src=False), workdir,
                       "read_rtlil top.il; prep -top bound_op; flatten; opt_clean; "
                       "write_smt2 -wires top.smt2")
    w = unit._ops.width
    lines = ["(declare-const |s| |bound_op_s|)"]
    for name in ("a", "b", "o"):
        lines += [f"(declare-const v_{name} (_ BitVec {w}))",
                  f"(assert (= v_{name} (|bound_op_n {name}| |s|)))"]
    facts = z3.parse_smt2_string(smt2 + "\n" + "\n".join(lines) + "\n")
    a, b, o = (z3.BitVec(f"v_{x}", w) for x in "abo")
    run = solve(z3.And(*facts, bound_operator_goal(fmt, kind, o, a, b)), timeout,
                watch={"a": a, "b": b, "o": o})
    out = {"result": run.result, "solver_seconds": round(run.seconds, 1),
           "seconds": round(time.monotonic() - t0, 1)}
    if run.result == "counterexample":
        out["values"] = run.values
    elif run.result == "unknown":
        out["reason"] = run.reason
    return out


def _bound_k(fmt: FPFormat) -> int:
    return int(certified_constants(fmt, 1.0, "exp")[2])


#: The certified mode's claims in separate solver calls (one call for all of them did not
#: finish in 10 minutes at e4m3, where each group takes one or two): the cut bound
#: operations' operands, the decision, and the rest (the paper mode's claims).
CERTIFIED_GROUPS = (("bound_args",), ("outcome", "tight", "hit"))


def _claim_groups(claims: dict, mode: str) -> list:
    """The claims' names in the groups :func:`prove_composition` solves one at a time: all
    together, or in certified mode :data:`CERTIFIED_GROUPS` and the rest."""
    if mode != "certified":
        return [tuple(claims)]
    taken = {k for g in CERTIFIED_GROUPS for k in g}
    return [*CERTIFIED_GROUPS, tuple(k for k in claims if k not in taken)]


def prove_composition(fmt: FPFormat, *, mode: str = "paper", timeout: float = 600,
                      cwd=None, unit_class=ComposedUnit) -> dict:
    """Prove the ray-triangle unit's datapath by composition (module docstring).

    Returns
    -------
    dict
        ``result`` ("proved", "counterexample" or "unknown"), ``ops`` (the operations
        bound), ``cycles`` (unrolled), ``seconds``, ``solver``; for a counterexample, the
        claims that fail (``differs``).

    Raises
    ------
    ValueError
        For a mode not in :data:`MODES`, or a format the mode does not take (the
        conservative mode needs 8 fraction bits).
    """
    t0 = time.monotonic()
    steps = []
    if mode == "certified":
        # the bound operators first: the composition takes them as functions
        check_certified_format(fmt)
        for kind in ("add", "mul"):
            one = prove_bound_operator(fmt, kind, timeout=timeout, cwd=cwd)
            steps.append({"proves": f"bound {kind}: the gateware's operator rounds up as the "
                                    "model does",
                          "result": one["result"], "seconds": one["solver_seconds"]})
            if one["result"] != "proved":
                return {"result": one["result"], "ops": 0, "cycles": 0, "solver": SOLVER,
                        "solver_seconds": one["solver_seconds"], "steps": steps,
                        "seconds": round(time.monotonic() - t0, 1),
                        **({"differs": [f"bound_{kind}"]} if one["result"] ==
                           "counterexample" else {"reason": one.get("reason", "")})}
    goal, claims, unit, n = composition_goal(fmt, mode=mode, cwd=cwd, unit_class=unit_class)
    facts = goal.children()[:-1]                  # goal = And(*facts, Not(And(*claims)))
    one, nil = z3.BitVecVal(1, 1), z3.BitVecVal(0, 1)
    for group in _claim_groups(claims, mode):
        part = {k: claims[k] for k in group}
        run = solve(z3.And(*facts, z3.Not(z3.And(*part.values()))), timeout,
                    watch={k: z3.If(c, one, nil) for k, c in part.items()},
                    ackermann_limit=ACKERMANN_LIMIT)
        what = ("output register == contract formula" if len(group) == len(claims)
                else ", ".join(group) + " == contract formula")
        steps.append({"proves": f"composition: {what} ({mode} mode)", "result": run.result,
                      "seconds": round(run.seconds, 1)})
        if run.result != "proved":
            break
    res = {"result": run.result, "ops": len(unit.ops), "cycles": n, "solver": SOLVER,
           "solver_seconds": round(sum(st["seconds"] for st in steps), 1), "steps": steps,
           "bound_ops": len(getattr(unit, "bound_ops", ())),
           "seconds": round(time.monotonic() - t0, 1)}
    if run.result == "counterexample":
        res["differs"] = [k for k, v in run.values.items() if v == 0]
    elif run.result == "unknown":
        res["reason"] = run.reason
    return res
