"""Evaluate a bit-vector term on NumPy arrays of operand values.

The references of :mod:`.reference` are z3 terms; to compare one with the golden model on
every operand pair of a small format (65 536 pairs and more), calling z3's simplifier per
pair is far too slow. :func:`evaluate` walks the term once and computes every node on
whole arrays (``uint64``, so every intermediate value must be at most 64 bits wide):
the same term the proofs use, evaluated concretely.

Supported: Boolean connectives, ``ite``, ``=``, ``distinct``, unsigned and signed
comparisons, ``bvadd``, ``bvsub``, ``bvneg``, ``bvmul``, ``bvand``, ``bvor``, ``bvxor``,
``bvnot``, ``bvshl``, ``bvlshr``, ``extract``, ``concat``, ``zero_extend``,
``sign_extend``, numerals and the variables given. Anything else (FloatingPoint terms)
raises ``ValueError``.
"""

from __future__ import annotations

import numpy as np
import z3

__all__ = ["evaluate"]


def _mask(width):
    return np.uint64((1 << width) - 1) if width < 64 else np.uint64(0xFFFFFFFFFFFFFFFF)


def _signed(x, width):
    x = x.astype(np.int64) if width < 64 else x.view(np.int64)
    if width < 64:
        x = np.where(x >= (1 << (width - 1)), x - (1 << width), x)
    return x


def _shift(x, amount, width, left):
    big = amount >= width
    safe = np.where(big, 0, amount).astype(np.uint64)
    out = (x << safe) if left else (x >> safe)
    return np.where(big, np.uint64(0), out & _mask(width))


def evaluate(term, values: dict, size: int):
    """Evaluate ``term`` with the variables set to arrays.

    Parameters
    ----------
    term : z3.ExprRef
        A bit-vector or Boolean term.
    values : dict
        Variable name -> integer array (all of length ``size``).
    size : int
        Number of points.

    Returns
    -------
    numpy.ndarray
        ``uint64`` values (bit vectors) or ``bool`` (Booleans).

    Raises
    ------
    ValueError
        For an operation it does not know, a node wider than 64 bits or an unknown variable.
    """
    memo = {}
    stack = [(term, False)]
    while stack:                                    # post-order without recursion
        t, done = stack.pop()
        if t.get_id() in memo:
            continue
        if done:
            memo[t.get_id()] = _node(t, [memo[c.get_id()] for c in t.children()], values, size)
            continue
        stack.append((t, True))
        stack.extend((c, False) for c in t.children() if c.get_id() not in memo)
    return memo[term.get_id()]


def _node(t, args, values, size):  # noqa: C901 (one dispatch table)
    k = t.decl().kind()
    if z3.is_bv(t) and t.size() > 64:
        raise ValueError(f"{t.sexpr()[:80]}: wider than 64 bits")
    w = t.size() if z3.is_bv(t) else None
    if z3.is_bv_value(t):
        return np.full(size, t.as_long(), dtype=np.uint64)
    if z3.is_true(t):
        return np.ones(size, dtype=bool)
    if z3.is_false(t):
        return np.zeros(size, dtype=bool)
    if k == z3.Z3_OP_UNINTERPRETED and t.num_args() == 0:
        name = t.decl().name()
        if name not in values:
            raise ValueError(f"no value for variable {name}")
        if w is None:
            return np.asarray(values[name], dtype=bool)
        return np.asarray(values[name], dtype=np.uint64) & _mask(w)
    cw = t.arg(0).size() if t.num_args() and z3.is_bv(t.arg(0)) else None
    simple = {
        z3.Z3_OP_AND: lambda: np.logical_and.reduce(args),
        z3.Z3_OP_OR: lambda: np.logical_or.reduce(args),
        z3.Z3_OP_NOT: lambda: ~args[0],
        z3.Z3_OP_XOR: lambda: args[0] ^ args[1],
        z3.Z3_OP_IMPLIES: lambda: ~args[0] | args[1],
        z3.Z3_OP_ITE: lambda: np.where(args[0], args[1], args[2]),
        z3.Z3_OP_EQ: lambda: args[0] == args[1],
        z3.Z3_OP_DISTINCT: lambda: args[0] != args[1],
        z3.Z3_OP_ULEQ: lambda: args[0] <= args[1],
        z3.Z3_OP_ULT: lambda: args[0] < args[1],
        z3.Z3_OP_UGEQ: lambda: args[0] >= args[1],
        z3.Z3_OP_UGT: lambda: args[0] > args[1],
        z3.Z3_OP_SLEQ: lambda: _signed(args[0], cw) <= _signed(args[1], cw),
        z3.Z3_OP_SLT: lambda: _signed(args[0], cw) < _signed(args[1], cw),
        z3.Z3_OP_SGEQ: lambda: _signed(args[0], cw) >= _signed(args[1], cw),
        z3.Z3_OP_SGT: lambda: _signed(args[0], cw) > _signed(args[1], cw),
    }
    if k in simple:
        return simple[k]()
    if k == z3.Z3_OP_BADD:
        out = args[0]
        for a in args[1:]:
            out = out + a
        return out & _mask(w)
    if k == z3.Z3_OP_BMUL:
        out = args[0]
        for a in args[1:]:
            out = out * a
        return out & _mask(w)
    arith = {
        z3.Z3_OP_BSUB: lambda: args[0] - args[1],
        z3.Z3_OP_BNEG: lambda: np.uint64(0) - args[0],
        z3.Z3_OP_BAND: lambda: np.bitwise_and.reduce(args),
        z3.Z3_OP_BOR: lambda: np.bitwise_or.reduce(args),
        z3.Z3_OP_BXOR: lambda: np.bitwise_xor.reduce(args),
        z3.Z3_OP_BNOT: lambda: ~args[0],
        z3.Z3_OP_BSHL: lambda: _shift(args[0], args[1], w, True),
        z3.Z3_OP_BLSHR: lambda: _shift(args[0], args[1], w, False),
        z3.Z3_OP_ZERO_EXT: lambda: args[0],
    }
    if k in arith:
        return arith[k]() & _mask(w)
    if k == z3.Z3_OP_EXTRACT:
        hi, lo = t.params()
        return (args[0] >> np.uint64(lo)) & _mask(hi - lo + 1)
    if k == z3.Z3_OP_CONCAT:
        out = np.zeros(size, dtype=np.uint64)
        for c, a in zip(t.children(), args):
            out = (out << np.uint64(c.size())) | a
        return out
    if k == z3.Z3_OP_SIGN_EXT:
        return _signed(args[0], cw).astype(np.uint64) & _mask(w)
    raise ValueError(f"cannot evaluate {t.decl().name()} ({t.sexpr()[:80]})")
