"""The specialised fast loops of the model equal its generic kernel loops, bit for bit and
flag for flag, on 10^6+ random and special operand pairs per format and rounding.

``model.add``/``sub``/``mul`` take the fast loops for large arrays; the oracle tests check
them there too. This file checks them against the generic loops (``add_k``/``mul_k``)
directly, at FP16, FP24 and FP32 in all three roundings, with and without flags.
"""

import functools

import numpy as np
import pytest

from raplas_hdl.fp import FP16, FP24, FP32, ROUNDINGS, FPFormat
from raplas_hdl.fp import model

FORMATS = {"FP16": (5, 10), "FP24": (7, 16), "FP32": (8, 23)}
N = 1 << 20
OPS = {"add": 0, "sub": 1, "mul": 2}


@functools.lru_cache(maxsize=None)
def operands(E, M):
    """``N`` operand pairs: raw random patterns, close exponents (cancellation, every
    alignment shift), products near overflow and underflow, and specials (zeros, denormal
    patterns, infinities, NaNs, max finite, min normal) against everything."""
    rng = np.random.default_rng([7, E, M])
    w, top, full = 1 + E + M, (1 << E) - 1, (1 << M) - 1
    bias = (1 << (E - 1)) - 1
    q = N // 4
    # Raw random patterns (about 2/2^E of them are specials).
    a1 = rng.integers(0, 1 << w, q)
    b1 = rng.integers(0, 1 << w, q)
    # Close magnitudes: b = a with low bits, exponent and sign perturbed; includes a - a.
    a2 = rng.integers(0, 1 << w, q)
    b2 = a2 ^ rng.integers(0, 1 << (M + 1), q)
    b2 = np.where(rng.random(q) < 0.3, a2 ^ (1 << (E + M)), b2)
    b2 = np.where(rng.random(q) < 0.3, b2 + (rng.integers(-M - 6, M + 7, q) << M), b2)
    b2 &= (1 << w) - 1
    # Exponent sums near the range limits (mul overflow/underflow, add overflow).
    xa = rng.integers(1, top, q)
    target = np.where(rng.random(q) < 0.5, top - 1, 1) + rng.integers(-2, 3, q)
    xb = np.clip(np.where(rng.random(q) < 0.5, target - xa + bias, xa), 1, top - 1)
    a3 = (rng.integers(0, 2, q) << (E + M)) | (xa << M) | rng.integers(0, full + 1, q)
    b3 = (rng.integers(0, 2, q) << (E + M)) | (xb << M) | rng.integers(0, full + 1, q)
    # Specials against random patterns and against each other.
    sp = np.array([0, 1, full, top << M, (top << M) | 1, (top << M) | (1 << (M - 1)),
                   (top << M) | full, ((top - 1) << M) | full, 1 << M, bias << M], np.int64)
    sp = np.concatenate([sp, sp | (1 << (E + M))])
    r = N - 3 * q
    a4 = np.where(rng.random(r) < 0.5, rng.choice(sp, r), rng.integers(0, 1 << w, r))
    b4 = np.where(rng.random(r) < 0.5, rng.choice(sp, r), rng.integers(0, 1 << w, r))
    a = np.concatenate([a1, a2, a3, a4]).astype(np.uint32)
    b = np.concatenate([b1, b2, b3, b4]).astype(np.uint32)
    return a, b


@pytest.mark.parametrize("rounding", ROUNDINGS)
@pytest.mark.parametrize("name", list(FORMATS))
def test_fast_equals_generic(name, rounding):
    fmt = FPFormat(*FORMATS[name], rounding)
    a, b = operands(*FORMATS[name])
    assert a.size >= 10**6
    for op, code in OPS.items():
        gbits, gflags = model._binary(a, b, fmt, code, True, path="generic")
        fbits, fflags = model._binary(a, b, fmt, code, True, path="fast")
        diff = np.nonzero((fbits != gbits) | (fflags != gflags))[0]
        assert diff.size == 0, (
            f"{op}/{fmt}: {diff.size} differ, first a={a[diff[0]]:#x} b={b[diff[0]]:#x} "
            f"fast {fbits[diff[0]]:#x}/{fflags[diff[0]]} "
            f"generic {gbits[diff[0]]:#x}/{gflags[diff[0]]}")
        nbits = model._binary(a, b, fmt, code, False, path="fast")
        assert np.array_equal(nbits, gbits), f"{op}/{fmt} without flags differs"
        # The public API takes the fast loop at this size.
        assert np.array_equal(getattr(model, op)(a, b, fmt), gbits)
        # The cases reach both passes: common elements and every event class.
        assert {0, 1, 2, 4} <= set(np.unique(gflags).tolist()), f"{op}/{fmt} misses events"


def test_fast_path_edges():
    """Wide patterns raise, broadcasting and odd sizes (thread split, partial blocks) work."""
    fmt = FPFormat(7, 16, "rne")
    a, b = operands(7, 16)
    n = model._FAST_MIN + 12345
    bits = model._binary(a[:n], b[:n], fmt, 2, False, path="fast")
    assert np.array_equal(bits, model._binary(a[:n], b[:n], fmt, 2, False, path="generic"))
    one = np.uint32(fmt.one)
    assert np.array_equal(model.mul(a[:n], one, fmt),
                          model._binary(a[:n], one, fmt, 2, False, path="generic"))
    wide = a[:n].copy()
    wide[n - 1] = 1 << 24
    with pytest.raises(ValueError, match="1 patterns wider"):
        model.add(wide, b[:n], fmt)
    with pytest.raises(ValueError, match="path must be"):
        model._binary(a[:4], b[:4], fmt, 0, False, path="fastest")


@pytest.mark.parametrize("fmt", [FP16, FP24, FP32])
@pytest.mark.parametrize("rounding", ["rtz", "rne", "chop"])
def test_nan_operand_raises_no_flag_in_small_arrays(fmt, rounding):
    """Regression: chop's alignment once shifted by a NaN's exponent and raised overflow.

    Small arrays take the per-element kernels (not the blocked fast path), so this checks
    ``add_k``/``sub_k`` as other models inline them.
    """
    fmt = fmt.with_rounding(rounding)
    rng = np.random.default_rng(7)
    a = rng.integers(0, fmt.inf, 4000, dtype=np.int64).astype(np.uint32)
    a |= rng.integers(0, 2, a.size, dtype=np.int64).astype(np.uint32) << (fmt.width - 1)
    if fmt.exp_bits == 8:
        a[0] = 0x4D31D7A6      # the pattern that exposed the bug (FP32 chop)
    nan = np.full_like(a, fmt.nan)
    for op in (model.add, model.sub):
        for x, y in ((a, nan), (nan, a)):
            bits, flags = op(x, y, fmt, flags=True)
            assert np.all(bits == fmt.nan)
            assert np.all(flags == 0), f"{op.__name__} {fmt}: flags {np.unique(flags)}"
