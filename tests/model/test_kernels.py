"""The compiled paths of the unit models give the reference kernels' bits.

- :func:`raplas_hdl.fp.fast.fast_add` / :func:`~raplas_hdl.fp.fast.fast_mul` equal the integer
  kernels wherever they do not return the sentinel (and flag nothing);
- the ray-triangle loop (a block at a time, with its fallbacks) and the reference path alone
  (:func:`pair_exact` on every pair) agree on every output, on vectors full of special
  patterns, in both modes, for several formats and roundings;
- likewise the plane-sphere tester's loop and :func:`plane_exact`.
"""

import numpy as np
import pytest
from numba import njit

from raplas_hdl.fp import model as fpm
from raplas_hdl.fp.fast import fast_add, fast_mul
from raplas_hdl.fp.format import parse_format
from raplas_hdl.fp.kernels import add_int_k, mul_int_k, rmode_code
from raplas_hdl.model import plane_sphere, ray_triangle
from raplas_hdl.model.conservative import margin_constants, margin_table
from raplas_hdl.model.stress_cases import vectors

FORMATS = ["FP24/rtz", "FP24/rne", "FP24/chop", "FP16/rne", "FP32/chop", "e5m10-rtz"]


@njit
def _fast_vs_int(a, b, e, m, r):
    bad = 0
    used = 0
    for i in range(a.size):
        x, y = np.int64(a[i]), np.int64(b[i])
        for op in range(2):
            if op == 0:
                got = fast_add(x, y, e, m, r)
                ref, fl = add_int_k(x, y, e, m, r)
            else:
                got = fast_mul(x, y, e, m, r)
                ref, fl = mul_int_k(x, y, e, m, r)
            if got >= 0:
                used += 1
                bad += (got != ref) | (fl != 0)
    return bad, used


@pytest.mark.parametrize("spec", FORMATS)
def test_fast_ops_equal_integer_kernels(spec):
    fmt = parse_format(spec)
    rng = np.random.default_rng(1)
    n = 200_000
    a = rng.integers(0, fmt.mask + 1, n)
    b = rng.integers(0, fmt.mask + 1, n)
    specials = np.array([0, fmt.sign_bit, fmt.inf, fmt.nan, 1, fmt.min_normal, fmt.max_finite,
                         fmt.one, fmt.one | fmt.sign_bit])
    a[:20_000] = rng.choice(specials, 20_000)
    b[20_000:40_000] = rng.choice(specials, 20_000)
    b[40_000:60_000] = a[40_000:60_000] ^ fmt.sign_bit          # x + (-x)
    b[60_000:80_000] = a[60_000:80_000]                          # x + x, x * x
    bad, used = _fast_vs_int(a, b, fmt.exp_bits, fmt.man_bits, rmode_code(fmt))
    assert bad == 0
    assert used > n                                              # most cases take the fast path


@pytest.mark.parametrize("mode", ["paper", "conservative"])
@pytest.mark.parametrize("spec", FORMATS)
def test_ray_triangle_paths_agree(spec, mode):
    fmt = parse_format(spec)
    assert mode == "paper" or fmt.man_bits >= 8     # every format here has a conservative mode
    v = vectors(fmt, 6000, seed=4, special_rate=0.05, random_rate=0.2)
    arrs = [np.ascontiguousarray(v[k], np.uint32) for k in ("o", "d", "v0", "e1", "e2", "n")]
    n = len(arrs[0])
    cons = mode == "conservative"
    mc = (margin_table(margin_constants(fmt)) if cons else np.zeros((3, 5), np.int64))
    key = (fmt.exp_bits, fmt.man_bits, rmode_code(fmt), cons)

    def outputs():
        return (np.empty(n, bool), *[np.empty(n, np.uint32) for _ in range(4)],
                np.empty((n, 3), np.uint8))

    whole, split = outputs(), outputs()
    ray_triangle.pairs_loop(*arrs, mc, 0, n, *whole, *key)
    for lo in range(0, n, 1000):          # ranges that cut blocks: the same bits
        ray_triangle.pairs_loop(*arrs, mc, lo, min(n, lo + 1000), *split, *key)
    ref = [ray_triangle.pair_exact(*[a for a in arrs[:1]], i, arrs[1], i, *arrs[2:], i, *key,
                                   mc) for i in range(n)]
    ref_hit = np.array([r[0] for r in ref])
    ref_cnt = np.array([[r[5] & 0xFF, (r[5] >> 8) & 0xFF, (r[5] >> 16) & 0xFF] for r in ref])
    for out in (whole, split):
        np.testing.assert_array_equal(out[0], ref_hit)
        for k, name in enumerate(("t", "u", "v", "det"), start=1):
            np.testing.assert_array_equal(out[k], [r[k] for r in ref], err_msg=name)
        np.testing.assert_array_equal(out[5], ref_cnt)
    assert ref_hit.any() and (ref_cnt.sum(axis=1) > 0).any()      # the vectors reach both


@pytest.mark.parametrize("spec", FORMATS[:4])
def test_plane_tester_paths_agree(spec):
    fmt = parse_format(spec)
    rng = np.random.default_rng(2)
    n = fpm.encode(rng.normal(size=(12, 3)), fmt)
    p = fpm.encode(rng.normal(size=12) * 3, fmt)
    n[0, 0] = 0
    p[1] = 0
    c = fpm.encode(rng.normal(size=(500, 3)) * 4, fmt)
    r = fpm.encode(np.abs(rng.normal(size=500)), fmt)
    c[:50] = rng.choice([0, fmt.inf, fmt.nan, 1, fmt.max_finite], (50, 3))
    r[50:80] = rng.choice([0, fmt.inf, fmt.nan], 30)
    shape = (500, 12)
    outs = [(np.empty(shape, np.uint32), np.empty(shape, bool), np.empty(shape, np.uint8))
            for _ in range(2)]
    key = (fmt.exp_bits, fmt.man_bits, rmode_code(fmt))
    plane_sphere._loop(n, p, c, r, 0, 500, *outs[0], *key)
    for lo in range(0, 500, 77):
        plane_sphere._loop(n, p, c, r, lo, min(500, lo + 77), *outs[1], *key)
    for k in range(3):
        np.testing.assert_array_equal(outs[0][k], outs[1][k])
    for s in range(0, 500, 7):
        for j in range(12):
            d, keep, fl = plane_sphere.plane_exact(*n[j], p[j], *c[s], r[s], *key)
            assert (outs[0][0][s, j], outs[0][1][s, j], outs[0][2][s, j]) == (d, keep, fl)
