"""Issue 23, first slice: the FP units' Verilog proved equal to the contract for all inputs.

What is checked here, and why each can fail:

- the proofs themselves (adders FP16/FP24 in rtz, rne, chop at the registry's default
  stages; the FP24 1-stage multiplier; the chain of the default multiplier);
- the references: the bit-vector forms (the chop adder, the multiplier) against the golden
  model on every operand pair of two 8-bit formats and on random FP24 pairs, evaluated
  concretely from the very terms the proofs use; the FloatingPoint-theory adder against
  the golden model on every pair of two 6-bit formats (folded by z3's simplifier); the
  multiplier's bit-vector form proved equal to its FloatingPoint-theory form at small
  formats;
- negative controls: mutated designs (a saturation constant changed in the Verilog text,
  the alignment or the rounding sticky bit dropped while building) must give a
  counterexample, and it must be a real one: the golden model agrees with the contract's
  result there and not with the RTL's;
- synthesis: the netlists of ``synth_ecp5`` (with the DSP register packing) and of
  ``synth_xilinx -family xc4v`` proved equal to the RTL, and a netlist synthesised from
  mutated Verilog caught, with the RTL's side agreeing with the golden model;
- stream stages (SymbiYosys): the block-RAM FIFO, Amaranth's SyncFIFOBuffered and the
  credit FIFO, plain and in banks (bounded), the job distributor, the result merger and the
  result framing (k-induction) keep the stream rule and lose, double or reorder no beat (the
  framing: and sets ``last`` and ``empty`` where the markers say), and a mutant of each
  gives a counterexample (three of the framing: no ``last``, no ``empty``, a hold register
  that takes a result not taken); the pair selector (k-induction) gives each ray of its
  spheres' masks in order, a job if enabled or else a skip, and four mutants of it fail
  (a disabled ray's job sent, a job overwritten under back-pressure, rays lost at a row
  change, the enable read from the wrong bank); the reducer's send stage (bounded, marked
  ``full``) sends each run's answers lowest ray first with ``last`` on the final one, or one
  ``empty`` beat, and three mutants fail (highest first, no ``last``, a beat without ``hit``
  as a candidate);
- the command line: exit codes 0, 1, 3 and 2.

Each proof takes seconds (about 60 s in all on a quiet 2-core machine); the durations are
printed (``pytest -s``) and shown by ``--durations``.
"""

from __future__ import annotations

import functools
import re
import time

import numpy as np
import pytest
from amaranth.hdl import Const
import z3

from raplas_hdl.cli import main
from raplas_hdl.fp import FP16, FP24, FPFormat, model
from raplas_hdl.formal import default_stages, describe, prove
from raplas_hdl.formal.concrete import evaluate
from raplas_hdl.formal.reference import reference
from raplas_hdl.rtl import fp_add, fp_mul

TIMEOUT = 120


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("formal")


def check_proof(unit, fmt, work, stages=None, **kw):
    t0 = time.monotonic()
    res = prove(unit, fmt, stages, timeout=TIMEOUT, cwd=work, **kw)
    print(f"{unit} {fmt} stages={res.stages} {res.method}: {res.result} "
          f"in {time.monotonic() - t0:.1f} s")
    return res


def check_real_counterexample(res, fmt):
    """The counterexample is real: golden model == contract != RTL on its operands."""
    assert res.result == "counterexample", (res.result, res.reason)
    c = res.counterexample
    op = model.mul if res.unit == "fp-mul" else model.sub if c.get("in.sub") else model.add
    gb, gf = op(c["in.a"], c["in.b"], fmt, flags=True)
    assert (c["ref.o"], c["ref.flags"]) == (int(gb), int(gf)), "the contract disagrees " \
        "with the golden model"
    assert (c["rtl.o"], c["rtl.flags"]) != (int(gb), int(gf)), "the RTL is right here"
    text = "\n".join(describe(res, fmt))
    assert f"0x{c['in.a']:06x}" in text and "golden" in text and "contract" in text


# -- proofs -----------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", [FP16, FP24], ids=["FP16", "FP24"])
@pytest.mark.parametrize("rounding", ["rtz", "rne", "chop"])
def test_adder_proved(fmt, rounding, work):
    res = check_proof("fp-add", fmt.with_rounding(rounding), work)
    assert res.result == "proved", (res.result, res.reason, res.counterexample)
    assert res.stages == default_stages("fp-add", fmt.with_rounding(rounding))
    assert res.stages == {"rtz": 6, "rne": 7, "chop": 5}[rounding]


