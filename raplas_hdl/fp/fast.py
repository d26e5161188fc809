"""Fast paths of add and mul for compiled callers: the common case, and a sentinel.

Most operations of a ray-tracing workload have two normal operands and a normal result.
For those, :func:`common_add` and :func:`common_mul` compute the contract's result as
straight-line integer code (no branch, no division; fields kept in place so that a rounding
carry or a normalisation shift simply adds into the exponent). Every other case (a zero,
infinite or NaN operand, overflow, underflow, an exact zero sum) gives the sentinel ``-1``,
which no operation ever returns (a NaN result has sign 0), and the caller recomputes it
with the reference kernels of :mod:`raplas_hdl.fp.kernels`. Flags of a common-case result
are always 0.

- :func:`common_add` / :func:`common_mul` are inlined into the block loops of
  :mod:`raplas_hdl.fp.model` (LLVM vectorises them there);
- :func:`fast_add` / :func:`fast_mul` add the zero operands and the exact zero sum (still
  flag-free, still the reference's bits) for scalar callers, the fused per-pair and
  per-plane kernels of the units (:mod:`raplas_hdl.model.ray_triangle`,
  :mod:`raplas_hdl.model.plane_sphere`): axis-aligned planes and geometry have many zero
  components, and these would otherwise all take the slow path.

``E``, ``M`` (exponent and fraction bits) and ``R`` (rounding code of
:mod:`raplas_hdl.fp.kernels`) are integers; callers pass compile-time constants so that
LLVM folds every shift and mask. Operands are ``int64`` holding valid patterns.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .kernels import CHOP, RNE

__all__ = ["common_add", "common_mul", "fast_add", "fast_mul"]

_F64_MAGIC = np.int64(0x4330000000000000)       # float64 2^52: bit length by conversion
_F64_TWO52 = 4503599627370496.0


@njit(inline="always")
def _bitlen_f(v):
    """Bit length of ``0 < v < 2**52``, branch-free and vectorisable: ``v + 2^52`` as a
    float64 minus ``2^52`` is ``v`` exactly; its exponent field is the bit length."""
    f = np.int64(v | _F64_MAGIC).view(np.float64) - _F64_TWO52
    return (np.float64(f).view(np.int64) >> 52) - 1022


@njit(inline="always")
def common_mul(a, b, E, M, R):
    """``a * b`` in the common case, or -1 (all ones: the sentinel once cut to 32 bits)
    when it is not (an operand not normal, overflow or underflow)."""
    H = np.int64(1) << M
    MM = H - 1
    SH = E + M
    MAG = (np.int64(1) << SH) - 1
    EM = ((np.int64(1) << E) - 1) << M               # exponent field of inf/NaN, in place
    BIAS1 = (np.int64(1) << (E - 1)) << M          # (bias + 1) in place
    ma = a & MAG
    mb = b & MAG
    p = ((a & MM) | H) * ((b & MM) | H)              # exact, in [2^2M, 2^(2M+2))
    t = p >> (2 * M + 1)                             # 1 when the product is >= 2
    sh = M + t
    if R == RNE:                                     # + (half - 1 + lsb), then truncate
        p = p + (((np.int64(1) << (M - 1)) << t) - 1) + ((p >> sh) & 1)
    q = p >> sh                                      # hidden one at bit M (or a carry)
    # Exponent and fraction in place: a carry of the rounding adds into the exponent.
    mag = (ma & EM) + (mb & EM) + (t << M) + q - BIAS1
    sg = (a ^ b) & (np.int64(1) << SH)
    ok = (mag - H) | (EM - 1 - mag) | (ma - H) | (EM - 1 - ma) | (mb - H) | (EM - 1 - mb)
    return sg | mag | (ok >> 63)


@njit(inline="always")
def common_add(a, b, E, M, R):
    """``a + b`` in the common case, or -1 (all ones: the sentinel once cut to 32 bits)
    when it is not (an operand not normal, exact zero, overflow or underflow)."""
    H = np.int64(1) << M
    MM = H - 1
    SH = E + M
    SB = np.int64(1) << SH
    MAG = SB - 1
    EM = ((np.int64(1) << E) - 1) << M
    ma = a & MAG
    mb = b & MAG
    swap = mb > ma
    hi = mb if swap else ma
    lo = ma if swap else mb
    sg = (b if swap else a) & SB                     # the larger magnitude's sign
    d = min((hi >> M) - (lo >> M), M + 4)            # (B << 3) >> (M + 4) is already 0
    ax = ((hi & MM) | H) << 3                        # guard, round, sticky bits
    bx = ((lo & MM) | H) << 3
    bal = bx >> d
    if R == CHOP:
        bal = bal & ~np.int64(7)                     # shifted-out bits are dropped
    else:
        bal = bal | np.int64((bal << d) != bx)       # sticky
    s3 = (ax - bal) if ((a ^ b) & SB) != 0 else (ax + bal)
    z = s3 - 1                                       # negative for an exact zero sum
    lsh = M + 4 - _bitlen_f(s3 | np.int64(s3 == 0))  # -1 (carry) .. M+3 (cancellation)
    r1 = np.int64(lsh < 0)
    s3 = ((s3 << (lsh + r1)) >> r1) | (s3 & r1)      # bit M+3 leads; a carry keeps sticky
    if R == RNE:
        s3 = s3 + 3 + ((s3 >> 3) & 1)                # ties to even
    q = s3 >> 3
    mag = (hi & EM) - ((lsh + 1) << M) + q           # a rounding carry adds into exponent
    ok = (mag - H) | (EM - 1 - mag) | (lo - H) | (EM - 1 - hi) | z
    return sg | mag | (ok >> 63)


@njit(cache=True)
def fast_mul(a, b, E, M, R):
    """``a * b`` without flags, or -1 when the reference kernel is needed.

    Beyond :func:`common_mul`: a zero (or denormal) operand times a finite one is the
    signed zero (rule 4 of the contract, no flag)."""
    r = common_mul(a, b, E, M, R)
    if r >= 0:
        return r
    emf = (np.int64(1) << E) - 1
    xa = (a >> M) & emf
    xb = (b >> M) & emf
    if (xa == 0 or xb == 0) and xa != emf and xb != emf:
        return ((a ^ b) >> (E + M) & 1) << (E + M)
    return np.int64(-1)


@njit(cache=True)
def fast_add(a, b, E, M, R):
    """``a + b`` without flags, or -1 when the reference kernel is needed.

    Beyond :func:`common_add`: a zero (or denormal) operand gives the other one, two zeros
    give ``-0`` only when both are ``-0``, and an exact zero sum of normals gives ``+0``
    (rules 4 and 5 of the contract, no flag)."""
    r = common_add(a, b, E, M, R)
    if r >= 0:
        return r
    emf = (np.int64(1) << E) - 1
    sh = E + M
    xa = (a >> M) & emf
    xb = (b >> M) & emf
    if xa == emf or xb == emf:
        return np.int64(-1)
    if xa == 0 and xb == 0:
        return ((a >> sh) & (b >> sh) & 1) << sh
    if xa == 0:
        return b
    if xb == 0:
        return a
    mag = (np.int64(1) << sh) - 1
    if (a & mag) == (b & mag) and ((a ^ b) >> sh) & 1:   # x + (-x), both normal: +0
        return np.int64(0)
    return np.int64(-1)
