"""Exact-rational oracle of the FP contract (``docs/fp-format.md``).

Written from the contract's text alone, with :class:`fractions.Fraction` values and
Python integers; it shares no code with ``raplas_hdl.fp`` (not even the format object:
it takes ``E`` and ``M`` as plain integers). One element per call, plain Python: slow
but obviously right. Rounding modes: ``"rtz"``, ``"rne"``, ``"chop"`` (add/sub by the
contract's truncation algorithm, everything else as ``rtz``), and for :func:`encode`
the directions ``"up"`` and ``"down"``.

Results are ``(bits, flags)`` with the flag bits overflow=1, underflow=2, invalid=4.
"""

from __future__ import annotations

from fractions import Fraction
from functools import lru_cache

OVF, UNF, INV = 1, 2, 4


@lru_cache(maxsize=None)
def fmt(E, M):
    return Fmt(E, M)


class Fmt:
    """The constants of format ``(E, M)`` derived from the contract's table."""

    def __init__(self, E, M):
        self.E, self.M = E, M
        self.W = 1 + E + M
        self.B = 2 ** (E - 1) - 1
        self.emin = 1 - self.B
        self.emax = 2 ** E - 2 - self.B
        self.top = 2 ** E - 1                 # all-ones exponent field
        self.nan = (self.top << M) | (1 << (M - 1))

    def pack(self, s, field, frac):
        return (s << (self.E + self.M)) | (field << self.M) | frac

    def inf(self, s):
        return self.pack(s, self.top, 0)

    def zero(self, s):
        return self.pack(s, 0, 0)

    def max_finite(self, s):
        return self.pack(s, self.top - 1, 2 ** self.M - 1)

    def min_normal(self, s):
        return self.pack(s, 1, 0)


def unpack(bits, F):
    """``(kind, sign, value)``: kind is "zero", "num", "inf" or "nan"; value a Fraction
    (signed) for "num", 0 for zeros."""
    s = (bits >> (F.E + F.M)) & 1
    field = (bits >> F.M) & F.top
    frac = bits & (2 ** F.M - 1)
    if field == 0:
        return "zero", s, Fraction(0)
    if field == F.top:
        return ("inf" if frac == 0 else "nan"), s, None
    exp = field - F.B - F.M                      # value = (2^M + frac) * 2^exp
    v = Fraction((2 ** F.M + frac) << exp) if exp >= 0 else Fraction(2 ** F.M + frac, 1 << -exp)
    return "num", s, (-v if s else v)


def round_value(x, F, mode):
    """Round a non-zero Fraction ``x`` once, with an unbounded exponent, then apply
    overflow (rule 2, or the encode rule for directions) and flush to zero (rule 3, or
    the encode rule). Returns ``(bits, flags)``."""
    s = 1 if x < 0 else 0
    mag = -x if s else x
    n, d = mag.numerator, mag.denominator
    k = n.bit_length() - d.bit_length()          # 2^k <= mag < 2^(k+1) after the fix
    if (n << max(0, -k)) < (d << max(0, k)):
        k -= 1
    shift = F.M - k                              # mag * 2^shift is in [2^M, 2^(M+1))
    num, den = (n << shift, d) if shift >= 0 else (n, d << -shift)
    q, r = divmod(num, den)                      # q = floor, r/den the rest in [0, 1)
    assert 2 ** F.M <= q < 2 ** (F.M + 1)
    away = (mode == "up" and s == 0) or (mode == "down" and s == 1)
    if mode == "rne":
        if 2 * r > den or (2 * r == den and q % 2 == 1):
            q += 1
    elif mode in ("up", "down"):
        if away and r != 0:
            q += 1
    else:
        assert mode in ("rtz", "chop")
    if q == 2 ** (F.M + 1):
        q //= 2
        k += 1
    if k > F.emax:
        if mode == "rne" or away:
            return F.inf(s), OVF
        return F.max_finite(s), OVF
    if k < F.emin:
        if away:
            return F.min_normal(s), UNF
        return F.zero(s), UNF
    return F.pack(s, k + F.B, q - 2 ** F.M), 0


def _chop_add(a, b, F):
    """The contract's ``chop`` add of two normal operands, literally."""
    def parts(bits):
        s = (bits >> (F.E + F.M)) & 1
        field = (bits >> F.M) & F.top
        sig = (bits & (2 ** F.M - 1)) + 2 ** F.M
        return s, field, sig

    pa, pb = parts(a), parts(b)
    if (pb[1], pb[2]) > (pa[1], pa[2]):
        pa, pb = pb, pa
    sa, ea, A = pa
    sb, eb, B = pb
    dd = ea - eb
    Bp = 0 if dd > F.M else B // 2 ** dd
    ex = ea
    if sa == sb:
        S = A + Bp
        if S >= 2 ** (F.M + 1):
            S //= 2
            ex += 1
    else:
        S = A - Bp
        if S == 0:
            return F.zero(0), 0
        while S < 2 ** F.M:
            S *= 2
            ex -= 1
    if ex >= F.top:
        return F.max_finite(sa), OVF
    if ex <= 0:
        return F.zero(sa), UNF
    return F.pack(sa, ex, S - 2 ** F.M), 0


