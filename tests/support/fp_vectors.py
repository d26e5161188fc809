"""FP operand vectors shared by the FP units' Verilog tests (``rtl/test_fp_cosim.py``,
``rtl/test_fp_add_dsp48.py``, ``rtl/test_dsp48_target.py``)."""

import numpy as np

from raplas_hdl.fp import FP24


def special_values(fmt):
    """Signed zeros, infinities, NaNs, denormal patterns, extremes and their neighbours."""
    e, m = fmt.exp_bits, fmt.man_bits
    v = [0, fmt.inf, fmt.nan, fmt.inf | 1, fmt.inf | fmt.man_mask, 1, fmt.man_mask,
         fmt.min_normal, fmt.min_normal + 1, fmt.max_finite, fmt.max_finite - 1, fmt.one,
         fmt.one + 1, fmt.one - 1, (fmt.bias + m + 2) << m, (fmt.bias + m + 1) << m | 1,
         (fmt.bias - 1) << m | fmt.man_mask, ((1 << e) - 3) << m, 2 << m]
    v = np.array(v, dtype=np.uint32)
    return np.concatenate([v, v | fmt.sign_bit]).astype(np.uint32)


def fp24_vectors(n, seed):
    rng = np.random.default_rng(seed)
    sp = special_values(FP24)
    a = rng.integers(0, 1 << FP24.width, n, dtype=np.uint32)
    # near operands (cancellation) and exponent-close pairs
    b = np.where(rng.random(n) < 0.3, a ^ rng.integers(0, 1 << 8, n, dtype=np.uint32),
                 rng.integers(0, 1 << FP24.width, n, dtype=np.uint32)).astype(np.uint32)
    pick = rng.random(n)
    a = np.where(pick < 0.15, sp[rng.integers(0, sp.size, n)], a).astype(np.uint32)
    b = np.where((pick > 0.1) & (pick < 0.25), sp[rng.integers(0, sp.size, n)], b)
    ga, gb = np.meshgrid(sp, sp)       # every special pair first
    a = np.concatenate([ga.ravel(), a]).astype(np.uint32)
    b = np.concatenate([gb.ravel(), b.astype(np.uint32)]).astype(np.uint32)
    sub = rng.integers(0, 2, a.size).astype(np.uint32)
    return a, b, sub

