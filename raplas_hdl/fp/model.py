"""Bit-exact golden model of the FP contract on NumPy arrays of bit patterns.

Every operation takes and returns ``uint32`` bit patterns of a
:class:`~raplas_hdl.fp.format.FPFormat` and follows ``docs/fp-format.md`` bit for
bit (the scalar rules live in :mod:`raplas_hdl.fp.kernels`; this module broadcasts in
NumPy and runs the kernels in parallel numba loops, no per-element Python).

Operands are array-likes of integers (Python ints, any integer dtype); a pattern wider
than the format (negative, or ``>= 2**fmt.width``) raises ``ValueError``. Scalars give
NumPy scalars, arrays give arrays of the broadcast shape.

Compile time: the kernels are compiled on first use and cached on disk (numba
``cache=True``, in ``__pycache__`` beside the sources); the first call in a fresh
checkout takes a few seconds per operation, later processes load the cache in well
under a second.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import get_num_threads, njit

from .format import (FLAG_INVALID, FLAG_NAMES, FLAG_OVERFLOW, FLAG_UNDERFLOW, FPFormat,
                     check_format)
from .kernels import (CHOP, DOWN, RNE, RTZ, UP, abs_le_k, add_int_k, add_k, decode_k,
                      encode_k, le_k, lt_k, mul_int_k, mul_k, neg_k, rmode_code)
from .fast import common_add as _common_add
from .fast import common_mul as _common_mul
from ..parallel import run_chunks
from .numba_cache import drop_stale_cache

drop_stale_cache(__file__)

__all__ = ["encode", "decode", "add", "sub", "mul", "neg", "le", "lt", "abs_le",
           "flags_names"]

_OP_ADD, _OP_SUB, _OP_MUL = 0, 1, 2
_CMP_LE, _CMP_LT, _CMP_ABS_LE = 0, 1, 2
_RNE, _CHOP = RNE, CHOP
_OVF_I, _UNF_I, _INV_I = FLAG_OVERFLOW, FLAG_UNDERFLOW, FLAG_INVALID


# -- compiled loops -----------------------------------------------------------------------
# One tight loop per operation (a runtime switch inside the loop costs several times the
# arithmetic), over the elements ``lo .. hi-1`` (:func:`_chunks` spreads a call over the
# cores; no numba ``parallel=True``: its compile costs seconds per loop). Each returns the
# number of operand patterns wider than the format.
@njit(nogil=True, cache=True)
def _add_loop(a, b, e, m, rmode, out, fl, lo, hi):
    lim = np.int64(1) << (1 + e + m)
    bad = 0
    for i in range(lo, hi):
        x = np.int64(a[i])
        y = np.int64(b[i])
        bad += np.int64(x >= lim) | np.int64(y >= lim)
        out[i], fl[i] = add_k(x & (lim - 1), y & (lim - 1), e, m, rmode)
    return bad


@njit(nogil=True, cache=True)
def _sub_loop(a, b, e, m, rmode, out, fl, lo, hi):
    lim = np.int64(1) << (1 + e + m)
    bad = 0
    for i in range(lo, hi):
        x = np.int64(a[i])
        y = np.int64(b[i])
        bad += np.int64(x >= lim) | np.int64(y >= lim)
        out[i], fl[i] = add_k(x & (lim - 1), np.int64(neg_k(y & (lim - 1), e, m)), e, m,
                              rmode)
    return bad


@njit(nogil=True, cache=True)
def _mul_loop(a, b, e, m, rmode, out, fl, lo, hi):
    lim = np.int64(1) << (1 + e + m)
    bad = 0
    for i in range(lo, hi):
        x = np.int64(a[i])
        y = np.int64(b[i])
        bad += np.int64(x >= lim) | np.int64(y >= lim)
        out[i], fl[i] = mul_k(x & (lim - 1), y & (lim - 1), e, m, rmode)
    return bad


@njit(nogil=True, cache=True)
def _int_loop(a, b, e, m, rmode, op, out, fl, lo, hi):
    """The integer kernels whatever the format (for the tests: both paths, same bits)."""
    lim = np.int64(1) << (1 + e + m)
    bad = 0
    for i in range(lo, hi):
        x = np.int64(a[i])
        y = np.int64(b[i])
        bad += np.int64(x >= lim) | np.int64(y >= lim)
        x &= lim - 1
        y &= lim - 1
        if op == _OP_SUB:
            y = np.int64(neg_k(y, e, m))
        if op == _OP_MUL:
            out[i], fl[i] = mul_int_k(x, y, e, m, rmode)
        else:
            out[i], fl[i] = add_int_k(x, y, e, m, rmode)
    return bad


@njit(nogil=True, cache=True)
def _negop(a, e, m, out, lo, hi):
    lim = np.int64(1) << (1 + e + m)
    bad = 0
    for i in range(lo, hi):
        x = np.int64(a[i])
        if x >= lim:
            bad += 1
            x = 0
        out[i] = neg_k(x, e, m)
    return bad


@njit(nogil=True, cache=True)
def _cmpop(a, b, e, m, op, out, lo, hi):
    lim = np.int64(1) << (1 + e + m)
    bad = 0
    for i in range(lo, hi):
        x = np.int64(a[i])
        y = np.int64(b[i])
        if x >= lim or y >= lim:
            bad += 1
            x = 0
            y = 0
        if op == _CMP_LE:
            out[i] = le_k(x, y, e, m)
        elif op == _CMP_LT:
            out[i] = lt_k(x, y, e, m)
        else:
            out[i] = abs_le_k(x, y, e, m)
    return bad


@njit(nogil=True, cache=True)
def _encode(x, e, m, mode, out, fl, lo, hi):
    for i in range(lo, hi):
        r, f = encode_k(x[i], e, m, mode)
        out[i] = r
        fl[i] = f
    return 0


@njit(nogil=True, cache=True)
def _decode(a, e, m, out, lo, hi):
    lim = np.int64(1) << (1 + e + m)
    bad = 0
    for i in range(lo, hi):
        x = np.int64(a[i])
        if x >= lim:
            bad += 1
            x = 0
        out[i] = decode_k(x, e, m)
    return bad


def _chunks(kernel, n, *args):
    """Run ``kernel(*args, lo, hi)`` over ``0 .. n`` on the cores; the summed returns."""
    return sum(run_chunks(n, lambda lo, hi: kernel(*args, lo, hi), min_chunk=1 << 15))


# -- specialised loops --------------------------------------------------------------------
# The loops above take the format as runtime integers and go through the generic kernels.
# For large arrays :func:`_fast_kernel` compiles, once per (operation, E, M, rounding,
# flags wanted), a loop in which the format and the rounding are compile-time constants
# (closure variables: every shift and mask is an immediate, dead roundings vanish). Each
# block of the array takes two passes:
#   1. the common case, both operands normal and the result in range, as straight-line
#      integer code (no branch, no division, fields kept in place so that a rounding carry
#      or a normalisation shift simply adds into the exponent) that LLVM vectorises (AVX2:
#      4 x int64 lanes, the significand product one ``vpmuldq``); every other element
#      (zero, infinity or NaN operand, overflow, underflow, exact zero sum) gets the
#      sentinel 0xFFFFFFFF, which no operation ever returns (a NaN result has sign 0);
#   2. only in blocks that hold a sentinel: those elements again through the generic
#      integer kernels ``add_int_k``/``mul_int_k`` (the reference for every case).
# Flags of common-case elements are 0. The result is the integer kernels' bit for bit and
# flag for flag (tests/fp/test_model_fastpath.py holds the fast loop to the generic one).
# The blocks of a large array are split across threads (numba releases the GIL).
_BLOCK = 4096             # elements per pass-1/pass-2 block (stays in L1/L2)
_FAST_MIN = 1 << 15       # smaller arrays take the generic loops (no compile per format)
_PAR_MIN = 1 << 16        # smaller arrays run in the calling thread
_SENT = np.uint32(0xFFFFFFFF)
_FAST_KERNELS = {}


def _fast_kernel(op, e, m, rmode, want_flags):
    """The compiled block loop of ``op`` for one format, rounding and flag choice (built
    once per process; numba's disk cache keys it by the constants). ``chop`` multiplies
    like ``rtz``, and ``sub`` is ``add`` with the sign of ``b`` flipped, so they share."""
    is_mul = op == _OP_MUL
    if is_mul and rmode == _CHOP:
        rmode = RTZ
    key = (is_mul, e, m, rmode, bool(want_flags))
    kern = _FAST_KERNELS.get(key)
    if kern is not None:
        return kern
    E, M, R, FL, IS_MUL, BL = int(e), int(m), int(rmode), bool(want_flags), is_mul, _BLOCK

    @njit(nogil=True, cache=True)
    def kern(a, b, negb, out, fl):
        """Blocks of ``out = a op b``; returns the OR of all operand patterns."""
        n = a.size
        o = np.uint32(0)
        for lo in range(0, n, BL):
            ab = a[lo:lo + BL]
            bb = b[lo:lo + BL]
            ob = out[lo:lo + BL]
            fix = np.int64(0)
            for i in range(ab.size):
                x = ab[i]
                y = bb[i]
                o |= x | y
                if IS_MUL:
                    r = _common_mul(np.int64(x), np.int64(y), E, M, R)
                else:
                    r = _common_add(np.int64(x), np.int64(y) ^ negb, E, M, R)
                fix |= r                                 # negative once a sentinel is out
                ob[i] = np.uint32(r)
            if FL:
                fl[lo:lo + BL] = 0
            if fix < 0:
                for i in range(ab.size):
                    if ob[i] == _SENT:
                        x = np.int64(ab[i])
                        y = np.int64(bb[i])
                        if IS_MUL:
                            r2, f2 = mul_int_k(x, y, E, M, R)
                        else:
                            y = np.int64(neg_k(y, E, M)) if negb else y
                            r2, f2 = add_int_k(x, y, E, M, R)
                        ob[i] = r2
                        if FL:
                            fl[lo + i] = f2
        return o

    _FAST_KERNELS[key] = kern
    return kern


_POOL = [None, None]      # (executor, pid): rebuilt after a fork


def _pool(workers):
    ex, pid = _POOL
    if ex is None or pid != os.getpid() or ex._max_workers < workers:
        ex = ThreadPoolExecutor(max_workers=max(workers, os.cpu_count() or 1),
                                thread_name_prefix="fp-model")
        _POOL[:] = [ex, os.getpid()]
    return ex


def _run_fast(fa, fb, fmt, op, want_flags):
    """Run the specialised loop; returns (bits, flags or None, number of wide patterns).
    Uses numba's thread count (``numba.set_num_threads``) for large arrays."""
    n = fa.size
    out = np.empty(n, dtype=np.uint32)
    fl = np.empty(n if want_flags else 0, dtype=np.uint8)
    kern = _fast_kernel(op, fmt.exp_bits, fmt.man_bits, rmode_code(fmt), want_flags)
    negb = (1 << (fmt.width - 1)) if op == _OP_SUB else 0
    threads = min(get_num_threads(), max(1, n // (_PAR_MIN // 2)))
    if threads <= 1:
        orv = kern(fa, fb, negb, out, fl)
    else:
        step = -(-n // (threads * _BLOCK)) * _BLOCK
        parts = [slice(lo, lo + step) for lo in range(0, n, step)]
        futs = [_pool(threads).submit(kern, fa[s], fb[s], negb, out[s],
                                      fl[s] if want_flags else fl) for s in parts]
        orv = 0
        for f in futs:
            orv |= int(f.result())
    bad = 0
    if int(orv) > fmt.mask:
        bad = int(np.count_nonzero((fa > fmt.mask) | (fb > fmt.mask)))
    return out, (fl if want_flags else None), bad


# -- argument handling --------------------------------------------------------------------
_check_fmt = check_format


def _patterns(x, fmt, name):
    """Coerce to a ``uint32`` array; patterns that do not fit ``uint32`` raise here, the
    rest is range-checked against the format inside the compiled loop."""
    arr = np.asarray(x)
    if arr.dtype == np.uint32:
        return arr
    if arr.size == 0:
        return arr.astype(np.uint32)
    if arr.dtype == object:
        try:
            arr = np.array(x, dtype=np.int64)
        except (OverflowError, TypeError, ValueError):
            raise ValueError(f"{name} must hold integer bit patterns of the {fmt.width}-bit "
                             f"format {fmt.name}") from None
    if arr.dtype.kind not in "iu":
        raise ValueError(f"{name} must hold integer bit patterns, not dtype {arr.dtype}")
    if arr.size and (arr.min() < 0 or arr.max() > fmt.mask):
        raise ValueError(f"{name} holds patterns outside 0..{fmt.mask:#x}, wider than the "
                         f"{fmt.width}-bit format {fmt.name}")
    return arr.astype(np.uint32)


def _flat(*arrays):
    """Broadcast, then contiguous 1-D views (copies only when needed)."""
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    flat = []
    for a in arrays:
        if a.shape != shape:
            a = np.broadcast_to(a, shape)
        flat.append(np.ascontiguousarray(a).reshape(-1))
    return shape, flat


def _shape_out(out, shape):
    out = out.reshape(shape)
    return out[()] if shape == () else out


def _raise_wide(bad, fmt, names):
    if bad:
        raise ValueError(f"{' or '.join(names)} holds {bad} patterns wider than the "
                         f"{fmt.width}-bit format {fmt.name}")


def _binary(a, b, fmt, op, flags, int_path=False, path="auto"):
    """Run a binary operation. ``path`` picks the loop: ``"auto"`` (the specialised loop
    for arrays of at least ``_FAST_MIN`` elements, else the generic one), ``"fast"``,
    ``"generic"`` (``add_k``/``mul_k``) or ``"int"`` (the integer kernels; also
    ``int_path=True``). Every path gives the same bits and flags; the tests check that."""
    _check_fmt(fmt)
    if int_path:
        path = "int"
    if path not in ("auto", "fast", "generic", "int"):
        raise ValueError(f"path must be auto, fast, generic or int, not {path!r}")
    a = _patterns(a, fmt, "a")
    b = _patterns(b, fmt, "b")
    shape, (fa, fb) = _flat(a, b)
    if path == "fast" or (path == "auto" and fa.size >= _FAST_MIN):
        out, fl, bad = _run_fast(fa, fb, fmt, op, flags)
        _raise_wide(bad, fmt, ("a", "b"))
        if flags:
            return _shape_out(out, shape), _shape_out(fl, shape)
        return _shape_out(out, shape)
    out = np.empty(fa.size, dtype=np.uint32)
    fl = np.empty(fa.size, dtype=np.uint8)
    args = (fa, fb, fmt.exp_bits, fmt.man_bits, rmode_code(fmt))
    if path == "int":
        bad = _chunks(_int_loop, fa.size, *args, op, out, fl)
    else:
        bad = _chunks((_add_loop, _sub_loop, _mul_loop)[op], fa.size, *args, out, fl)
    _raise_wide(bad, fmt, ("a", "b"))
    if flags:
        return _shape_out(out, shape), _shape_out(fl, shape)
    return _shape_out(out, shape)


# -- public API ---------------------------------------------------------------------------
def add(a, b, fmt: FPFormat, flags: bool = False):
    """``a + b``, rounded once by ``fmt.rounding``.

    Parameters
    ----------
    a, b : array_like of int
        Bit patterns of ``fmt`` (broadcast against each other).
    fmt : FPFormat
        Format and rounding.
    flags : bool
        Also return the event flags.

    Returns
    -------
    numpy.ndarray of uint32, or (bits, flags)
        ``flags`` is a ``uint8`` array of ``FLAG_OVERFLOW | FLAG_UNDERFLOW | FLAG_INVALID``.

    Raises
    ------
    ValueError
        If a pattern is wider than the format or not an integer.
    """
    return _binary(a, b, fmt, _OP_ADD, flags)


def sub(a, b, fmt: FPFormat, flags: bool = False):
    """``a - b = add(a, neg(b))``; see :func:`add`."""
    return _binary(a, b, fmt, _OP_SUB, flags)


def mul(a, b, fmt: FPFormat, flags: bool = False):
    """``a * b``, rounded once (``chop`` multiplies like ``rtz``); see :func:`add`."""
    return _binary(a, b, fmt, _OP_MUL, flags)


def neg(a, fmt: FPFormat):
    """``-a``: the sign bit flipped; a NaN gives the canonical NaN."""
    _check_fmt(fmt)
    a = _patterns(a, fmt, "a")
    shape, (fa,) = _flat(a)
    out = np.empty(fa.size, dtype=np.uint32)
    _raise_wide(_chunks(_negop, fa.size, fa, fmt.exp_bits, fmt.man_bits, out), fmt, ("a",))
    return _shape_out(out, shape)


def _compare(a, b, fmt, op):
    _check_fmt(fmt)
    a = _patterns(a, fmt, "a")
    b = _patterns(b, fmt, "b")
    shape, (fa, fb) = _flat(a, b)
    out = np.empty(fa.size, dtype=np.bool_)
    _raise_wide(_chunks(_cmpop, fa.size, fa, fb, fmt.exp_bits, fmt.man_bits, op, out), fmt,
                ("a", "b"))
    return _shape_out(out, shape)


def le(a, b, fmt: FPFormat):
    """``a <= b`` as an ordered comparison: NaN gives False, -0 == +0, denormals are 0."""
    return _compare(a, b, fmt, _CMP_LE)


def lt(a, b, fmt: FPFormat):
    """``a < b`` as an ordered comparison: NaN gives False, -0 == +0, denormals are 0."""
    return _compare(a, b, fmt, _CMP_LT)


def abs_le(a, b, fmt: FPFormat):
    """``|a| <= |b|``: NaN gives False, denormal patterns are 0."""
    return _compare(a, b, fmt, _CMP_ABS_LE)


def encode(x, fmt: FPFormat, direction: str | None = None, flags: bool = False):
    """Round float64 values into ``fmt``.

    Parameters
    ----------
    x : array_like of float
        Values (converted to float64).
    fmt : FPFormat
        Target format; with ``direction=None`` its rounding is used (``chop`` as ``rtz``).
    direction : {None, "up", "down"}
        ``"up"`` rounds toward +inf, ``"down"`` toward -inf. An overflow in the
        direction of rounding gives the signed infinity, otherwise the signed max finite;
        a non-zero value below the normal range gives the signed zero, or the signed min
        normal when rounding away from zero.
    flags : bool
        Also return event flags: overflow (a finite value beyond the range), underflow (a
        non-zero value below the normal range, whatever it became). Never invalid.

    Returns
    -------
    numpy.ndarray of uint32, or (bits, flags)

    Raises
    ------
    ValueError
        For an unknown direction or values that are not real numbers.
    """
    _check_fmt(fmt)
    if direction is None:
        mode = rmode_code(fmt)
        mode = RTZ if mode == 2 else mode
    elif direction == "up":
        mode = UP
    elif direction == "down":
        mode = DOWN
    else:
        raise ValueError(f"direction must be None, 'up' or 'down', not {direction!r}")
    arr = np.asarray(x)
    if arr.dtype.kind not in "fiub":
        raise ValueError(f"x must hold real numbers, not dtype {arr.dtype}")
    shape = arr.shape
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    bits = arr.reshape(-1).view(np.int64)
    out = np.empty(bits.size, dtype=np.uint32)
    fl = np.empty(bits.size, dtype=np.uint8)
    _chunks(_encode, bits.size, bits, fmt.exp_bits, fmt.man_bits, mode, out, fl)
    if flags:
        return _shape_out(out, shape), _shape_out(fl, shape)
    return _shape_out(out, shape)


def decode(bits, fmt: FPFormat):
    """Exact float64 values of bit patterns (denormal patterns decode as signed zeros,
    NaNs as NaN)."""
    _check_fmt(fmt)
    a = _patterns(bits, fmt, "bits")
    shape, (fa,) = _flat(a)
    out = np.empty(fa.size, dtype=np.int64)
    _raise_wide(_chunks(_decode, fa.size, fa, fmt.exp_bits, fmt.man_bits, out), fmt,
                ("bits",))
    return _shape_out(out.view(np.float64), shape)


def flags_names(flags) -> list[str]:
    """Names of the event flags set in one flag value, e.g. ``["overflow", "invalid"]``.

    For an array, the names of the flags set in any element.
    """
    value = int(np.bitwise_or.reduce(np.asarray(flags, dtype=np.uint8).reshape(-1))) \
        if np.ndim(flags) else int(flags)
    return [name for bit, name in sorted(FLAG_NAMES.items()) if value & bit]
