"""References of the ray-triangle test: R (exact) and float64.

**R** is the reference of every accuracy claim: the Moller-Trumbore test in exact
arithmetic on the *original geometry* (the host's float64 vertices V0, V1, V2) and the
*encoded ray* (O and D as the unit sees them, decoded exactly). Every float64 value is an
integer times a power of two, so each pair is scaled to integers (Python ints) and
``T = V0 - O``, ``E1``, ``E2``, ``N = E1 x E2``, ``det = N.D``, ``t' = N.T``, ``Q = D x T``,
``u' = -(Q.E2)`` and ``v' = Q.E1`` are exact. R hits when ``det != 0`` and, for a positive
det, ``u' >= 0``, ``v' >= 0``, ``u' + v' <= det`` and ``t' >= 0`` (mirrored for a negative
det): the closed triangle, a ray that starts on it included.

The float64 reference runs the same formulas in float64 on the original geometry.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from ..fp.format import FPFormat
from ..fp.model import decode
from ..model.triangles import to_scaled_ints

__all__ = ["exact_intersect", "exact_intersect_bits", "exact_t", "float64_intersect"]


def _dot(a, b):
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def _cross(a, b):
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
                     a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def _ratio(num, den):
    out = np.full(num.shape, np.nan)
    for i in range(num.size):
        if den[i] != 0:
            out[i] = num[i] / den[i]          # int / int: correctly rounded
    return out


def _scaled(ints, scale):
    return np.array([math.ldexp(float(x), int(k)) for x, k in zip(ints, scale)])


def _exact_terms(o, d, v0, v1, v2):
    """R's exact ``det, t', u', v'`` (object arrays of Python ints, scaled by ``2**(3*k0)``
    per row) and ``k0``; None for no rows."""
    arrs = [np.asarray(x, dtype=np.float64) for x in (o, d, v0, v1, v2)]
    if any(a.ndim != 2 or a.shape[1] != 3 or a.shape != arrs[0].shape for a in arrs):
        raise ValueError("o, d, v0, v1 and v2 must all have the same shape (n, 3)")
    allv = np.concatenate(arrs, axis=1)
    if not np.isfinite(allv).all():
        raise ValueError("the exact reference needs finite rays and vertices")
    if allv.shape[0] == 0:
        return None
    ints, k0 = to_scaled_ints(allv)
    oi, di, a, b, c = (ints[:, 3 * k:3 * k + 3] for k in range(5))
    t = a - oi
    e1, e2 = b - a, c - a
    n = _cross(e1, e2)
    q = _cross(di, t)
    return _dot(n, di), _dot(n, t), -_dot(q, e2), _dot(q, e1), k0


def _exact_hits(det, tp, up, vp) -> np.ndarray:
    """R's decision from its exact terms (module docstring)."""
    return np.array([(dt > 0 and u >= 0 and v >= 0 and u + v <= dt and tt >= 0)
                     or (dt < 0 and u <= 0 and v <= 0 and u + v >= dt and tt <= 0)
                     for u, v, dt, tt in zip(up, vp, det, tp)], dtype=bool)


def exact_t(o, d, v0, v1, v2) -> tuple[np.ndarray, list]:
    """R's hit and its exact ``t = t'/det`` per pair (arguments as :func:`exact_intersect`).

    Returns
    -------
    hit : ndarray (n,) bool
    t : list of :class:`fractions.Fraction` or None
        ``t'/det`` exactly where R hits, None where it misses.
    """
    terms = _exact_terms(o, d, v0, v1, v2)
    if terms is None:
        return np.zeros(0, bool), []
    det, tp, up, vp, _ = terms
    hit = _exact_hits(det, tp, up, vp)
    return hit, [Fraction(int(a), int(b)) if h else None for a, b, h in zip(tp, det, hit)]


def exact_intersect(o, d, v0, v1, v2, values: bool = False) -> dict:
    """Exact ray-triangle test of float64 rays against float64 triangles (pairwise).

    Parameters
    ----------
    o, d : array_like of float64, shape (n, 3)
        Ray origin and direction (pass the *decoded encoded* ray for R).
    v0, v1, v2 : array_like of float64, shape (n, 3)
        Original vertices. All values finite.
    values : bool
        Also return R's ``det``, ``tp`` (t'), ``up`` (u'), ``vp`` (v') and
        ``wp = det - u' - v'``, each exact then rounded once to float64.

    Returns
    -------
    dict
        ``hit`` (bool), ``det_sign`` (int8: -1, 0, 1), and ``t``, ``u``, ``v``
        (``t'/det``, ``u'/det``, ``v'/det`` correctly rounded to float64; NaN where det is 0).

    Raises
    ------
    ValueError
        On shapes that differ or non-finite values.
    """
    terms = _exact_terms(o, d, v0, v1, v2)
    if terms is None:
        z = np.zeros(0)
        return {"hit": z.astype(bool), "det_sign": z.astype(np.int8), "t": z, "u": z, "v": z}
    det, tp, up, vp, k0 = terms
    sign = np.array([(x > 0) - (x < 0) for x in det], dtype=np.int8)
    hit = _exact_hits(det, tp, up, vp)
    out = {"hit": hit, "det_sign": sign, "t": _ratio(tp, det), "u": _ratio(up, det),
           "v": _ratio(vp, det)}
    if values:
        k3 = 3 * k0
        out.update(det=_scaled(det, k3), tp=_scaled(tp, k3), up=_scaled(up, k3),
                   vp=_scaled(vp, k3), wp=_scaled(det - up - vp, k3))
    return out


def exact_intersect_bits(o_bits, d_bits, v0, v1, v2, fmt: FPFormat,
                         values: bool = False) -> dict:
    """R: :func:`exact_intersect` with the encoded ray (bit patterns of ``fmt``)."""
    return exact_intersect(decode(np.asarray(o_bits), fmt), decode(np.asarray(d_bits), fmt),
                           v0, v1, v2, values=values)


def float64_intersect(o, d, v0, v1, v2) -> dict:
    """The same test in float64 (no quantisation of the geometry).

    Returns
    -------
    dict
        ``hit`` (bool), ``det``, ``t``, ``u``, ``v`` (float64; ``t = t'/det`` etc.).
    """
    o, d, v0, v1, v2 = (np.asarray(x, dtype=np.float64) for x in (o, d, v0, v1, v2))
    e1, e2 = v1 - v0, v2 - v0
    n = _cross(e1, e2)           # the same products as np.cross, without its overhead
    t = v0 - o
    det = _dot(n, d)
    tp = _dot(n, t)
    q = _cross(d, t)
    up = -_dot(q, e2)
    vp = _dot(q, e1)
    s = up + vp
    with np.errstate(divide="ignore", invalid="ignore"):
        pos = (up >= 0) & (vp >= 0) & (s <= det) & (tp >= 0)
        neg = (up <= 0) & (vp <= 0) & (s >= det) & (tp <= 0)
        hit = ((det > 0) & pos) | ((det < 0) & neg)
        return {"hit": hit, "det": det, "t": tp / det, "u": up / det, "v": vp / det}
