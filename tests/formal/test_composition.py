"""The ray-triangle unit proved by composition (``raplas_hdl.formal.composition``).

The stand-in build keeps the real unit's schedule; a unit wired wrong (operands of an
operation swapped, an operation's flags left out of the counts) gives a counterexample that
names the claims that fail; the paper-mode unit is proved (full: about 10 minutes at
FP16).
"""

from __future__ import annotations

import pytest

from raplas_hdl.formal.composition import ComposedUnit, StandIn, prove_composition
from raplas_hdl.fp import FP16
from raplas_hdl.fp.format import parse_format
from raplas_hdl.rtl.ray_triangle import RayTriangleUnit

#: The smallest format the comparisons' reference takes, with room for the decision.
SMALL = parse_format("e4m3")
TIMEOUT = 900


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


def test_only_the_paper_mode_is_stated():
    with pytest.raises(ValueError, match="paper mode only"):
        prove_composition(FP16, mode="certified")
