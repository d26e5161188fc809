"""E=8/M=23 ``rne`` is IEEE binary32 (and E=5/M=10 binary16) without denormals: wherever
the operands and the *exact* result are normal, the model must equal NumPy bit for bit.

The exact result is judged in float64: a product of two binary32 (or binary16) values is
exact there; a sum may round, but never across the normal threshold, because both
operands are multiples of the smallest denormal, far coarser than float64's rounding.
"""

import numpy as np
import pytest

from raplas_hdl.fp import FPFormat
from raplas_hdl.fp import model

IEEE = {"binary32": (FPFormat(8, 23, "rne"), np.float32, np.uint32),
        "binary16": (FPFormat(5, 10, "rne"), np.float16, np.uint16)}
N = 1_000_000


def operands(fmt, op, n, seed):
    """Normal operands: raw random patterns, close exponents (cancellation, alignment),
    and exponents aimed at the ends of the range."""
    rng = np.random.default_rng([seed, fmt.exp_bits, ["add", "sub", "mul"].index(op)])
    E, M = fmt.exp_bits, fmt.man_bits
    top, bias = (1 << E) - 1, fmt.bias

    def pat(x):
        k = x.size
        return ((rng.integers(0, 2, k) << (E + M)) | (x << M)
                | rng.integers(0, 1 << M, k)).astype(np.int64)

    k = n // 3
    xa = rng.integers(1, top, size=3 * k)
    xb = np.concatenate([rng.integers(1, top, size=k),
                         np.clip(xa[k:2 * k] + rng.integers(-M - 3, M + 4, k), 1, top - 1),
                         np.clip((top - 1 if op == "mul" else 0) + bias - xa[2 * k:]
                                 + rng.integers(-2, 3, k), 1, top - 1)
                         if op == "mul" else
                         np.clip(xa[2 * k:] + rng.integers(-1, 2, k), 1, top - 1)])
    a, b = pat(xa), pat(xb)
    # Same magnitude with tiny perturbations: deep cancellation in add/sub.
    b[:200] = (a[:200] ^ (1 << (E + M))) + rng.integers(-3, 4, 200)
    return a.astype(np.uint32), np.clip(b, 0, fmt.mask).astype(np.uint32)


def check(name, op, seed=1):
    fmt, ftype, utype = IEEE[name]
    a, b = operands(fmt, op, N, seed)
    fa, fb = a.astype(utype).view(ftype), b.astype(utype).view(ftype)
    x, y = fa.astype(np.float64), fb.astype(np.float64)
    exact = {"add": x + y, "sub": x - y, "mul": x * y}[op]
    info = np.finfo(ftype)
    keep = (np.abs(x) >= info.tiny) & (np.abs(y) >= info.tiny) & np.isfinite(x) \
        & np.isfinite(y) & (np.abs(exact) >= float(info.tiny)) \
        & (np.abs(exact) <= float(info.max))
    assert keep.sum() > N // 2
    a, b, fa, fb = a[keep], b[keep], fa[keep], fb[keep]
    with np.errstate(all="ignore"):
        ref = {"add": fa + fb, "sub": fa - fb, "mul": fa * fb}[op]
    ref = ref.view(utype).astype(np.uint32)
    got = getattr(model, op)(a, b, fmt)
    bad = np.flatnonzero(got != ref)
    assert bad.size == 0, (f"{name} {op}: {bad.size} of {a.size} differ, e.g. "
                           f"{a[bad[0]]:#x} {op} {b[bad[0]]:#x} = {got[bad[0]]:#x}, "
                           f"numpy {ref[bad[0]]:#x}")


@pytest.mark.parametrize("op", ["add", "sub", "mul"])
def test_binary32(op):
    check("binary32", op)


@pytest.mark.parametrize("op", ["add", "sub", "mul"])
def test_binary16(op):
    check("binary16", op)


def test_binary32_flushes_where_ieee_gives_denormals():
    """The one place the formats part: a tiny exact result flushes to a signed zero."""
    fmt = FPFormat(8, 23, "rne")
    a = np.float32(1.5 * 2.0 ** -126)
    b = np.float32(-1.25 * 2.0 ** -126)
    ua, ub = (np.array([v]).view(np.uint32) for v in (a, b))
    bits, flags = model.add(ua, ub, fmt, flags=True)
    assert (a + b) != 0 and bits[0] == 0 and flags[0] == 2
    bits, flags = model.mul(ub, ua, fmt, flags=True)
    assert bits[0] == 0x8000_0000 and flags[0] == 2
