"""The ray-triangle unit proved by composition (``raplas_hdl.formal.composition``).

The stand-in build keeps the real unit's schedule; a unit wired wrong (operands of an
operation swapped, an operation's flags left out of the counts, two conservative margins
swapped) gives a counterexample that names the claims that fail; the paper-mode and the
conservative unit are proved (full: about 10 and 20 minutes at FP16). The conservative
margins' bit-vector form equals the golden model's on random exponent fields (make test).
"""

from __future__ import annotations

import random

import pytest
import z3

from raplas_hdl.formal.composition import (ComposedUnit, StandIn, margins_z3,
                                           prove_composition)
from raplas_hdl.fp import FP16, FP24
from raplas_hdl.fp.format import parse_format
from raplas_hdl.model.conservative import (MARGIN_NAMES, margin_constants, margin_k,
                                           margin_table)
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


def test_the_certified_mode_is_not_stated_and_the_conservative_needs_8_fraction_bits():
    with pytest.raises(ValueError, match="paper and conservative modes"):
        prove_composition(FP16, mode="certified")
    with pytest.raises(ValueError, match="man_bits >= 8"):
        prove_composition(SMALL, mode="conservative")
