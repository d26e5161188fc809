"""Proof by test that plane culling never loses a hit (issue 3, point 3).

Over 10,000 random bundles with random sphere sets (radii and distances over several
orders of magnitude; centres near the origin, far away, behind it) plus adversarial
spheres at distance r(1 +- k 2^-M) from a ray or from a plane, at FP24 in all three
roundings: for every ray whose *line* meets its sphere exactly (an exact rational test
on the encoded ray and the encoded sphere), the golden model of the tester must keep the
sphere in both of the ray's planes. The inflation is checked against the closed form,
written out again here from ``docs/plane-culling.md``; culling must still reject a
substantial fraction of (plane, sphere) pairs; and without inflation the adversarial set
must show false rejections (so the test can fail).
"""

from __future__ import annotations

import numpy as np
import pytest

from raplas_hdl.fp import FP24, FPFormat
from raplas_hdl.fp import model as fpm
from raplas_hdl.model.bundles import RayBundle, encode_bundles
# the generators are shared with the stress campaign
from raplas_hdl.verify.campaign import line_gap
from raplas_hdl.verify.campaign import (adversarial_spheres, exact_line_hit, random_bundle,
                                      random_spheres)
from raplas_hdl.host.culling import CullingBudget, bundle_slack, bundle_slacks, encode_spheres
from raplas_hdl.model import plane_sphere as ps_model

O_MAX = 8.0
#: Stated lower bound on the fraction of (plane, sphere) pairs rejected on random sets.
MIN_REJECTED = 0.4


def closed_form(fmt: FPFormat, o_max, margin, r, c_norm):
    """The inflated radius of docs/plane-culling.md, from the format alone (float64, each
    term rounded up by a relative 2^-45 in the end)."""
    u = 2.0 ** -fmt.man_bits
    phi = 2.0 ** (1 - (2 ** (fmt.exp_bits - 1) - 1))
    g3 = 3 * u + 3 * u * u + u ** 3
    nu0 = 1 + 2.0 ** -40
    delta0 = (2 * u + u * u) / (1 - u) * (1 + 2.0 ** -20) + 4 * phi
    b0 = (u + 2.0 ** -50 + delta0 + g3 * (1 + u)) * o_max * nu0 + phi
    value = (nu0 + delta0) * r + (delta0 + g3 * nu0) * c_norm + b0 + 6 * phi + margin
    return value * (1 + 2.0 ** -45)


def check_bundles(fmt, n_bundles, seed, n_random=10, n_adv=6, batch=500):
    """Run the proof over ``n_bundles`` (in batches: the encodings are array calls);
    return the counts."""
    rng = np.random.default_rng(seed)
    budget = CullingBudget(fmt, O_MAX)
    st = dict(bundles=0, pairs_plane=0, rejected=0, rejected_raw=0, line_hits=0, exact_calls=0,
              false_reject=0, false_reject_raw=0, adv_line_hits=0, ray_pairs=0,
              survive=0, survive_raw=0, out_of_budget=0, r_over=0, r_under=0)
    n_s = n_random + n_adv
    for start in range(0, n_bundles, batch):
        bundles = [random_bundle(rng) for _ in range(min(batch, n_bundles - start))]
        spheres = [(random_spheres(rng, b, n_random), adversarial_spheres(rng, b, n_adv, fmt))
                   for b in bundles]
        centres = np.concatenate([np.vstack([c1, c2]) for (c1, _), (c2, _) in spheres])
        radii = np.concatenate([np.concatenate([r1, r2]) for (_, r1), (_, r2) in spheres])
        c_all, r_all, rinf_all, ok = encode_spheres(centres, radii, budget)
        assert ok.all()
        # r' against the closed form written out above.
        c_dec_all, r_dec_all = fpm.decode(c_all, fmt), fpm.decode(r_all, fmt)
        bound = closed_form(fmt, O_MAX, 0.0, r_dec_all, np.linalg.norm(c_dec_all, axis=1))
        rp = fpm.decode(rinf_all, fmt)
        st["r_over"] += int(np.sum(rp > bound * (1 + fmt.ulp)))
        st["r_under"] += int(np.sum(rp < bound * (1 - 2.0 ** -40)))
        enc = encode_bundles(bundles, fmt)
        slacks = bundle_slacks([(n, p, o, d, b.rows, b.cols) for (n, p, o, d), b
                                in zip(enc, bundles)], fmt)
        st["out_of_budget"] += sum(not budget.admits(x) for x in slacks)
        o_all = fpm.decode(np.array([e[2] for e in enc]), fmt)
        d_all = fpm.decode(np.concatenate([e[3] for e in enc]), fmt)
        d_at = 0
        for k, (bundle, (n_enc, p_enc, _, d_enc)) in enumerate(zip(bundles, enc)):
            sl = slice(k * n_s, (k + 1) * n_s)
            c_enc, r_enc, r_inf = c_all[sl], r_all[sl], rinf_all[sl]
            c_dec, r_dec = c_dec_all[sl], r_dec_all[sl]
            o_dec, d_dec = o_all[k], d_all[d_at:d_at + bundle.n_rays]
            d_at += bundle.n_rays
            keep = ps_model.tester_flags(n_enc, p_enc, c_enc, r_inf, fmt)          # (S, P)
            keep_raw = ps_model.tester_flags(n_enc, p_enc, c_enc, r_enc, fmt)      # no inflation
            st["pairs_plane"] += keep[:n_random].size
            st["rejected"] += int(np.sum(~keep[:n_random]))
            st["rejected_raw"] += int(np.sum(~keep_raw[:n_random]))
            row, col = bundle.ray_planes()
            both = keep[:, row] & keep[:, col]                             # (S, rays)
            both_raw = keep_raw[:, row] & keep_raw[:, col]
            gap, scale = line_gap(o_dec, d_dec, c_dec, r_dec)             # (rays, S)
            sure_hit = gap < -1e-9 * scale
            maybe = np.abs(gap) <= 1e-9 * scale
            st["ray_pairs"] += both[:n_random].size
            st["survive"] += int(both[:n_random].sum())
            st["survive_raw"] += int(both_raw[:n_random].sum())
            for kept, key in ((both, "false_reject"), (both_raw, "false_reject_raw")):
                rays_s, sph_s = np.nonzero(~kept.T & (sure_hit | maybe))
                for i, s in zip(rays_s, sph_s):
                    if sure_hit[i, s]:
                        hit = True
                    else:
                        st["exact_calls"] += 1
                        hit = exact_line_hit(o_dec, d_dec[i], c_dec[s], r_dec[s])
                    st[key] += hit
            st["line_hits"] += int(np.sum(sure_hit | maybe))
            st["adv_line_hits"] += int(np.sum((sure_hit | maybe)[:, n_random:]))
            st["bundles"] += 1
    return st