def test_fp24_one_stage_multiplier_proved(work):
    res = check_proof("fp-mul", FP24, work, stages=1)
    assert res.result == "proved", (res.result, res.reason)
    assert "cut" in res.method


def test_default_multiplier_proved_by_chain(work):
    res = check_proof("fp-mul", FP24, work, method="chain")
    assert res.result == "proved", (res.result, res.reason)
    assert [s["result"] for s in res.steps] == ["proved", "proved"]
    assert res.steps[0]["proves"].startswith(f"{default_stages('fp-mul', FP24)}-stage == 1-stage")


def test_default_stages_follow_the_rtl(work, monkeypatch):
    """The proof takes the RTL's own default stage count, whatever it is."""
    from raplas_hdl.rtl import step_delays

    table = {u: dict(per) for u, per in step_delays.DEFAULT_STAGES.items()}
    table["fp_mul"]["rtz"] = 2
    monkeypatch.setattr(step_delays, "DEFAULT_STAGES", table)
    monkeypatch.setattr("raplas_hdl.rtl.fp_mul.DEFAULT_STAGES", table)
    res = check_proof("fp-mul", FP16, work)
    assert res.stages == 2 and res.result == "proved"


# -- references against the golden model -------------------------------------------------
def _all_pairs(fmt):
    n = 1 << fmt.width
    return np.repeat(np.arange(n, dtype=np.uint64), n), np.tile(np.arange(n, dtype=np.uint64), n)


def _random_pairs(fmt, count, seed):
    rng = np.random.default_rng(seed)
    a = rng.integers(0, 1 << fmt.width, count, dtype=np.uint64)
    b = rng.integers(0, 1 << fmt.width, count, dtype=np.uint64)
    # half of them near each other: cancellation and small alignment shifts
    near = a ^ rng.integers(0, 1 << (fmt.man_bits + 2), count, dtype=np.uint64)
    return a, np.where(np.arange(count) % 2 == 0, b, near)


def check_reference(fmt, op, a, b, sub=0):
    w = fmt.width
    va, vb, vs = z3.BitVec("a", w), z3.BitVec("b", w), z3.BitVec("s", 1)
    bits, flags = reference(fmt, op, va, vb, vs if op == "add" else None,
                            bitvector=op == "mul")
    values = {"a": a, "b": b, "s": np.full(a.size, sub, dtype=np.uint64)}
    rb, rf = evaluate(bits, values, a.size), evaluate(flags, values, a.size)
    fn = model.mul if op == "mul" else model.sub if sub else model.add
    gb, gf = fn(a.astype(np.uint32), b.astype(np.uint32), fmt, flags=True)
    bad = np.nonzero((rb != gb) | (rf != gf))[0]
    assert bad.size == 0, [(hex(int(a[i])), hex(int(b[i])), hex(int(rb[i])), hex(int(gb[i])),
                            int(rf[i]), int(gf[i])) for i in bad[:5]]


@pytest.mark.parametrize("fmt", [FPFormat(4, 3, "chop"), FPFormat(3, 4, "chop")],
                         ids=["e4m3", "e3m4"])
@pytest.mark.parametrize("sub", [0, 1], ids=["add", "sub"])
def test_chop_reference_matches_golden_on_every_pair(fmt, sub):
    check_reference(fmt, "add", *_all_pairs(fmt), sub)


@pytest.mark.parametrize("sub", [0, 1], ids=["add", "sub"])
def test_chop_reference_matches_golden_fp24_random(sub):
    check_reference(FP24.with_rounding("chop"), "add", *_random_pairs(FP24, 200_000, 23 + sub),
                    sub)


@pytest.mark.parametrize("rounding", ["rtz", "rne", "chop"])
def test_bitvector_mul_reference_matches_golden(rounding):
    check_reference(FPFormat(4, 3, rounding), "mul", *_all_pairs(FPFormat(4, 3)))
    fmt = FP24.with_rounding(rounding)
    check_reference(fmt, "mul", *_random_pairs(fmt, 200_000, 7))


