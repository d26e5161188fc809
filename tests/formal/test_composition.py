"""The ray-triangle unit proved by composition (``raplas_hdl.formal.composition``).

The stand-in build keeps the real unit's schedule; a unit wired wrong (operands of an
operation swapped, an operation's flags left out of the counts, two conservative margins
swapped) gives a counterexample that names the claims that fail; the paper-mode and the
conservative unit are proved (full: about 10 and 20 minutes at FP16). The conservative
margins' bit-vector form equals the golden model's on random exponent fields (make test).
"""

from __future__ import annotations

import random

import numpy as np
import pytest
import z3

from amaranth.hdl import Mux

from raplas_hdl.formal.composition import (ComposedUnit, StandIn, contract, margins_z3,
                                           prove_bound_operator, prove_composition)
from raplas_hdl.fp import FP16, FP24
from raplas_hdl.fp.format import parse_format
from raplas_hdl.model.conservative import (MARGIN_NAMES, margin_constants, margin_k,
                                           margin_table)
from raplas_hdl.rtl.certified_bound import BoundOps
from raplas_hdl.rtl.ray_triangle import RayTriangleUnit

#: The smallest format the comparisons' reference takes, with room for the decision.
SMALL = parse_format("e4m3")
#: The smallest the conservative mode takes (8 fraction bits).
SMALL_CONSERVATIVE = parse_format("e4m8")
TIMEOUT = 900
#: The conservative proofs' solver time: 942 s at e4m8 (load 3), 1,203 s at FP16.
CONSERVATIVE_TIMEOUT = 3600


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("composition")


def test_the_stand_ins_keep_the_units_schedule():
    real, composed = RayTriangleUnit(FP16), ComposedUnit(FP16)
    real._MustUse__silence = True            # built for its schedule only
    assert composed.decision_cycle == real.decision_cycle
    assert composed.latency == real.latency
    from amaranth.hdl import Fragment

    Fragment.get(composed, None)
    kinds = [k for _, k, _, _ in composed.ops]
    assert len(kinds) == 33 and kinds.count("mul") == 18 and kinds.count("add") == 15
    assert len({n for n, *_ in composed.ops}) == 33
    assert sum(sub for *_, sub, _ in composed.ops) == 6        # T (3) and Q (3)


def test_a_stand_in_has_its_operations_ports():
    add, mul = StandIn(FP16, 3, "add"), StandIn(FP16, 2, "mul")
    add._MustUse__silence = mul._MustUse__silence = True
    assert {"a", "b", "sub", "i_valid", "en", "o", "flags", "o_valid"} <= set(
        add.signature.members)
    assert "sub" not in mul.signature.members


class SwappedSubtraction(ComposedUnit):
    """T = O - V0 in x: the first subtraction's operands swapped."""

    def _op(self, m, kind, a, b, sub=False):
        if sub and not self.ops:
            a, b = b, a
        return super()._op(m, kind, a, b, sub)


class FlagsLeftOut(ComposedUnit):
    """The last operation's flags never reach the event counts."""

    def _op(self, m, kind, a, b, sub=False):
        out = super()._op(m, kind, a, b, sub)
        if len(self.ops) == 33:
            self._flag_taps.pop()
        return out


# about 35 s each at e4m3; the first runs in make test
@pytest.mark.parametrize("unit_class, fails", [
    (SwappedSubtraction, {"t", "u", "v", "hit"}),
    pytest.param(FlagsLeftOut, {"n_overflow", "n_underflow", "n_invalid"},
                 marks=pytest.mark.full),
])
def test_a_unit_wired_wrong_gives_a_counterexample(unit_class, fails, work):
    res = prove_composition(SMALL, timeout=TIMEOUT, cwd=work, unit_class=unit_class)
    assert res["result"] == "counterexample", res
    assert set(res["differs"]) & fails, res


@pytest.mark.full
def test_the_paper_unit_is_proved(work):
    res = prove_composition(FP16, timeout=TIMEOUT, cwd=work)
    assert res["result"] == "proved", res
    assert res["ops"] == 33


