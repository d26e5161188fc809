"""encode/decode against the exact oracle (all roundings and both directions, with event
flags), the comparison and API details: broadcasting, scalars, errors."""

import numpy as np
import pytest

from raplas_hdl.fp import FP24, FPFormat
from raplas_hdl.fp import model
from tests.support import fp_oracle as oracle

MODES = [("rtz", None), ("rne", None), ("chop", None), ("rtz", "up"), ("rne", "down")]
FORMATS = [FPFormat(4, 3), FP24, FPFormat(11, 20), FPFormat(2, 5)]


def encode_inputs(fmt, n_random=20_000, seed=7):
    """Float64 values that probe every rounding decision of ``fmt``."""
    rng = np.random.default_rng([seed, fmt.exp_bits, fmt.man_bits])
    if fmt.width <= 12:
        pats = np.arange(1 << fmt.width, dtype=np.uint32)
    else:
        pats = rng.integers(0, 1 << fmt.width, 4000).astype(np.uint32)
        pats = np.concatenate([pats, np.array([fmt.max_finite, fmt.min_normal, fmt.one,
                                               fmt.max_finite - 1, fmt.min_normal + 1],
                                              np.uint32)])
    v = model.decode(pats, fmt)
    v = v[np.isfinite(v)]
    v = np.concatenate([v, -v])
    half_ulp = np.abs(v) * 2.0 ** (-fmt.man_bits - 1)
    mid = np.concatenate([v + half_ulp, v - half_ulp / 2])       # ties and just below
    near = np.concatenate([np.nextafter(v, np.inf), np.nextafter(v, -np.inf),
                           np.nextafter(mid, np.inf), np.nextafter(mid, -np.inf)])
    big, tiny = fmt.max_value, fmt.min_value
    edges = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, big, big * (1 + 2.0 ** -60),
                      big + big * 2.0 ** (-fmt.man_bits - 2), 2 * big, 1e308, 5e-324,
                      2.2250738585072009e-308, 2.2250738585072014e-308, tiny, tiny / 2,
                      tiny * (1 - 2.0 ** (-fmt.man_bits - 2)), tiny * (1 - 2.0 ** -52),
                      tiny * (1 - 2.0 ** (-fmt.man_bits - 1))])
    edges = np.concatenate([edges, -edges])
    lo, hi = np.log2(tiny) - 4, min(np.log2(big) + 4, 1023)
    rand = np.ldexp(rng.uniform(0.5, 1, n_random), rng.integers(int(lo), int(hi), n_random))
    rand *= rng.choice([-1.0, 1.0], n_random)
    raw = rng.integers(0, 1 << 63, n_random // 4, dtype=np.int64).view(np.float64)
    return np.concatenate([v, mid, near, edges, rand, raw])


@pytest.mark.parametrize("rounding, direction", MODES)
@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f.name[:-4])
def test_encode(fmt, rounding, direction):
    fmt = fmt.with_rounding(rounding)
    x = encode_inputs(fmt)
    bits, flags = model.encode(x, fmt, direction, flags=True)
    mode = direction or rounding
    exp = [oracle.encode(float(v), fmt.exp_bits, fmt.man_bits, mode) for v in x]
    bad, text = oracle.mismatches(bits, flags, [e[0] for e in exp], [e[1] for e in exp],
                                  x.view(np.int64))
    assert not bad, f"encode {fmt} {direction}: {len(bad)} of {x.size} differ\n{text}"
    # A finite float64 overflows E=11 only when rounding up past the largest binade.
    events = {0, 2} | ({1} if fmt.exp_bits < 11 or mode in ("rne", "up") else set())
    assert events <= set(np.unique(flags).tolist())


def test_encode_direction_rules():
    """The contract's words, spelled out on FP24."""
    f = FP24
    big, tiny = f.max_value, f.min_value
    sign = f.sign_bit
    assert model.encode(2 * big, f, "up") == f.inf
    assert model.encode(2 * big, f, "down") == f.max_finite
    assert model.encode(-2 * big, f, "down") == f.inf | sign
    assert model.encode(-2 * big, f, "up") == f.max_finite | sign
    assert model.encode(2 * big, f.with_rounding("rne")) == f.inf
    assert model.encode(2 * big, f.with_rounding("chop")) == f.max_finite
    assert model.encode(tiny / 3, f, "up") == f.min_normal
    assert model.encode(tiny / 3, f, "down") == 0
    assert model.encode(-tiny / 3, f, "down") == f.min_normal | sign
    assert model.encode(-tiny / 3, f, "up") == sign
    assert model.encode(np.nan, f) == f.nan
    assert model.encode(1 + 2.0 ** -20, f, "up") == f.one + 1
    assert model.encode(1 + 2.0 ** -20, f, "down") == f.one
    assert model.encode(-(1 + 2.0 ** -20), f, "up") == f.one | sign