@pytest.mark.parametrize("fmt", [FPFormat(3, 2), FPFormat(2, 3)], ids=["e3m2", "e2m3"])
@pytest.mark.parametrize("rounding", ["rtz", "rne"])
def test_floating_point_adder_reference_matches_golden_on_every_pair(fmt, rounding):
    """The FloatingPoint-theory reference has no concrete evaluator of its own: z3's
    simplifier folds it for each constant operand pair (4096 pairs, add and sub:
    about 1 s)."""
    fmt = fmt.with_rounding(rounding)
    w = fmt.width
    a, b, s = z3.BitVec("a", w), z3.BitVec("b", w), z3.BitVec("s", 1)
    term = z3.Concat(*reference(fmt, "add", a, b, s))
    n = 1 << w
    pa, pb = _all_pairs(fmt)
    bad = []
    for sub, fn in ((0, model.add), (1, model.sub)):
        gb, gf = fn(pa.astype(np.uint32), pb.astype(np.uint32), fmt, flags=True)
        for i in range(n * n):
            got = z3.simplify(z3.substitute(term, (a, z3.BitVecVal(int(pa[i]), w)),
                                            (b, z3.BitVecVal(int(pb[i]), w)),
                                            (s, z3.BitVecVal(sub, 1))))
            if got.as_long() != (int(gb[i]) << 3) | int(gf[i]):
                bad.append((sub, int(pa[i]), int(pb[i])))
    assert not bad, bad[:5]


@pytest.mark.parametrize("fmt", [FPFormat(4, 3), FPFormat(3, 4), FPFormat(5, 6)],
                         ids=["e4m3", "e3m4", "e5m6"])
@pytest.mark.parametrize("rounding", ["rtz", "rne"])
def test_bitvector_mul_reference_equals_floating_point_theory(fmt, rounding):
    fmt = fmt.with_rounding(rounding)
    a, b = z3.BitVecs("a b", fmt.width)
    bv = reference(fmt, "mul", a, b, bitvector=True)
    fp = reference(fmt, "mul", a, b)
    s = z3.Solver()
    s.set("timeout", 60_000)
    s.add(z3.Or(bv[0] != fp[0], bv[1] != fp[1]))
    assert s.check() == z3.unsat


# -- negative controls ----------------------------------------------------------------------
def _saturate_wrong(text):
    """rtz overflow gives max finite - 1 ulp (the constant in the pack step)."""
    return text.replace(f"23'h{FP24.max_finite:06x}", f"23'h{FP24.max_finite - 1:06x}")


def test_mutated_saturation_gives_real_counterexample(work):
    res = check_proof("fp-add", FP24, work, mutate=_saturate_wrong)
    check_real_counterexample(res, FP24)
    assert res.counterexample["rtl.flags"] & 1    # the overflow path is the one changed


def test_dropped_alignment_sticky_gives_real_counterexample(work, monkeypatch):
    real = fp_add.FPAdd._step_shift

    def no_sticky(self, m, v):                 # the alignment's sticky bit dropped
        return {**real(self, m, v), "sticky": Const(0, 1)}

    monkeypatch.setattr(fp_add.FPAdd, "_step_shift", no_sticky)
    res = check_proof("fp-add", FP24, work)
    check_real_counterexample(res, FP24)
    assert res.counterexample["in.a"] >> 23 != res.counterexample["in.b"] >> 23 \
        or res.counterexample["in.sub"], "only an effective subtraction needs the sticky bit"


def _round_without_sticky(module, monkeypatch):
    """The module's rounding (plain, and with the range tests where it has that) blind to
    the sticky bit."""
    for name in ("round_significand", "round_significand_ranged"):
        if hasattr(module, name):
            monkeypatch.setattr(module, name, functools.partial(_no_sticky,
                                                                getattr(module, name)))


def _no_sticky(real, fmt, sig, exp, guard, sticky):
    return real(fmt, sig, exp, guard, 0)


def test_rne_adder_without_sticky_gives_real_counterexample(work, monkeypatch):
    _round_without_sticky(fp_add, monkeypatch)
    fmt = FP24.with_rounding("rne")
    check_real_counterexample(check_proof("fp-add", fmt, work), fmt)


def test_rne_multiplier_without_sticky_gives_real_counterexample(work, monkeypatch):
    _round_without_sticky(fp_mul, monkeypatch)
    fmt = FP24.with_rounding("rne")
    check_real_counterexample(check_proof("fp-mul", fmt, work), fmt)


def test_mutated_multiplier_fails_the_chain(work):
    res = check_proof("fp-mul", FP24, work, method="chain", mutate=_saturate_wrong)
    check_real_counterexample(res, FP24)
    assert res.steps[0]["result"] == "counterexample"


