"""The model at FP24 (and a thin run at E=8/M=23) against the exact oracle, on structured
cases in the style of TestFloat's generators plus seeded random ones."""

import functools

import numpy as np
import pytest

from raplas_hdl.fp import FP24, ROUNDINGS, FPFormat
from raplas_hdl.fp import model
from tests.support import fp_oracle as oracle

N_RANDOM = 60_000


def significands(M):
    """Fraction patterns: zero, all ones, single bits, runs from either end, alternations."""
    full = (1 << M) - 1
    pats = {0, full, full ^ 1, full >> 1, 0x5555_5555 & full, 0xAAAA_AAAA & full}
    for i in range(M):
        pats.add(1 << i)                         # single bits
        pats.add(full ^ (1 << i))                # all ones but one
        pats.add(full >> i << i)                 # run of ones from the top
        pats.add(full >> (M - i))                # run of ones from the bottom
    return sorted(pats)


def exponent_classes(E):
    """Biased exponent fields: zero, the smallest, around the bias, the largest, all ones."""
    top = (1 << E) - 1
    bias = (1 << (E - 1)) - 1
    fields = {0, 1, 2, 3, bias - 2, bias - 1, bias, bias + 1, bias + 2, top - 3, top - 2,
              top - 1, top, bias // 2, bias + bias // 2}
    return sorted(f for f in fields if 0 <= f <= top)


def pack(s, x, f, E, M):
    return (np.asarray(s, np.int64) << (E + M)) | (np.asarray(x, np.int64) << M) \
        | np.asarray(f, np.int64)


@functools.lru_cache(maxsize=None)
def cases(op, E, M, n_random=N_RANDOM, seed=2024):
    """Operand pairs (a, b) as uint32 arrays for ``op`` in format (E, M)."""
    rng = np.random.default_rng([seed, E, M, ["add", "sub", "mul"].index(op)])
    top = (1 << E) - 1
    bias = (1 << (E - 1)) - 1
    full = (1 << M) - 1
    sig = np.array(significands(M), np.int64)
    exps = np.array(exponent_classes(E), np.int64)
    # Every exponent class x every significand pattern x both signs.
    s_, x_, f_ = np.meshgrid([0, 1], exps, sig, indexing="ij")
    pool = pack(s_.ravel(), x_.ravel(), f_.ravel(), E, M)
    specials = np.array([0, 1 << (E + M), 1, full, (1 << (E + M)) | 5,      # zeros, denormals
                         top << M, (top << M) | (1 << (E + M)),           # infinities
                         (top << M) | (1 << (M - 1)), (top << M) | 1,     # NaNs
                         (1 << (E + M)) | (top << M) | full,
                         ((top - 1) << M) | full, 1 << M, bias << M,     # max, min normal, 1
                         (1 << (E + M)) | ((top - 1) << M) | full], np.int64)
    a_parts, b_parts = [], []

    def put(a, b):
        a_parts.append(np.asarray(a, np.int64).ravel())
        b_parts.append(np.asarray(b, np.int64).ravel())

    # Specials against specials and against the structured pool.
    put(*[g.ravel() for g in np.meshgrid(specials, specials)])
    put(np.repeat(specials, 200), rng.choice(pool, specials.size * 200))
    put(rng.choice(pool, specials.size * 200), np.repeat(specials, 200))
    # Pairs from the structured pool.
    n = 20_000
    put(rng.choice(pool, n), rng.choice(pool, n))
    normal_x = rng.integers(1, top, size=n)
    sa = rng.integers(0, 2, n)
    fa = rng.choice(sig, n)
    if op in ("add", "sub"):
        # Alignment shifts 0 .. M+6: just below, at and beyond the guard bits.
        d = rng.integers(0, M + 7, n)
        xb = np.clip(normal_x - d, 1, top - 1)
        flip = rng.integers(0, 2, n)             # same or opposite effective signs
        put(pack(sa, normal_x, fa, E, M),
            pack(sa ^ flip, xb, np.where(rng.random(n) < 0.5, rng.choice(sig, n),
                                         rng.integers(0, full + 1, n)), E, M))
        # Cancellation: b's magnitude within a few ulps of a's, effective subtraction.
        mag = pack(0, normal_x, rng.integers(0, full + 1, n), E, M)
        mag_b = np.clip(mag + rng.integers(-4, 5, n), 1 << M, (top << M) - 1)
        eff_sub = sa ^ (1 if op == "add" else 0)
        put(mag | (sa << (E + M)), mag_b | (eff_sub << (E + M)))
        # Near overflow and near underflow.
        hi = rng.integers(top - 3, top, n)
        lo = rng.integers(1, 4, n)
        xb_hi = np.clip(hi - rng.integers(0, 3, n), 1, top - 1)
        put(pack(sa, hi, rng.choice(sig, n), E, M),
            pack(rng.integers(0, 2, n), xb_hi, rng.choice(sig, n), E, M))
        put(pack(sa, lo, rng.integers(0, full + 1, n), E, M),
            pack(rng.integers(0, 2, n), rng.integers(1, 4, n), rng.integers(0, full + 1, n), E, M))
    else:
        # Products whose exponent lands near emax and emin (overflow/underflow, rne carry).
        target = np.where(rng.random(n) < 0.5, top - 1, 1) + rng.integers(-2, 3, n)
        xa = rng.integers(1, top, n)
        xb = np.clip(target - xa + bias, 1, top - 1)
        put(pack(sa, xa, fa, E, M), pack(rng.integers(0, 2, n), xb, rng.choice(sig, n), E, M))
        # Significands whose product has long runs (rounding ties and carries).
        put(pack(sa, normal_x, rng.choice(sig, n), E, M),
            pack(rng.integers(0, 2, n), np.clip(2 * bias - normal_x + rng.integers(-1, 2, n),
                                                1, top - 1), rng.choice(sig, n), E, M))
    # Seeded random: raw patterns, and patterns with close exponents.
    w = 1 + E + M
    put(rng.integers(0, 1 << w, n_random // 2), rng.integers(0, 1 << w, n_random // 2))
    k = n_random - n_random // 2
    xr = rng.integers(1, top, k)
    put(pack(rng.integers(0, 2, k), xr, rng.integers(0, full + 1, k), E, M),
        pack(rng.integers(0, 2, k), np.clip(xr + rng.integers(-M - 3, M + 4, k), 1, top - 1),
             rng.integers(0, full + 1, k), E, M))
    a = np.concatenate(a_parts).astype(np.uint32)
    b = np.concatenate(b_parts).astype(np.uint32)
    return a, b


def check(op, fmt, min_cases):
    E, M = fmt.exp_bits, fmt.man_bits
    a, b = cases(op, E, M, n_random=max(N_RANDOM * min_cases // 100_000, 1000))
    assert a.size >= min_cases
    bits, flags = getattr(model, op)(a, b, fmt, flags=True)
    exp_bits, exp_flags = oracle.expected_binop(op, a, b, E, M, fmt.rounding)
    bad, text = oracle.mismatches(bits, flags, exp_bits, exp_flags, a, b)
    assert not bad, f"{op}/{fmt}: {len(bad)} of {a.size} cases differ\n{text}"
    # The integer kernels (the only path beyond E=8/M=25) must agree as well.
    code = {"add": 0, "sub": 1, "mul": 2}[op]
    ibits, iflags = model._binary(a, b, fmt, code, True, int_path=True)
    bad, text = oracle.mismatches(ibits, iflags, exp_bits, exp_flags, a, b)
    assert not bad, f"integer {op}/{fmt}: {len(bad)} of {a.size} cases differ\n{text}"
    # Every event class must occur (E=2 products are >= 1 and cannot underflow).
    events = {1, 2, 4} if E > 2 or op != "mul" else {1, 4}
    assert events <= set(np.unique(flags).tolist()), "cases miss an event class"


@pytest.mark.parametrize("rounding", ROUNDINGS)
def test_add(rounding):
    check("add", FP24.with_rounding(rounding), 100_000)


@pytest.mark.parametrize("rounding", ROUNDINGS)
def test_sub(rounding):
    check("sub", FP24.with_rounding(rounding), 100_000)


@pytest.mark.parametrize("rounding", ROUNDINGS)
def test_mul(rounding):
    check("mul", FP24.with_rounding(rounding), 100_000)


@pytest.mark.parametrize("op", ["add", "mul"])
@pytest.mark.parametrize("fmt", [FPFormat(8, 23, "rtz"), FPFormat(8, 23, "chop"),
                                 FPFormat(5, 10, "rne"), FPFormat(2, 29, "rne")],
                         ids=str)
def test_other_formats(op, fmt):
    """Thin runs at the widest formats (32 bits; 30-bit significand products) and FP16."""
    check(op, fmt, 20_000)


def test_cases_cover_alignment_and_cancellation():
    """The structured add cases really do shift past the guard bits and cancel."""
    a, b = cases("add", 7, 16)
    xa = (a.astype(np.int64) >> 16) & 0x7F
    xb = (b.astype(np.int64) >> 16) & 0x7F
    d = np.abs(xa - xb)[(xa > 0) & (xb > 0) & (xa < 127) & (xb < 127)]
    assert set(range(0, 23)) <= set(d.tolist())
    s = model.add(a, b, FP24)
    xs = (s.astype(np.int64) >> 16) & 0x7F
    lost = np.maximum(xa, xb) - xs
    assert (lost[(xs > 0) & (xs < 127)] >= 10).sum() > 100     # deep cancellations