@pytest.mark.parametrize("fmt", [FPFormat(4, 3), FP24, FPFormat(8, 23), FPFormat(11, 20)],
                         ids=str)
def test_decode_and_round_trip(fmt):
    rng = np.random.default_rng(3)
    pats = rng.integers(0, 1 << fmt.width, 30_000).astype(np.uint32)
    got = model.decode(pats, fmt)
    exp = np.array([oracle.decode(int(p), fmt.exp_bits, fmt.man_bits) for p in pats])
    assert np.array_equal(got, exp, equal_nan=True)
    assert np.array_equal(np.signbit(got), np.signbit(exp))
    # Exact: encoding the decoded value gives the pattern back (denormals as zeros).
    exp_field = (pats >> fmt.man_bits) & fmt.exp_max_field
    ok = (exp_field != fmt.exp_max_field) | ((pats & fmt.man_mask) == 0)
    canon = np.where(exp_field == 0, pats & fmt.sign_bit, pats)[ok]
    for d in (None, "up", "down"):
        assert np.array_equal(model.encode(got[ok], fmt, d), canon)


def test_compare_fp24_cases():
    f = FP24
    rng = np.random.default_rng(5)
    vals = np.concatenate([rng.integers(0, 1 << 24, 3000),
                           [0, f.sign_bit, 1, f.sign_bit | 7, f.inf, f.inf | f.sign_bit,
                            f.nan, f.nan | 3, f.max_finite, f.one, f.one | f.sign_bit]])
    a = np.repeat(vals[-15:], vals.size).astype(np.uint32)
    b = np.tile(vals, 15).astype(np.uint32)
    a = np.concatenate([a, vals.astype(np.uint32)])
    b = np.concatenate([b, rng.permutation(vals).astype(np.uint32)])
    for name in ("le", "lt", "abs_le"):
        fn = getattr(oracle, name)
        exp = [fn(int(x), int(y), 7, 16) for x, y in zip(a, b)]
        assert getattr(model, name)(a, b, f).tolist() == exp, name


def test_signed_zero_and_denormal_comparisons():
    f = FP24
    neg0, den, nden = f.sign_bit, 5, f.sign_bit | 5
    assert model.le(neg0, 0, f) and model.le(0, neg0, f) and not model.lt(neg0, 0, f)
    assert model.le(den, nden, f) and not model.lt(0, den, f) and model.abs_le(den, neg0, f)
    assert not model.le(f.nan, f.nan, f) and not model.abs_le(0, f.nan, f)
    assert not model.lt(f.nan | 1, f.inf, f)


def test_broadcast_and_scalars():
    f = FP24
    one, two = f.one, int(model.encode(2.0, f))
    col = np.array([[one], [two]], dtype=np.uint32)
    row = np.array([one, two, 0], dtype=np.int64)
    out = model.mul(col, row, f)
    assert out.shape == (2, 3) and out.dtype == np.uint32
    assert model.decode(out, f).tolist() == [[1, 2, 0], [2, 4, 0]]
    s = model.add(one, one, f)
    assert isinstance(s, np.uint32) and s == two
    bits, fl = model.sub(one, [one, two], f, flags=True)
    assert bits.tolist() == [0, one | f.sign_bit] and fl.tolist() == [0, 0]
    assert model.decode([], f).shape == (0,)
    assert model.encode(np.float32(2.0), f) == two
    assert model.neg([f.nan | 1, one], f).tolist() == [f.nan, one | f.sign_bit]


def test_flags_names():
    assert model.flags_names(0) == []
    assert model.flags_names(np.uint8(5)) == ["overflow", "invalid"]
    _, fl = model.mul([FP24.inf, FP24.max_finite], [0, FP24.max_finite], FP24, flags=True)
    assert model.flags_names(fl) == ["overflow", "invalid"]


@pytest.mark.parametrize("call", [
    lambda: model.add(1 << 24, 0, FP24),
    lambda: model.add(np.array([1 << 24], np.uint32), 0, FP24),
    lambda: model.mul(0, np.array([0, 1 << 30], np.uint32), FP24),
    lambda: model.le(-1, 0, FP24),
    lambda: model.decode(1 << 40, FP24),
    lambda: model.neg(np.array([1 << 24], np.uint32), FP24),
    lambda: model.add(1.0, 0, FP24),
    lambda: model.add(0, 0, "FP24"),
    lambda: model.encode(1.0, FP24, direction="nearest"),
    lambda: model.encode("1.0", FP24),
])
def test_errors(call):
    with pytest.raises(ValueError):
        call()