# -- stall and reset ----------------------------------------------------------------------
@pytest.mark.parametrize("unit", ["fp-add", "fp-mul"])
def test_control_properties_proved(unit, work):
    res = check_proof(unit, FP24, work, method="control")
    assert res.result == "proved", (res.result, res.reason, res.steps)
    assert [s["proves"] for s in res.steps] == ["control: hold", "control: reset",
                                                "control: outputs"]


@pytest.mark.parametrize("unit", ["fp-add", "fp-mul"])
@pytest.mark.parametrize("prop, mutation", [
    ("hold", ("if (en) begin", "if (1'h1) begin")),     # one register ignores the stall
    ("reset", ("if (rst) begin", "if (1'h0) begin")),   # one valid bit ignores the reset
])
def test_control_mutants_fail(unit, prop, mutation, work):
    res = check_proof(unit, FP24, work, method="control",
                      mutate=lambda t: t.replace(*mutation, 1))
    assert res.result == "counterexample"
    assert res.steps[-1]["proves"] == f"control: {prop}"


@pytest.mark.parametrize("unit", ["fp-add", "fp-mul"])
def test_sby_agrees_at_the_ports(unit, work):
    res = check_proof(unit, FP24, work, method="sby")
    assert res.result == "proved", (res.result, res.reason)
    for mutation in (("if (en) begin", "if (1'h1) begin"), ("if (rst) begin", "if (1'h0) begin")):
        bad = check_proof(unit, FP24, work, method="sby", mutate=lambda t: t.replace(*mutation))
        assert bad.result == "counterexample", (mutation, bad.result, bad.reason)


# -- command line -----------------------------------------------------------------------------
def test_cli_proves_and_exits_0(capsys, monkeypatch, work):
    monkeypatch.chdir(work)
    assert main(["prove", "fp-mul", "--format", "FP16/rne"]) == 0
    out = capsys.readouterr().out
    stages = default_stages("fp-mul", FP16.with_rounding("rne"))
    assert re.search(rf"fp-mul FP16/rne, {stages} stages, generic: proved in [\d.]+ s by cut",
                     out), out


def test_cli_counterexample_exits_1(capsys, monkeypatch, work):
    monkeypatch.chdir(work)
    _round_without_sticky(fp_mul, monkeypatch)
    assert main(["prove", "fp-mul", "--format", "FP16/rne", "--stages", "1"]) == 1
    out = capsys.readouterr().out
    assert "counterexample" in out and "golden" in out and "RTL" in out


