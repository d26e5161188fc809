"""The conservative mode: its derivation, its error bounds against R, and the stress subset.

The constants are recomputed here from the steps of the derivation (module docstring of
:mod:`raplas_hdl.model.conservative`), not copied from a run. The margins must bound the
actual difference between every computed quantity (det, t', u', v', w) and R's exact
value on every in-domain stress pair; then the decision cannot miss what R hits. The
stress subset asserts zero false misses and zero leaks in conservative mode and that the
paper's exact-inequality mode does leak on the same cases.
"""

from fractions import Fraction

import numpy as np
import pytest

from raplas_hdl.fp import FP24, FP32
from raplas_hdl.fp import model as fpm
from raplas_hdl.verify import stress
from raplas_hdl.host.exact import exact_intersect_bits
from raplas_hdl.model import conservative as cons
from raplas_hdl.model import stress_cases
from raplas_hdl.model.ray_triangle import intersect

FORMATS = [FP24, FP24.with_rounding("rne"), FP24.with_rounding("chop"), FP32]
PER_FAMILY = 120


def derived_constants():
    """The closed-form constants, step by step (units: eps times the magnitude bounds)."""
    dot = 3 * 3              # 3 eps per dot product times 3 terms of at most (max * max)
    d_t = 1 + 2              # V0 encoded (eps v) + the sub (eps (v + o)), in eps vo
    t_mag, q_mag = 2, 4      # |T| <= 2 vo, |Q| <= 2 d |T|
    c_det = 3 + dot                                   # N encoded + rounding
    c_t = 3 * t_mag + 3 * d_t + dot * t_mag           # N encoded, T error, rounding
    c_q = 2 * d_t + 2 * (2 * t_mag)                  # T error; 2 mul + 1 sub on 2 terms
    c_u = 3 * c_q + 3 * q_mag + dot * q_mag           # Q error, E2 encoded, rounding
    c_s = 2 * (c_u + 3 * q_mag)                       # u' + v' errors + the add, e1+e2 <= 2 e12
    c_w = (c_det + 3) + c_s + 2 * 3 * q_mag           # det + |det|, s + |s| (<= 24 d vo e12)
    return {"det": c_det, "t": c_t, "q": c_q, "u": c_u, "s": c_s, "w": c_w}


def test_constants_follow_the_derivation():
    c = derived_constants()
    assert c["q"] == 14 and c["s"] == 204
    assert (cons.C_DET, cons.C_T, cons.C_UV, cons.C_W) == (c["det"], c["t"], c["u"], c["w"])


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("scale", [1.0, 0.3])
def test_margin_constants_round_up(fmt, scale):
    k = cons.margin_constants(fmt, scale)
    eps = Fraction(1, 1 << fmt.man_bits)
    g = cons.GUARD_EXP
    for name, c in k.coeff.items():
        exact = Fraction(scale) * cons.SAFETY * c * eps * (1 + Fraction(1, 1 << g))
        got = Fraction(float(fpm.decode(np.uint32(k.k_bits[name]), fmt)))
        assert exact <= got < exact * (1 + 2 * eps)
    # the flush floor: C eps 2**(floor - g) covers the absolute flush errors in the domain
    eta = Fraction(2) ** fmt.emin
    p2 = Fraction(2) ** cons.domain(fmt).pos_exp
    flush_uv = (3 * 7 * 2 * p2 + 3 * 4 * p2 + 5) * eta
    assert cons.C_UV * eps * Fraction(2) ** (k.floor["u"] - g) >= flush_uv
    assert cons.C_DET * eps * Fraction(2) ** (k.floor["det"] - g) >= 8 * eta


@pytest.fixture(scope="module", params=FORMATS, ids=lambda f: f.name)
def suite(request):
    fmt = request.param
    cases = stress_cases.generate(fmt, PER_FAMILY, seed=7)
    return fmt, cases, stress.reference(cases, fmt)


def test_margins_bound_every_error_against_r(suite):
    fmt, cases, enc = suite
    k = enc.kept
    ok = enc.in_domain[k]
    args = (enc.o_bits[k], enc.d_bits[k], enc.v0_bits, enc.e1_bits, enc.e2_bits, enc.n_bits)
    unit = intersect(*args, fmt, mode="conservative")
    w = fpm.sub(unit["det"], fpm.add(unit["u"], unit["v"], fmt), fmt)
    r = exact_intersect_bits(enc.o_bits[k], enc.d_bits[k], cases.v0[k], cases.v1[k],
                             cases.v2[k], fmt, values=True)
    mg = cons.margins(*args, fmt)
    worst = 0.0
    for q, rq, mq in (("det", "det", "det"), ("t", "tp", "t"), ("u", "up", "u"),
                      ("v", "vp", "v"), (None, "wp", "w")):
        val = fpm.decode(w if q is None else unit[q], fmt)[ok]
        err = np.abs(val - r[rq][ok])
        bound = fpm.decode(mg[mq], fmt)[ok]
        assert np.isfinite(val).all()
        assert (err <= bound * (1 + 2.0 ** -40)).all(), \
            f"{mq}: error exceeds the margin on {int((err > bound).sum())} pairs"
        worst = max(worst, float((err / bound).max()))
    assert worst > 0


def test_conservative_mode_never_misses_and_never_leaks(suite):
    fmt, cases, enc = suite
    table = stress.evaluate(cases, enc, "conservative")
    tot = stress.pooled(table)
    assert tot["false_misses"] == 0
    assert tot["leaks"] == 0
    assert tot["edge_rays"] >= PER_FAMILY
    # it does not accept everything: most R-misses of the random family stay misses
    row = table["random"]
    assert row["false_hits"] < 0.75 * (row["pairs"] - row["unguaranteed"] - row["r_hits"])


def test_paper_mode_leaks(suite):
    fmt, cases, enc = suite
    tot = stress.pooled(stress.evaluate(cases, enc, "paper"))
    assert tot["leaks"] > 0
    assert tot["false_misses"] > 0