def add(a, b, E, M, rounding):
    """``a + b`` by the contract; returns ``(bits, flags)``."""
    F = fmt(E, M)
    ka, sa, va = unpack(a, F)
    kb, sb, vb = unpack(b, F)
    if ka == "nan" or kb == "nan":
        return F.nan, 0
    if ka == "inf" and kb == "inf":
        return (F.inf(sa), 0) if sa == sb else (F.nan, INV)
    if ka == "inf":
        return F.inf(sa), 0
    if kb == "inf":
        return F.inf(sb), 0
    if ka == "zero" and kb == "zero":
        return F.zero(1 if (sa and sb) else 0), 0
    if rounding == "chop":
        if ka == "zero":
            return F.pack(sb, (b >> M) & F.top, b & (2 ** M - 1)), 0
        if kb == "zero":
            return F.pack(sa, (a >> M) & F.top, a & (2 ** M - 1)), 0
        return _chop_add(a, b, F)
    x = va + vb
    if x == 0:
        return F.zero(0), 0
    return round_value(x, F, rounding)


def neg(a, E, M):
    """``-a``: sign flipped, NaN gives the canonical NaN."""
    F = fmt(E, M)
    if unpack(a, F)[0] == "nan":
        return F.nan
    return a ^ (1 << (E + M))


def sub(a, b, E, M, rounding):
    return add(a, neg(b, E, M), E, M, rounding)


def mul(a, b, E, M, rounding):
    """``a * b`` by the contract (``chop`` as ``rtz``); returns ``(bits, flags)``."""
    F = fmt(E, M)
    ka, sa, va = unpack(a, F)
    kb, sb, vb = unpack(b, F)
    s = sa ^ sb
    if ka == "nan" or kb == "nan":
        return F.nan, 0
    if ka == "inf" or kb == "inf":
        if ka == "zero" or kb == "zero":
            return F.nan, INV
        return F.inf(s), 0
    if ka == "zero" or kb == "zero":
        return F.zero(s), 0
    return round_value(va * vb, F, "rtz" if rounding == "chop" else rounding)


def _order_value(bits, F):
    """A comparable value (Fraction or +-inf as float), or None for NaN."""
    kind, s, v = unpack(bits, F)
    if kind == "nan":
        return None
    if kind == "inf":
        return float("-inf") if s else float("inf")
    return v


def le(a, b, E, M):
    F = fmt(E, M)
    x, y = _order_value(a, F), _order_value(b, F)
    return x is not None and y is not None and x <= y


def lt(a, b, E, M):
    F = fmt(E, M)
    x, y = _order_value(a, F), _order_value(b, F)
    return x is not None and y is not None and x < y


def abs_le(a, b, E, M):
    F = fmt(E, M)
    x, y = _order_value(a, F), _order_value(b, F)
    return x is not None and y is not None and abs(x) <= abs(y)


def encode(x, E, M, mode):
    """Round the float ``x`` into ``(E, M)``; ``mode`` is "rtz", "rne", "chop" (as rtz),
    "up" or "down". Returns ``(bits, flags)``."""
    F = fmt(E, M)
    if x != x:
        return F.nan, 0
    s = 1 if (x < 0 or (x == 0 and str(x).startswith("-"))) else 0
    if x in (float("inf"), float("-inf")):
        return F.inf(s), 0
    if x == 0:
        return F.zero(s), 0
    return round_value(Fraction(x), F, "rtz" if mode == "chop" else mode)


def decode(bits, E, M):
    """The exact value as a float (zeros signed, denormal patterns as zeros)."""
    F = fmt(E, M)
    kind, s, v = unpack(bits, F)
    if kind == "nan":
        return float("nan")
    if kind == "inf":
        return float("-inf") if s else float("inf")
    if kind == "zero":
        return -0.0 if s else 0.0
    f = float(v)
    assert Fraction(f) == v
    return f


# -- comparison helper for the tests ------------------------------------------------------
_OPS = {"add": add, "sub": sub, "mul": mul}


def expected_binop(op, a, b, E, M, rounding):
    """Oracle results of ``op`` over sequences of patterns: (bits list, flags list)."""
    fn = _OPS[op]
    bits, flags = [], []
    for x, y in zip(a, b):
        r, f = fn(int(x), int(y), E, M, rounding)
        bits.append(r)
        flags.append(f)
    return bits, flags


def mismatches(got_bits, got_flags, exp_bits, exp_flags, a, b=None, limit=5):
    """Indices where bits or flags differ, and a readable description of the first few."""
    bad = [i for i in range(len(exp_bits))
           if int(got_bits[i]) != exp_bits[i] or int(got_flags[i]) != exp_flags[i]]
    lines = []
    for i in bad[:limit]:
        ops = f"{int(a[i]):#x}" + ("" if b is None else f", {int(b[i]):#x}")
        lines.append(f"({ops}): got {int(got_bits[i]):#x}/{int(got_flags[i])} "
                     f"expected {exp_bits[i]:#x}/{exp_flags[i]}")
    return bad, "\n".join(lines)
