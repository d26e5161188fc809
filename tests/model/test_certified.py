"""The certified mode of the ray-triangle model: every hit is an R hit, every miss an R miss
(raplas_hdl/model/certified.py, docs/certified-mode.md)."""

import numpy as np
import pytest

from raplas_hdl.fp.format import FPFormat
from raplas_hdl.model import certified, stress_cases
from raplas_hdl.model.modes import MODES
from raplas_hdl.model.ray_triangle import intersect
from raplas_hdl.verify import stress


def _run(fmt, per_family, seed, scale=1.0, variant=certified.DEFAULT_VARIANT):
    cases = stress_cases.generate(fmt, per_family, seed)
    enc = stress.reference(cases, fmt)
    k = enc.kept
    res = intersect(enc.o_bits[k], enc.d_bits[k], enc.v0_bits, enc.e1_bits, enc.e2_bits,
                    enc.n_bits, fmt, mode="certified", margin_scale=scale,
                    bound_variant=variant)
    return cases, enc, res


def test_mode_listed():
    assert "certified" in MODES


@pytest.mark.parametrize("fmt", [FPFormat(7, 16, "rtz"), FPFormat(7, 16, "rne"),
                                 FPFormat(7, 16, "chop"), FPFormat(5, 10, "rtz")],
                         ids=lambda f: f.name)
@pytest.mark.parametrize("variant", sorted(certified.VARIANTS))
def test_outcome_agrees_with_r(fmt, variant):
    cases, enc, res = _run(fmt, 120, 11, variant=variant)
    oc = res["outcome"]
    rh = enc.r_hit[enc.kept]
    assert set(np.unique(oc)) <= {0, 1, 2}
    assert not ((oc == 1) & ~rh).any()
    assert not ((oc == 0) & rh).any()
    assert np.array_equal(res["hit"], oc == 1)
    # a unit that calls everything uncertain must not pass: the random family decides
    # (FP16 has 10 fraction bits: many of its pairs are within its error of a boundary)
    rnd = cases.family[enc.kept] == stress_cases.FAMILIES.index("random")
    assert (oc[rnd] == 2).mean() < (0.15 if fmt.man_bits >= 16 else 0.75)


def test_same_results_as_paper_mode():
    fmt = FPFormat(7, 16, "rtz")
    cases, enc, res = _run(fmt, 40, 3)
    k = enc.kept
    ref = intersect(enc.o_bits[k], enc.d_bits[k], enc.v0_bits, enc.e1_bits, enc.e2_bits,
                    enc.n_bits, fmt, mode="paper")
    for key in ("t", "u", "v", "det"):
        assert np.array_equal(res[key], ref[key])


def test_domain_and_constants():
    assert certified.certified_domain(FPFormat(7, 16)) == 2.0 ** 30
    assert certified.certified_domain(FPFormat(5, 10)) == 2.0 ** 6
    cc = certified.certified_constants(FPFormat(7, 16), 0.5, "exp")
    assert list(cc) == [0.5, 0, 3]
    with pytest.raises(ValueError, match="exp_bits <= 9"):
        certified.certified_domain(FPFormat(11, 20))
    with pytest.raises(ValueError, match="bound variant"):
        certified.certified_constants(FPFormat(7, 16), 1.0, "nope")
    with pytest.raises(ValueError, match="scale"):
        certified.certified_constants(FPFormat(7, 16), 0.0)
    with pytest.raises(ValueError, match="certified mode only"):
        intersect(np.zeros((1, 3), np.uint32), *[np.zeros((1, 3), np.uint32)] * 5,
                  FPFormat(7, 16), bound_variant="exp")


def test_special_values_are_uncertain():
    """NaN, infinite and overflowing pairs (random and special patterns) are never decided;
    the pair function called from compiled code gives intersect's results."""
    from numba import njit

    from raplas_hdl.fp.kernels import rmode_code

    fmt = FPFormat(7, 16, "rne")
    vec = stress_cases.vectors(fmt, 3000, seed=4, special_rate=0.05, random_rate=0.2)
    arrs = [vec[k] for k in ("o", "d", "v0", "e1", "e2", "n")]
    res = intersect(*arrs, fmt, mode="certified")
    bad = (res["flags"] & 5) != 0                   # overflow or invalid
    assert bad.sum() > 100
    assert (res["outcome"][bad] == 2).all()
    cc = certified.certified_constants(fmt)

    @njit
    def run(o, d, v0, e1, e2, nn, cc, e, m, r):
        out = np.empty((o.shape[0], 3), np.int64)
        for i in range(o.shape[0]):
            oc, tp, det, cnt = certified.pair_certified(o, i, d, i, v0, e1, e2, nn, i, e, m,
                                                        r, cc)
            out[i, 0], out[i, 1], out[i, 2] = oc, tp, det
        return out

    got = run(*arrs, cc, fmt.exp_bits, fmt.man_bits, rmode_code(fmt))
    assert np.array_equal(got[:, 0], res["outcome"])
    assert np.array_equal(got[:, 1], res["t"]) and np.array_equal(got[:, 2], res["det"])


def test_scale_only_shrinks_the_decided_set():
    fmt = FPFormat(7, 16, "rtz")
    _, enc, full = _run(fmt, 60, 8)
    _, _, half = _run(fmt, 60, 8, scale=0.5)
    # a smaller bound decides at least every pair the full bound decides, the same way
    decided = full["outcome"] != 2
    assert np.array_equal(half["outcome"][decided], full["outcome"][decided])
    assert (half["outcome"] != 2).sum() >= decided.sum()


def test_rtl_mode_check():
    from raplas_hdl.model.modes import RTL_MODES, check_rtl_mode

    assert check_rtl_mode("conservative") == "conservative"
    assert check_rtl_mode("certified") == "certified"
    assert set(RTL_MODES) == {"paper", "conservative", "certified"}
    with pytest.raises(ValueError, match="mode must be one of"):
        check_rtl_mode("bogus")
