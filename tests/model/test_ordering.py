"""model/ordering.py: the margins that let the certified reduction order certain hits exactly.

- ``near_shift`` is the smallest shift whose margin covers two tight hits' errors;
- ``product_key`` orders as the exact product, and keys that are not ``near`` are further
  apart than that margin (random patterns, exact rationals);
- ``tight_flags`` marks a certain hit tight exactly when its ``t'`` and ``det`` pass the test
  against the unit's own bounds, and only certain hits; hits whose origin is just short of
  the plane (``t'`` small against its bound) are loose.
"""

from fractions import Fraction

import numpy as np
import pytest

from raplas_hdl.fp import FP16, FP24, FP32, FPFormat
from raplas_hdl.fp import model as fpm
from raplas_hdl.fp.kernels import rmode_code
from raplas_hdl.model.certified import certified_constants, intersect_certified, pair_bounds
from raplas_hdl.model.ordering import (key_int, key_lt, near, near_int, near_shift, product_key,
                                      tight_bits, tight_flags)

FORMATS = [FP16, FP24, FP32, FPFormat(6, 8), FPFormat(5, 6)]


def _margin(fmt):
    d = Fraction(1, 2 ** tight_bits(fmt))
    return ((1 + d) / (1 - d)) ** 2


@pytest.mark.parametrize("fmt", FORMATS, ids=str)
def test_near_shift_is_the_smallest_that_covers(fmt):
    s, m = near_shift(fmt), fmt.man_bits
    assert 1 + Fraction(2) ** (s - 2 * m - 2) >= _margin(fmt)
    assert 1 + Fraction(2) ** (s - 1 - 2 * m - 2) < _margin(fmt)


def _patterns(rng, fmt, n):
    v = rng.choice([-1.0, 1.0], n) * np.exp(rng.uniform(-6, 6, n))
    bits = fpm.encode(v, fmt).astype(np.int64)
    bits[rng.random(n) < 0.05] = 0                        # zeros
    return bits


def _exact(fmt, bits):
    return [Fraction(float(x)) for x in fpm.decode(np.asarray(bits, np.uint32), fmt)]


@pytest.mark.parametrize("fmt", [FP16, FP24, FPFormat(6, 8)], ids=str)
def test_keys_order_and_near_margin(fmt):
    rng = np.random.default_rng(7)
    n = 4000
    x, y = _patterns(rng, fmt, n), _patterns(rng, fmt, n)
    # a second product close to the first one: the same y, x a few ulps off (or equal)
    x2 = np.where(rng.random(n) < 0.5, x + rng.integers(-40, 41, n), _patterns(rng, fmt, n))
    x2 = np.where((x2 >> fmt.man_bits) != (x >> fmt.man_bits), x, x2)
    y2 = np.where(rng.random(n) < 0.7, y, _patterns(rng, fmt, n))
    sg = fmt.width - 1
    ka = product_key(fmt, x, y, (x >> sg) ^ (y >> sg))
    kb = product_key(fmt, x2, y2, (x2 >> sg) ^ (y2 >> sg))
    close = near(fmt, ka, kb)
    assert 50 < close.sum() < n - 50
    # the fold's scalar forms are the same functions
    for i in range(0, n, 7):
        a = key_int(fmt, int(x[i]), int(y[i]), int((x[i] >> sg) ^ (y[i] >> sg)))
        b = key_int(fmt, int(x2[i]), int(y2[i]), int((x2[i] >> sg) ^ (y2[i] >> sg)))
        assert a == (ka[0][i], ka[1][i]) and b == (kb[0][i], kb[1][i])
        assert near_int(fmt, a, b) == close[i]
    xa, ya, xb, yb = (_exact(fmt, v) for v in (x, y, x2, y2))
    margin = _margin(fmt)
    for i in range(n):
        pa, pb = xa[i] * ya[i], xb[i] * yb[i]
        # the key orders as the product's value (sign and magnitude)
        lt = key_lt((int(ka[0][i]), int(ka[1][i])), (int(kb[0][i]), int(kb[1][i])))
        assert lt == (pa < pb), i
        if not close[i] and pa != 0 and pb != 0 and (pa > 0) == (pb > 0):
            lo, hi = sorted((abs(pa), abs(pb)))
            assert hi > lo * margin, (i, pa, pb)


def test_tight_flags_follow_the_bounds():
    rng = np.random.default_rng(3)
    for fmt in (FP24, FPFormat(6, 8)):
        n = 3000
        o = rng.uniform(-0.2, 0.2, (n, 3))
        close = rng.random(n) < 0.4             # origins just short of the plane: t' small
        o[close, 2] = 3.0 - np.exp(rng.uniform(-9, -2, close.sum()))
        o = fpm.encode(o, fmt)
        d = fpm.encode(np.tile([0.0, 0.0, 1.0], (n, 1)) + rng.uniform(-0.3, 0.3, (n, 3)), fmt)
        v0 = rng.uniform(-0.1, 0.1, (n, 3)) + [-0.6, -0.6, 3]       # triangles facing the rays
        e1 = rng.uniform(-0.3, 0.3, (n, 3)) + [1.6, 0, 0]
        e2 = rng.uniform(-0.3, 0.3, (n, 3)) + [0, 1.6, 0]
        nn = np.cross(e1, e2)
        arrs = [np.ascontiguousarray(a, np.uint32) for a in
                (o, d, fpm.encode(v0, fmt), fpm.encode(e1, fmt), fpm.encode(e2, fmt),
                 fpm.encode(nn, fmt))]
        cc = certified_constants(fmt, 1.0, "exp")
        res = intersect_certified(arrs, fmt, 1.0, "exp")
        tight = tight_flags(arrs, res["outcome"], fmt, 1.0, "exp")
        hits = res["outcome"] == 1
        assert hits.sum() > 100 and not tight[~hits].any()
        q = tight_bits(fmt)
        e, m, r = fmt.exp_bits, fmt.man_bits, rmode_code(fmt)
        for i in np.flatnonzero(hits)[:400]:
            tp, _, _, det, _, gdet, gt, *_ = pair_bounds(arrs[0], i, arrs[1], i,
                                                         *arrs[2:], i, e, m, r, cc)
            vt, vd = fpm.decode(np.array([tp, det], np.uint32), fmt)
            want = abs(vt) >= gt * 2.0 ** q and abs(vd) >= gdet * 2.0 ** q
            assert bool(tight[i]) == want, i
        assert (hits & ~tight).sum() > 0              # loose hits: t' small, near the plane
        if fmt.man_bits >= 10:                        # elsewhere FP24's hits are tight
            assert tight[hits & ~close].mean() > 0.9
