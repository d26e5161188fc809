# amaranth: UnusedElaboratable=no
"""The certified mode of RayTriangleUnit as Verilog in Icarus and Verilator against the
golden model (:func:`raplas_hdl.model.ray_triangle.intersect` with ``mode="certified",
bound_variant="exp"``), every output bit: the outcome (0 miss, 1 hit, 2 uncertain), hit,
t', u', v', det, flags, the per-pair event counts and the IDs, in order.

It runs through the batch harness of ``raplas-hdl cosim ray-triangle --mode certified``
(:class:`raplas_hdl.sim.cosim.RayTriangleCosim`: random gaps in ``i.valid`` and
back-pressure on ``o.ready``). The pairs: every stress family (edge, vertex, grazing,
flush, ... with special patterns mixed in, :func:`raplas_hdl.model.stress_cases.vectors`), the
pairs with known event counts and uniformly random patterns. ``make test`` runs FP24 rtz
under Icarus and FP24 chop under Verilator (one build each); the ``full`` runs cover FP16,
FP20 and FP24 in all three roundings under both simulators with more pairs.
"""

import numpy as np
import pytest
from amaranth.hdl import Fragment

from raplas_hdl.fp import FP16, FP20, FP24, FPFormat
from raplas_hdl.model.ray_triangle import intersect
from raplas_hdl.model.stress_cases import vectors
from raplas_hdl.rtl.ray_triangle import RayTriangleUnit
from raplas_hdl.sim.cosim import RayTriangleCosim, compare
from tests.support.ray_triangle import NAMES, event_pairs


def certified_pairs(fmt, count, seed):
    """Stress-family vectors, the event-count pairs and uniformly random patterns."""
    vec = vectors(fmt, count, seed)
    ev, _ = event_pairs(fmt)
    rng = np.random.default_rng([seed, 13])
    rand = rng.integers(0, 1 << fmt.width, (6, max(8, count // 10), 3), dtype=np.uint32)
    return {k: np.concatenate([vec[k], ev[i], rand[i]]) for i, k in enumerate(NAMES)}


def cosim(simulator, fmt, count, seed):
    """Every output bit of the RTL against the model; returns the model's outcomes."""
    unit = RayTriangleCosim(fmt, {"mode": "certified"})
    vec = certified_pairs(fmt, count, seed)
    n = len(vec["o"])
    rng = np.random.default_rng(seed)
    cases = {"ray_id": rng.integers(0, 1 << 16, n).astype(np.uint64),
             "tri_id": rng.integers(0, 1 << 16, n).astype(np.uint64)}
    for k, v in vec.items():
        for j, p in enumerate("xyz"):
            cases[f"{k}.{p}"] = v[:, j].astype(np.uint64)
    exp = unit.expected(cases)
    got, info = unit.simulate(cases, simulator, valid_density=0.8, stall_density=0.3,
                              seed=seed)
    assert "outcome" in unit.compared and "tight" in unit.compared
    bad = compare(exp, got, unit.compared)
    assert len(bad) == 0, f"{len(bad)} of {n} pairs differ, first:\n" + "\n".join(
        unit.show(cases, exp, got, int(bad[0])))
    # the vectors reach all three outcomes, and the outcome bits are not the other
    # variant's (the comparison can fail)
    assert set(np.unique(exp["outcome"]).tolist()) == {0, 1, 2}
    # and the certain hits are both tight and loose (model/ordering.py), no other pair tight
    hits = exp["outcome"] == 1
    assert exp["tight"][hits].any() and not exp["tight"][hits].all()
    assert not exp["tight"][~hits].any()
    other = intersect(*(vec[k] for k in NAMES), fmt, mode="certified", bound_variant="lead3")
    assert (other["outcome"] != exp["outcome"]).any()
    return exp


@pytest.mark.parametrize("simulator, rounding, count", [("icarus", "rtz", 1500),
                                                        ("verilator", "chop", 3000)])
def test_certified_cosim(simulator, rounding, count):
    cosim(simulator, FP24.with_rounding(rounding), count, 21 + len(rounding))


@pytest.mark.full
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
@pytest.mark.parametrize("fmt", [FP16, FP20, FP24], ids=lambda f: f.name)
@pytest.mark.parametrize("rounding", ["rtz", "rne", "chop"])
def test_certified_cosim_full(simulator, fmt, rounding):
    count = 20000 if simulator == "icarus" else 100000
    cosim(simulator, fmt.with_rounding(rounding), count, 5 + fmt.width + len(rounding))


def test_certified_latency_and_schedule():
    unit = RayTriangleUnit(FP24, mode="certified")
    Fragment.get(unit, None)            # elaborates: every result and bound before the decision
    assert unit.decision_cycle > 6 * 4 + 2 * 3          # the bounds end after w
    assert unit.latency == unit.decision_cycle + 3
    assert unit.bound_variant == "exp"


@pytest.mark.parametrize("fmt, kwargs, word", [
    (FP24, {"bound_variant": "lead6"}, "bound variant"),
    (FP24, {"margin_scale": 0.5}, "margin_scale"),
    (FPFormat(10, 13), {}, "exp_bits"),
])
def test_certified_bad_parameters(fmt, kwargs, word):
    with pytest.raises(ValueError, match=word):
        RayTriangleUnit(fmt, mode="certified", **kwargs)


def test_intersection_unit_certified_carries_outcome():
    """The certified intersection unit (tests/rtl/test_certified_unit.py) puts the outcome on
    its result stream."""
    from raplas_hdl.rtl.intersection import IntersectionUnit

    unit = IntersectionUnit(mode="certified")
    assert dict(unit.result_layout.members)["outcome"] == 2