class MarginsSwapped(ComposedUnit):
    """The conservative decision widens u' by v's margin and v' by u's."""

    def _margin_fields(self, m, p):
        mg = super()._margin_fields(m, p)
        mg["u"], mg["v"] = mg["v"], mg["u"]
        return mg


# e4m8: 2 minutes for the counterexample, 16 for the proof (load 3); FP16 about 20 minutes
@pytest.mark.full
def test_a_conservative_unit_with_its_margins_swapped_gives_a_counterexample(work):
    res = prove_composition(SMALL_CONSERVATIVE, mode="conservative", timeout=TIMEOUT,
                            cwd=work, unit_class=MarginsSwapped)
    assert res["result"] == "counterexample", res
    assert res["differs"] == ["hit"], res


@pytest.mark.full
def test_the_conservative_unit_is_proved_at_a_small_format(work):
    res = prove_composition(SMALL_CONSERVATIVE, mode="conservative",
                            timeout=CONSERVATIVE_TIMEOUT, cwd=work)
    assert res["result"] == "proved", res
    assert res["ops"] == 34


@pytest.mark.full
def test_the_conservative_unit_is_proved(work):
    res = prove_composition(FP16, mode="conservative", timeout=CONSERVATIVE_TIMEOUT,
                            cwd=work)
    assert res["result"] == "proved", res


@pytest.mark.parametrize("fmt", [SMALL_CONSERVATIVE, FP16, FP24], ids=str)
def test_the_margins_bit_vector_form_is_the_models(fmt):
    consts = margin_constants(fmt)
    table = margin_table(consts)
    names = ("o", "d", "v0", "e1", "e2", "n")
    var = {k: z3.BitVec(k, fmt.exp_bits) for k in names}
    terms = margins_z3(fmt, consts, var)
    rng = random.Random(23)
    emf = fmt.exp_max_field
    for _ in range(300):
        # the ends of the field's range (zero, the largest finite, all ones) often
        f = {k: rng.choice([0, 1, emf - 1, emf, rng.randrange(emf + 1)]) for k in names}
        want = margin_k(*(f[k] for k in names), table, fmt.exp_bits, fmt.man_bits)
        sub = [(var[k], z3.BitVecVal(f[k], fmt.exp_bits)) for k in names]
        got = [z3.simplify(z3.substitute(terms[k], *sub)).as_long() for k in MARGIN_NAMES]
        assert got == [int(x) for x in want], f


def test_modes_and_the_formats_they_take():
    with pytest.raises(ValueError, match="modes paper, conservative, certified, not 'exact'"):
        prove_composition(FP16, mode="exact")
    with pytest.raises(ValueError, match="exp_bits <= 9"):
        prove_composition(parse_format("e10m5"), mode="certified")
    with pytest.raises(ValueError, match="man_bits >= 8"):
        prove_composition(SMALL, mode="conservative")


def _model_fns(fmt):
    """The golden model's operations as ``contract``'s functions (constants in, constants
    out)."""
    from raplas_hdl.fp.kernels import rmode_code
    from raplas_hdl.model.pair_kernels import add_op, mul_op, sub_op

    e, m, r = fmt.exp_bits, fmt.man_bits, rmode_code(fmt)

    def kind(op):
        def run(a, b):
            return op(z3.simplify(a).as_long(), z3.simplify(b).as_long(), e, m, r)
        return (lambda a, b: z3.BitVecVal(int(run(a, b)[0]), fmt.width),
                lambda a, b: z3.BitVecVal(int(run(a, b)[1]), 3))

    return {"mul": kind(mul_op), "add": kind(add_op), "sub": kind(sub_op)}


@pytest.mark.parametrize("fmt", [FP16, FP16.with_rounding("rne"), FP24.with_rounding("chop")],
                         ids=lambda f: f.name)