@pytest.mark.parametrize("rounding,n_bundles", [("rtz", 4000), ("rne", 3000), ("chop", 3000)])
def test_culling_never_loses_a_hit(rounding, n_bundles):
    fmt = FP24.with_rounding(rounding)
    st = check_bundles(fmt, n_bundles, seed={"rtz": 1, "rne": 2, "chop": 3}[rounding])
    assert st["out_of_budget"] == 0, "a bundle inside the domain exceeds the slack budget"
    assert st["r_over"] == 0, "r' exceeds the closed form"
    assert st["r_under"] == 0, "r' is below the closed form"
    assert st["line_hits"] > 10_000 and st["adv_line_hits"] > 1_000
    assert st["false_reject"] == 0, f"culling lost hits: {st}"
    rejected = st["rejected"] / st["pairs_plane"]
    assert rejected >= MIN_REJECTED, f"only {rejected:.3f} of (plane, sphere) pairs rejected"
    assert st["false_reject_raw"] > 0, "without inflation the adversarial set lost no hit"
    print(f"\n{fmt}: {st}; rejected {rejected:.3f} (without inflation "
          f"{st['rejected_raw'] / st['pairs_plane']:.3f}); (ray, sphere) pairs surviving "
          f"{st['survive'] / st['ray_pairs']:.3f} (without inflation "
          f"{st['survive_raw'] / st['ray_pairs']:.3f})")


def test_closed_form_matches_module():
    """The module's coefficients are the closed form's (margin and o_max included)."""
    for fmt in (FP24, FPFormat(5, 10), FPFormat(8, 23)):
        budget = CullingBudget(fmt, 3.0, margin=1e-3)
        for r, cn in ((0.0, 0.0), (1.0, 2.0), (1e-6, 1e3)):
            mine = closed_form(fmt, 3.0, 1e-3, r, cn)
            theirs = (budget.coef_r * r + budget.coef_c * cn + budget.const) * (1 + 2.0 ** -46)
            assert theirs <= mine * (1 + 2.0 ** -40) and mine <= theirs * (1 + 2.0 ** -40)


def test_domain_and_errors():
    budget = CullingBudget(FP24, O_MAX)
    big = budget.limit * 2
    c, r, r_inf, ok = encode_spheres(np.array([[0, 0, 0], [big, 0, 0], [0, 0, 0]]),
                                     np.array([1.0, 1.0, np.nan]), budget)
    assert list(ok) == [True, False, False]
    assert r_inf[1] == FP24.inf and r_inf[2] == FP24.inf
    # outside the domain: kept by every plane, whatever the plane says
    n = fpm.encode(np.array([[1.0, 0, 0]]), FP24)
    p = fpm.encode(np.array([-5.0]), FP24)
    assert ps_model.tester_flags(n, p, c, r_inf, FP24)[1:].all()
    with pytest.raises(ValueError, match="o_max"):
        CullingBudget(FP24, -1.0)
    with pytest.raises(ValueError, match="o_max"):
        CullingBudget(FP24, 2.0 ** 70)
    with pytest.raises(ValueError, match="margin"):
        CullingBudget(FP24, 1.0, margin=float("nan"))
    # a bundle beyond o_max is over budget
    far = RayBundle([20.0, 0, 0], [21.0, 0, 0], [0, 0.1, 0], [0, 0, 0.1], 2, 2)
    n, p = far.encode_planes(FP24)
    o, d = far.encode_rays(FP24)
    assert not budget.admits(bundle_slack(n, p, o, d, 2, 2, FP24))


def test_nan_keeps_the_sphere():
    n = fpm.encode(np.array([[1.0, 0, 0]]), FP24)
    p = fpm.encode(np.array([-5.0]), FP24)
    c = np.array([[FP24.nan, 0, 0], [FP24.inf, 0, 0]], np.uint32)
    r = fpm.encode(np.array([1.0, 1.0]), FP24)
    keep = ps_model.tester_flags(n, p, c, r, FP24)
    assert keep[0, 0]                       # NaN distance: kept (fail safe)
    assert not keep[1, 0]                   # infinite distance: rejected
