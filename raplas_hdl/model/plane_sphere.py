"""Golden model of the plane-sphere tester and of the tester array (bit for bit with the RTL).

One tester holds a plane ``(n, p)`` (unit normal, offset; plane ``n . x + p = 0``) and
tests a sphere ``(C, r')`` (centre, inflated radius) with six operations of the FP
contract, in this order and grouping (the RTL's):

1. ``mx = mul(n.x, C.x)``, ``my = mul(n.y, C.y)``, ``mz = mul(n.z, C.z)``
2. ``s1 = add(mx, my)``, ``s2 = add(mz, p)``
3. ``d = add(s1, s2)``
4. ``flag = NOT lt(r', |d|)``, i.e. NOT(``|d| > r'``) as an ordered comparison: a NaN
   ``d`` (or ``r'``) *keeps* the sphere, so culling fails safe. ``|d|`` clears the sign bit.

The array broadcasts each sphere to ``testers`` testers. With ``P = rows + cols`` planes
and ``P > testers`` it time-shares them: pass ``g`` (``0 .. G-1``, ``G = ceil(P/T)``)
gives tester ``k`` plane ``g*T + k`` (testers without a plane in the last pass are idle).
The decoder collects the flags into the row mask (bit ``k`` = row plane ``k``, planes
``0 .. rows-1``) and the column mask (bit ``k`` = column plane ``rows + k``).

Nothing here imports Amaranth.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from raplas_hdl.fp import FPFormat, check_format
from raplas_hdl.fp.fast import fast_add, fast_mul
from raplas_hdl.fp.kernels import add_int_k, lt_k, mul_int_k, rmode_code
from raplas_hdl.fp.numba_cache import drop_stale_cache
from raplas_hdl.parallel import run_chunks

drop_stale_cache(__file__)

__all__ = ["tester_flags", "plane_distances", "sphere_masks", "schedule", "n_passes",
           "pack_masks"]


@njit(cache=True)
def plane_exact(nx, ny, nz, p, cx, cy, cz, r, e, m, rmode):
    """One tester operation through the reference kernels: ``(d, keep, flags)``."""
    mx, f0 = mul_int_k(np.int64(nx), np.int64(cx), e, m, rmode)
    my, f1 = mul_int_k(np.int64(ny), np.int64(cy), e, m, rmode)
    mz, f2 = mul_int_k(np.int64(nz), np.int64(cz), e, m, rmode)
    s1, f3 = add_int_k(np.int64(mx), np.int64(my), e, m, rmode)
    s2, f4 = add_int_k(np.int64(mz), np.int64(p), e, m, rmode)
    d, f5 = add_int_k(np.int64(s1), np.int64(s2), e, m, rmode)
    sign = np.uint32(1) << np.uint32(e + m)
    keep = not lt_k(r, d & ~sign, e, m)
    return d, keep, f0 | f1 | f2 | f3 | f4 | f5


@njit(cache=True)
def plane_fast(nx, ny, nz, p, cx, cy, cz, r, E, M, R):
    """:func:`plane_exact` when its six operations take the flag-free fast path of
    :mod:`raplas_hdl.fp.fast`: ``d``, or -1 when the caller must run :func:`plane_exact`.
    Callers pass ``E, M, R`` as compile-time constants."""
    mx = fast_mul(np.int64(nx), np.int64(cx), E, M, R)
    my = fast_mul(np.int64(ny), np.int64(cy), E, M, R)
    mz = fast_mul(np.int64(nz), np.int64(cz), E, M, R)
    s1 = fast_add(mx, my, E, M, R)
    s2 = fast_add(mz, np.int64(p), E, M, R)
    d = fast_add(s1, s2, E, M, R)
    return d | ((mx | my | mz | s1 | s2) >> 63)


@njit(cache=True)
def plane_keep(nx, ny, nz, p, cx, cy, cz, r, E, M, R):
    """The tester's keep flag, ``NOT(|d| > r')``: the fast path, else the reference."""
    d = plane_fast(nx, ny, nz, p, cx, cy, cz, r, E, M, R)
    if d >= 0:
        return not lt_k(r, np.uint32(d & ((np.int64(1) << (E + M)) - 1)), E, M)
    return plane_exact(nx, ny, nz, p, cx, cy, cz, r, E, M, R)[1]


@njit(nogil=True, cache=True)
def _loop(n, p, c, r, lo, hi, d_out, keep_out, fl_out, e, m, rmode):
    """Every (sphere, plane) pair of spheres ``lo .. hi-1``: the fast path, else the
    reference; the format and the rounding are runtime arguments (one compile for all)."""
    sign = np.int64(1) << (e + m)
    for s in range(lo, hi):
        for k in range(n.shape[0]):
            d = plane_fast(n[k, 0], n[k, 1], n[k, 2], p[k], c[s, 0], c[s, 1], c[s, 2], r[s],
                           e, m, rmode)
            if d >= 0:
                d_out[s, k] = d
                keep_out[s, k] = not lt_k(r[s], np.uint32(d & (sign - 1)), e, m)
                fl_out[s, k] = 0
            else:
                d_out[s, k], keep_out[s, k], fl_out[s, k] = plane_exact(
                    n[k, 0], n[k, 1], n[k, 2], p[k], c[s, 0], c[s, 1], c[s, 2], r[s], e, m,
                    rmode)


def _as_bits(x, shape_tail, name, fmt):
    a = np.asarray(x)
    if a.dtype.kind not in "ui":
        raise ValueError(f"{name} must hold bit patterns (unsigned integers), not {a.dtype}")
    if a.ndim != len(shape_tail) + 1 or tuple(a.shape[1:]) != shape_tail:
        raise ValueError(f"{name} must have shape (N, {', '.join(map(str, shape_tail))})"
                         if shape_tail else f"{name} must have shape (N,), not {a.shape}")
    if a.size and (a.min() < 0 or int(a.max()) > fmt.mask):
        raise ValueError(f"{name} holds values wider than the format's {fmt.width} bits")
    return np.ascontiguousarray(a, dtype=np.uint32)


def _run(planes_n, planes_p, centres, radii, fmt: FPFormat):
    check_format(fmt)
    n = _as_bits(planes_n, (3,), "planes_n", fmt)
    p = _as_bits(planes_p, (), "planes_p", fmt)
    c = _as_bits(centres, (3,), "centres", fmt)
    r = _as_bits(radii, (), "radii", fmt)
    if n.shape[0] != p.shape[0]:
        raise ValueError(f"planes_n has {n.shape[0]} planes but planes_p {p.shape[0]}")
    if c.shape[0] != r.shape[0]:
        raise ValueError(f"centres has {c.shape[0]} spheres but radii {r.shape[0]}")
    shape = (c.shape[0], n.shape[0])
    d = np.empty(shape, np.uint32)
    keep = np.empty(shape, np.bool_)
    fl = np.empty(shape, np.uint8)
    key = (np.int64(fmt.exp_bits), np.int64(fmt.man_bits), np.int64(rmode_code(fmt)))
    run_chunks(c.shape[0], lambda lo, hi: _loop(n, p, c, r, lo, hi, d, keep, fl, *key),
               min_chunk=max(1, 8192 // max(1, n.shape[0])))
    return d, keep, fl


def tester_flags(planes_n, planes_p, centres, radii, fmt: FPFormat, flags: bool = False):
    """Flags of every (sphere, plane) pair: True keeps the sphere (``NOT(|d| > r')``).

    Parameters
    ----------
    planes_n : array of uint32, shape (P, 3)
    planes_p : array of uint32, shape (P,)
    centres : array of uint32, shape (S, 3)
    radii : array of uint32, shape (S,)
        The inflated radii ``r'`` (see :mod:`raplas_hdl.host.culling`).
    fmt : FPFormat
    flags : bool
        Also return the OR of the six operations' event flags, shape (S, P).

    Returns
    -------
    keep : ndarray of bool, shape (S, P)
    """
    _, keep, fl = _run(planes_n, planes_p, centres, radii, fmt)
    return (keep, fl) if flags else keep


def plane_distances(planes_n, planes_p, centres, fmt: FPFormat):
    """The computed ``d = n . C + p`` of every (sphere, plane) pair, bit patterns (S, P)."""
    zeros = np.zeros(np.asarray(centres).shape[0], np.uint32)
    d, _, _ = _run(planes_n, planes_p, centres, zeros, fmt)
    return d


def n_passes(rows: int, cols: int, testers: int) -> int:
    """Clocks per sphere of the array: ``ceil((rows + cols) / testers)``."""
    return math.ceil((rows + cols) / testers)


def schedule(rows: int, cols: int, testers: int) -> np.ndarray:
    """Plane ID that tester ``k`` tests in pass ``g``, shape (G, testers); -1 for none."""
    g = n_passes(rows, cols, testers)
    ids = np.arange(g * testers).reshape(g, testers)
    return np.where(ids < rows + cols, ids, -1)


def sphere_masks(planes_n, planes_p, centres, radii, rows: int, cols: int, fmt: FPFormat):
    """Row and column masks of a stream of spheres, as the array's decoder emits them.

    Parameters
    ----------
    planes_n : array of uint32, shape (rows+cols, 3)
        Plane normals in plane-ID order (rows first, then columns).
    planes_p : array of uint32, shape (rows+cols,)
    centres : array of uint32, shape (S, 3)
    radii : array of uint32, shape (S,)
        Inflated radii ``r'``.
    rows, cols : int
    fmt : FPFormat

    Returns
    -------
    row_mask : ndarray of bool, shape (S, rows)
        ``row_mask[s, k]``: sphere ``s`` touches row plane ``k``.
    col_mask : ndarray of bool, shape (S, cols)

    Raises
    ------
    ValueError
        When the plane count is not ``rows + cols`` or an array is mis-shaped.

    Notes
    -----
    Time-sharing changes when a flag is computed, not its value: every pass uses the
    same tester arithmetic, so the masks do not depend on ``testers``.
    """
    if np.asarray(planes_n).shape[0] != rows + cols:
        raise ValueError(f"expected rows+cols = {rows + cols} planes, got "
                         f"{np.asarray(planes_n).shape[0]}")
    keep = tester_flags(planes_n, planes_p, centres, radii, fmt)
    return keep[:, :rows], keep[:, rows:]


def pack_masks(row_mask, col_mask):
    """Masks as Python ints (bit ``k`` = plane ``k`` of its kind), one pair per sphere."""
    def pack(mask):
        weights = [1 << k for k in range(mask.shape[1])]
        return [sum(w for w, b in zip(weights, row) if b) for row in mask]
    return pack(np.asarray(row_mask)), pack(np.asarray(col_mask))