def test_the_certified_reference_is_the_models(fmt):
    """The certified composition's reference (bounds in z3's FloatingPoint theory, rounded
    up) folded on the golden model's operations: its outcome and tight bit are the model's
    (``intersect`` in certified mode and ``tight_flags``: float64 bounds, variant exp) on
    stress pairs of every family, hits, misses and uncertain pairs among them."""
    from raplas_hdl.model import stress_cases
    from raplas_hdl.model.ordering import tight_flags
    from raplas_hdl.model.ray_triangle import intersect
    from raplas_hdl.verify import stress

    enc = stress.reference(stress_cases.generate(fmt, 4, 5), fmt)
    k = enc.kept
    arrs = (enc.o_bits[k], enc.d_bits[k], enc.v0_bits, enc.e1_bits, enc.e2_bits, enc.n_bits)
    want = intersect(*arrs, fmt, mode="certified", bound_variant="exp")
    tight = tight_flags(arrs, want["outcome"], fmt, 1.0, "exp")
    assert set(np.unique(want["outcome"])) == {0, 1, 2}
    fns = _model_fns(fmt)
    for i in range(len(k)):
        pay = {name: [z3.BitVecVal(int(a[i, c]), fmt.width) for c in range(3)]
               for name, a in zip(("o", "d", "v0", "e1", "e2", "n"), arrs)}
        _, _, (outcome, tgt) = contract(fmt, pay, fns, "certified")
        got = (z3.simplify(outcome).as_long(), z3.is_true(z3.simplify(tgt)))
        assert got == (int(want["outcome"][i]), bool(tight[i])), i


@pytest.mark.parametrize("fmt", [FP16, FP24], ids=lambda f: f.name)
@pytest.mark.parametrize("kind", ["add", "mul"])
def test_the_bound_operators_round_up_as_the_model(kind, fmt, work):
    """The certified unit's two-stage bound operators equal the model's rounded-up sum and
    product of their operands' values, for every pair (a second or so each)."""
    res = prove_bound_operator(fmt, kind, cwd=work, timeout=TIMEOUT)
    assert res["result"] == "proved", res


class _MulRoundsDown(BoundOps):
    """A bound product that truncates instead of rounding up."""

    def mul_round(self, m, x):
        k = self.k
        big = x.p[2 * k + 1]
        mant = Mux(big, x.p[k + 1:], x.p[k:2 * k + 1])
        return self._new(m, "mul", x.z, self._bump(m, x, big, 0), mant[:k])


def test_a_bound_product_rounded_down_gives_a_counterexample(work):
    res = prove_bound_operator(FP24, "mul", cwd=work, timeout=TIMEOUT, ops_class=_MulRoundsDown)
    assert res["result"] == "counterexample", res


class BoundOfTheWrongFactor(ComposedUnit):
    """Certified: the bound of a product with an exact factor takes ``U`` of the factor
    whose bound it is, not of the exact one (``U(x) B_x`` for ``U(y) B_x``)."""

    def _bound_mul(self, m, x, bx, y, by, p):
        if by is not None:
            return super()._bound_mul(m, x, bx, y, by, p)
        acc = self._bop(m, "mul", self._upper(m, x), bx)
        return self._bop(m, "add", acc, self._breg(m, self._bo.rnd_mul(m, p.value), p.time))


# e4m3 (full): the bound operators' lemmas first, then three solver calls
@pytest.mark.full
def test_a_certified_unit_with_a_bound_of_the_wrong_factor_gives_a_counterexample(work):
    res = prove_composition(SMALL, mode="certified", timeout=CONSERVATIVE_TIMEOUT, cwd=work,
                            unit_class=BoundOfTheWrongFactor)
    assert res["result"] == "counterexample", res
    assert "bound_args" in res["differs"], res


@pytest.mark.full
def test_the_certified_unit_is_proved_at_a_small_format(work):
    res = prove_composition(SMALL, mode="certified", timeout=CONSERVATIVE_TIMEOUT, cwd=work)
    assert res["result"] == "proved", res
    assert (res["ops"], res["bound_ops"]) == (34, 92)
    assert [st["result"] for st in res["steps"]] == ["proved"] * 5