def test_cli_unknown_exits_3(capsys, monkeypatch, work):
    monkeypatch.chdir(work)
    assert main(["prove", "fp-add", "--format", "FP24/rne", "--timeout", "0.05"]) == 3
    assert "unknown after" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["fp-div"], "unit must be one of fp-add, fp-mul"),
    (["fp-mul", "--stages", "6"], "--stages of fp-mul must be 1 to 5"),
    (["fp-add", "--method", "cut"], "--method of fp-add must be direct"),
    (["fp-le", "--target", "virtex4"], "fp-le has no --target"),
    (["fp-mul", "--target", "virtex4", "--method", "chain"], "proved by --method cut"),
    (["fp-add", "--timeout", "-1"], "--timeout"),
    (["fp-add", "--format", "FP48"], "FP48"),
    (["fp-add", "--json", "out.txt"], ".json"),
    (["fp-add", "--mode", "conservative"], "fp-add has no --mode"),
    (["ray-triangle", "--mode", "certified", "--format", "e10m5"],
     "--mode certified needs at most 9 exponent bits, not 10"),
    (["ray-triangle", "--mode", "conservative", "--format", "e4m3"],
     "--mode conservative needs at least 8 fraction bits, not 3"),
    (["ray-triangle", "--mode", "exact"], "mode must be one of paper, conservative"),
    (["ray-triangle", "--stages", "3"], "ray-triangle takes no --stages"),
    (["ray-triangle", "--method", "direct"], "--method of ray-triangle must be composition"),
    (["fp-add", "--method", "composition"], "--method of fp-add must be direct"),
])
def test_cli_bad_input_is_one_line_exit_2(argv, message, capsys, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    assert main(["prove", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "build").exists(), "work was done before the error"


def test_cli_help_is_plain(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["prove", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "``" not in text and ":mod:" not in text and "(default None)" not in text
    assert ("--method {direct,cut,chain,control,sby,netlist-ecp5,netlist-xc4v,composition}"
            in text)


def test_model_and_host_never_import_the_prover():
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = str(Path(__file__).resolve().parents[2])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [root, *filter(None, [os.environ.get("PYTHONPATH")])])}
    code = ("import sys, raplas_hdl.fp.model, raplas_hdl.host, raplas_hdl.rtl.units, "
            "raplas_hdl.cli; "
            "bad = [m for m in sys.modules if m.startswith('raplas_hdl.formal') or m == 'z3']; "
            "assert not bad, bad")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, env=env, cwd=root)
    assert res.returncode == 0, res.stderr[-2000:]


# -- the comparisons and neg (the ray-triangle unit's decision) ----------------------------
@pytest.mark.parametrize("fmt", [FP16, FP24, FPFormat(8, 23)], ids=["FP16", "FP24", "FP32"])
@pytest.mark.parametrize("unit", ["fp-le", "fp-lt", "fp-neg"])
def test_comparisons_and_neg_proved(unit, fmt, work):
    res = check_proof(unit, fmt, work)
    assert res.result == "proved", (res.result, res.reason, res.counterexample)
    assert res.stages == 1 == default_stages(unit, fmt)


@pytest.mark.parametrize("op", ["le", "lt", "neg"])
def test_comparison_and_neg_references_match_golden_on_every_pair(op):
    """The references of le, lt (the FloatingPoint theory's ordered comparisons of the
    decoded values) and neg, folded by z3 for every operand pair of e3m2, against the
    golden model."""
    fmt = FPFormat(3, 2)
    w = fmt.width
    a, b = z3.BitVec("a", w), z3.BitVec("b", w)
    term = reference(fmt, op, a, b)[0]
    pa, pb = _all_pairs(fmt)
    pa, pb = pa.astype(np.uint32), pb.astype(np.uint32)
    golden = (model.neg(pa, fmt) if op == "neg" else
              (model.le if op == "le" else model.lt)(pa, pb, fmt).astype(np.uint32))
    bad = []
    for i in range(pa.size):
        got = z3.simplify(z3.substitute(term, (a, z3.BitVecVal(int(pa[i]), w)),
                                        (b, z3.BitVecVal(int(pb[i]), w)))).as_long()
        if got != int(golden[i]):
            bad.append((int(pa[i]), int(pb[i]), got, int(golden[i])))
    assert not bad, bad[:5]


def test_le_unit_against_the_lt_contract_differs_where_equal(work):
    """A negative control: fp-le's netlist against lt's contract gives a counterexample,
    two operands with equal values (the golden model says le and not lt)."""
    from raplas_hdl.formal.miter import contract_miter, unroll
    from raplas_hdl.formal.netlist import netlist
    from raplas_hdl.formal.solve import solve

    goal, watch = contract_miter(unroll(netlist("fp-le", FP24, 1, cwd=work)), "lt")
    run = solve(goal, TIMEOUT, watch)
    assert run.result == "counterexample", (run.result, run.reason)
    c = run.values
    a, b = c["in.a"], c["in.b"]
    assert model.le(a, b, FP24) and not model.lt(a, b, FP24)
    assert (c["rtl.o"], c["ref.o"]) == (1, 0)


def test_mutated_neg_nan_gives_real_counterexample(work):
    """fp-neg with its canonical NaN changed: the counterexample is a NaN operand, where
    the golden model agrees with the contract and not with the RTL."""
    res = check_proof("fp-neg", FP24, work,
                      mutate=lambda t: t.replace("24'h7f8000", "24'h7f8001"))
    assert res.result == "counterexample", (res.result, res.reason)
    c = res.counterexample
    golden = int(model.neg(c["in.a"], FP24))
    assert golden == FP24.nan == c["ref.o"] != c["rtl.o"]
    text = "\n".join(describe(res, FP24))
    assert "neg(a)" in text and "golden" in text and f"0x{FP24.nan:06x}" in text


# -- synthesised netlists against the RTL ---------------------------------------------------
@pytest.mark.parametrize("unit, flow", [("fp-add", "ecp5"), ("fp-mul", "xc4v")])
def test_synthesised_netlist_proved_equal_to_the_rtl(unit, flow, work):
    """The other pairs (and every format and rounding) are in benchmarks/bench_prove.py; the
    controls below run them the other way round."""
    fmt = FP24.with_rounding("rne")
    res = check_proof(unit, fmt, work, method=f"netlist-{flow}")
    assert res.result == "proved", (res.result, res.reason, res.steps)
    assert res.stages == default_stages(unit, fmt)
    assert res.method.startswith(f"netlist-{flow}: the {flow} netlist == the RTL")
    assert ("product cut" in res.method) == (unit == "fp-mul")


@pytest.mark.parametrize("unit, flow", [("fp-add", "xc4v"), ("fp-mul", "ecp5")])
def test_netlist_of_a_mutated_verilog_gives_a_real_counterexample(unit, flow, work):
    """A synthesis that did not do what the RTL says (here: it was given Verilog whose rtz
    overflow saturates one ulp low) is caught, and the RTL is the side that is right."""
    res = check_proof(unit, FP24, work, method=f"netlist-{flow}", mutate=_saturate_wrong)
    assert res.result == "counterexample", (res.result, res.reason)
    c = res.counterexample
    op = model.mul if unit == "fp-mul" else model.sub if c.get("in.sub") else model.add
    gb, gf = op(c["in.a"], c["in.b"], FP24, flags=True)
    assert (c["rtl.o"], c["rtl.flags"]) == (int(gb), int(gf))
    magnitude = c["net.o"] & ((1 << (FP24.width - 1)) - 1)     # either sign overflows
    assert magnitude == FP24.max_finite - 1 and c["net.flags"] & 1
    text = "\n".join(describe(res, FP24))
    assert "netlist" in text and "golden" in text


def test_a_cut_counterexample_that_the_real_product_refutes_is_excluded(work, monkeypatch):
    """The solver may answer the product cut with a counterexample that needs a product that
    is not one (which one it picks is its own choice): those inputs are checked with the
    real product, excluded, and the cut asked again, so the real counterexample is found."""
    import importlib

    from raplas_hdl.formal.solve import SolverRun

    prove_module = importlib.import_module("raplas_hdl.formal.prove")   # not the function

    real_solve = prove_module.solve
    calls = []

    def first_answer_spurious(goal, timeout, watch=None, **kw):
        calls.append(goal)
        if len(calls) == 1:                     # a = b = 0 (0 * 0 never overflows)
            return SolverRun("counterexample", 0.0,
                             {k: 0 for k in watch if k.startswith("in.")})
        return real_solve(goal, timeout, watch, **kw)

    monkeypatch.setattr(prove_module, "solve", first_answer_spurious)
    res = check_proof("fp-mul", FP24, work, method="netlist-ecp5", mutate=_saturate_wrong)
    assert res.result == "counterexample", (res.result, res.reason, res.steps)
    assert [s["result"] for s in res.steps] == ["counterexample", "proved", "counterexample",
                                                "counterexample"]
    assert "those inputs excluded" in res.steps[2]["proves"]
    assert (res.counterexample["in.a"], res.counterexample["in.b"]) != (0, 0)


# -- the virtex4 target (DSP48 through Yosys's model of it) --------------------------------
@pytest.mark.parametrize("unit, fmt", [("fp-mul", FP24.with_rounding("rne")),
                                       ("fp-add", FP16)], ids=["fp-mul-FP24-rne", "fp-add-FP16"])
def test_virtex4_target_proved(unit, fmt, work):
    res = check_proof(unit, fmt, work, target="virtex4")
    assert res.result == "proved", (res.result, res.reason, res.steps)
    assert res.target == "virtex4"
    assert ("guarded" in res.method) == (unit == "fp-mul")
    top = unit.replace("-", "_")
    dirs = list((work / "build" / "formal").glob(f"{top}-{fmt.name}-s{res.stages}-virtex4-*"))
    assert dirs and all("DSP48" in (d / "top.v").read_text() for d in dirs)


def test_virtex4_multiplier_mutant_gives_real_counterexample(work):
    res = check_proof("fp-mul", FP24, work, target="virtex4", mutate=_saturate_wrong)
    check_real_counterexample(res, FP24)


# -- stream stages of the intersection unit (SymbiYosys) ------------------------------------
@pytest.mark.parametrize("stage", ["bram-fifo", "sync-fifo-buffered", "credit-fifo",
                                   "credit-fifo-banked", "output-credits",
                                   "job-distributor", "result-merger",
                                   "result-framing", "pair-selector", "pair-selector-reduce",
                                   "record-fetch",
                                   pytest.param("sphere-feeder", marks=pytest.mark.full),
                                   pytest.param("reducer-send", marks=pytest.mark.full),
                                   pytest.param("reducer-certified", marks=pytest.mark.full)])
def test_stream_stage_checked(stage, work):
    from raplas_hdl.formal.streams import STAGES, check_stage

    # the feeder's and the reducers' bounded checks take 160 to 290 s, 220 to 310 s and
    # about 300 s in one solver call (docs/formal.md)
    slow = stage in ("sphere-feeder", "reducer-send", "reducer-certified")
    res = check_stage(stage, timeout=600 if slow else TIMEOUT, cwd=work)
    print(f"{stage}: {res['result']} in {res['seconds']:.1f} s")
    expected = "proved" if STAGES[stage].mode == "prove" else "bounded"
    assert res["result"] == expected, res
    assert [s["proves"].split(":")[0] for s in res["steps"]] == [
        f"sby {STAGES[stage].mode}", "sby cover"]


@pytest.mark.parametrize("stage, mutation", [
    # the turn moves on a beat offered but not taken: a beat on the wrong lane
    ("job-distributor", ("assign \\$7  = i__valid & i__ready;", "assign \\$7  = i__valid;")),
    # the turn moves after every beat, not after a job's last: results out of job order
    ("result-merger", ("assign \\$8  = \\$7  & job_last;", "assign \\$8  = \\$7 ;")),
    # a write into a full FIFO is accepted: a word overwritten, lost
    ("bram-fifo", ("inner_level != 2'h3", "inner_level != 3'h4")),
    ("sync-fifo-buffered", ("inner_level != 2'h3", "inner_level != 3'h4")),
    # the FIFO reports room an entry early: the writers' credits no longer find it
    ("credit-fifo", ("w_stream__ready = inner_level != 2'h3", "w_stream__ready = inner_level "
                                                              "!= 2'h2")),
    # the ray-triangle unit's credit count allows one pair too many after an accept: the
    # FIFO behind, written unchecked, is written full
    ("output-credits", ("assign \\$15  = held < 3'h4;", "assign \\$15  = held < 3'h5;")),
    # ... its ready ignores the credit freed by the last take: a pair refused with room
    ("output-credits", ("assign i_ready = took ? held_le : held_lt;",
                        "assign i_ready = held_lt;")),
    # the framing sends a held result on a marker without last (bit 71; an empty beat's
    # last, set by the same line further on, is left alone)
    ("result-framing", ("o__payload[71] = 1'h1;", "o__payload[71] = 1'h0;", 1)),
    # ... its hold register takes a result offered but not taken: beats doubled or lost
    ("result-framing", ("assign \\$2  = i__valid & o__ready;", "assign \\$2  = i__valid;")),
    # ... a marker with no result since the last sends a beat without empty (bit 72)
    ("result-framing", ("o__payload[72] = 1'h1;", "o__payload[72] = 1'h0;")),
    # the selector sends a disabled ray's job (the enable lookup drops nothing)
    ("pair-selector", ("assign o__valid = e_v & \\$33 ;", "assign o__valid = e_v;")),
    # ... its iterator moves on while the lookup is stalled: a job overwritten, lost
    ("pair-selector", ("assign enable__en = \\$30  | o__ready;", "assign enable__en = 1'h1;")),
    # ... a row after the first starts from the columns left, not the mask: rays lost
    ("pair-selector", ("assign \\$44  = \\$43  ? it[4:3] : cols_next;",
                       "assign \\$44  = cols_next;")),
    # ... the enable lookup reads bank 0 whatever the run's bank
    ("pair-selector", ("assign \\$32  = it[8] ? \\$31  : { 2'h0, \\$24 [1:0] };",
                       "assign \\$32  = { 2'h0, \\$24 [1:0] };")),
    # with the early-out, the selector counts a blocked ray as skipped
    ("pair-selector-reduce", ("assign \\$41  = ~ enable__data;",
                              "assign \\$41  = ~ enable__data | \\blocked$29 ;")),
    # ... it applies a report for an earlier run too
    ("pair-selector-reduce", ("assign \\$27  = blk_seq == \\$signal ;",
                              "assign \\$27  = blk_seq <= \\$signal ;")),
    # ... it takes the blocked bits without their cycle's delay (the run number with it)
    ("pair-selector-reduce", ("assign \\$29  = blk >> o__payload[1:0];",
                              "assign \\$29  = blocked >> o__payload[1:0];")),
    # ... its run number counts every job taken, not the markers
    ("pair-selector-reduce", ("assign \\$51  = \\$50  & o__payload[6];",
                              "assign \\$51  = \\$50 ;")),
    # the record fetch starts with 5 credits for a FIFO of 4: a write into a full FIFO
    ("record-fetch", ("3'h4", "3'h5")),
    # ... it takes the next job after any pair, not only the last: a job's pairs lost
    ("record-fetch", ("assign \\$4  = issue & last;", "assign \\$4  = issue;")),
    # ... its registered ``last`` comes a pair late: a pair beyond the job's triangles
    ("record-fetch", ("assign \\$11  = k + 2'h2;", "assign \\$11  = k + 1'h1;")),
    # ... its registered credit test reads the credit before the cycle's pair: one pair
    # more than the FIFO has room for
    ("record-fetch", ("assign \\$9  = | \\$2 [2:0];", "assign \\$9  = | credit;")),
    # ... it reads the Ray Memory's bank 0 whatever the job's bank
    ("record-fetch", ("assign \\$8  = g2[2] ? \\$7  : { 2'h0, g2[1] };",
                      "assign \\$8  = { 2'h0, g2[1] };")),
    # ... it sets the job-last bit on a marker's pair only: the lanes' merger never moves on
    ("record-fetch", ("\\$25 [4] = last;", "\\$25 [4] = job[5];")),
    # the sphere feeder ignores the run lists: an indirect run's spheres are its positions
    ("sphere-feeder", ("assign f1_sid = f1[1] ? rlist__data : f1[2];",
                       "assign f1_sid = f1[2];")),
    # ... it loads the planes of bank 0 whatever the run's bank
    ("sphere-feeder", ("assign \\$10  = run[3] ? \\$9  : { 2'h0, ld_k };",
                       "assign \\$10  = { 2'h0, ld_k };")),
    # ... it loads planes without draining the spheres of the runs before
    ("sphere-feeder", ("assign drained = \\$7  & \\$8 ;", "assign drained = 1'h1;")),
    # ... it starts with 9 credits for a FIFO of 8
    ("sphere-feeder", ("4'h8", "4'h9")),
    # the reducer sends its answers highest ray first (the encoder's index from the valid
    # bits, highest set)
    ("reducer-send", ("assign \\$227  = | { \\$226 [3], \\$226 [1] };\n"
                      "  assign \\$228  = | \\$226 [3:2];",
                      "assign \\$227  = rest[3] | (~rest[2] & rest[1]);\n"
                      "  assign \\$228  = rest[3] | rest[2];")),
    # ... it never marks an answer last: the run ends in an empty beat after its answers
    ("reducer-send", ("\\$382  = s_only;", "\\$382  = 1'h0;")),
    # ... a beat without hit can be a candidate: an answer for a ray without a hit beat
    ("reducer-send", ("assign \\$52  = b[31] & \\$51 ;", "assign \\$52  = \\$51 ;")),
    # the certified reducer does not stall while its skid register is full: a passed-on
    # pair overwrites the one held there, lost
    ("reducer-certified", ("assign en = \\$258  & \\$259 ;", "assign en = \\$258 ;")),
])
def test_stream_stage_mutants_fail(stage, mutation, work):
    from raplas_hdl.formal.streams import check_stage

    def mutate(text):
        assert mutation[0] in text, f"the mutation no longer applies to {stage}: {mutation[0]}"
        return text.replace(*mutation)

    res = check_stage(stage, timeout=TIMEOUT, cwd=work, mutate=mutate)
    assert res["result"] == "counterexample", res


def test_a_bank_out_of_step_fails(work):
    """The banked credit FIFO with its last bank's inner read ignoring the reader (it moves
    a word to its output register only when that is empty): the banks' words part, and the
    check gives a counterexample."""
    from raplas_hdl.formal.streams import check_stage

    a, b = "assign \\$3  = \\$2  | r_stream__ready;", "assign \\$3  = \\$2 ;"

    def last_bank(text):
        assert text.count(a) == 3          # once per bank: mutate bank 2 only
        i = text.rindex(a)
        return text[:i] + b + text[i + len(a):]

    res = check_stage("credit-fifo-banked", timeout=TIMEOUT, cwd=work, mutate=last_bank)
    assert res["result"] == "counterexample", res
