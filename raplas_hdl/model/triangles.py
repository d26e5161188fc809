"""Triangle records for Triangle Memory: V0, E1 = V1 - V0, E2 = V2 - V0 and N = E1 x E2.

The host's float64 vertices (after the load normalisation of raplas.md, "Coordinates")
are the *original geometry*. E1, E2 and N are formed from them exactly (integer arithmetic
on the float64 significands), rounded once to float64 and then encoded, so every
component of the record is within one rounding of the exact value (the conservative
margin relies on that, see :mod:`raplas_hdl.model.conservative`).

Bad triangles are never passed on silently. With ``on_bad="raise"`` the first one raises
:class:`ValueError` naming the problem; with ``on_bad="skip"`` they are left out, and the
result counts them by reason and lists their indices:

``nonfinite``     a NaN or infinite coordinate;
``degenerate``    zero area (repeated vertices, collinear vertices: exact ``N = 0``);
``flushed``       the encoded ``N`` is zero (the area is below the format's range);
``out_of_domain`` a coordinate beyond the format's domain or an edge shorter than its
                  minimum edge (``raplas_hdl.model.conservative.domain``); such triangles
                  are only dropped when ``check_domain=True``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..fp.format import FPFormat
from ..fp.model import encode
from .conservative import domain

__all__ = ["TriangleRecords", "make_triangles", "exact_edges", "to_scaled_ints", "REASONS"]

REASONS = ("nonfinite", "degenerate", "flushed", "out_of_domain")


def to_scaled_ints(x: np.ndarray):
    """Exact integer form of float64 rows: ``x[i, j] == ints[i, j] * 2**k0[i]``.

    Parameters
    ----------
    x : ndarray of float64, shape (n, k)
        Finite values.

    Returns
    -------
    ints : ndarray of object (Python ints), shape (n, k)
    k0 : ndarray of int64, shape (n,)
    """
    x = np.asarray(x, dtype=np.float64)
    mant, ex = np.frexp(x)
    im = (mant * 2.0 ** 53).astype(np.int64)
    e = ex.astype(np.int64) - 53
    e_nz = np.where(im != 0, e, np.iinfo(np.int64).max)
    k0 = e_nz.min(axis=1)
    k0 = np.where(k0 == np.iinfo(np.int64).max, 0, k0)
    shift = np.where(im != 0, e - k0[:, None], 0)
    ints = im.astype(object) << shift.astype(object)
    return ints, k0


def _cross(a, b):
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
                     a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def _to_float(ints, scale):
    out = np.empty(ints.shape, dtype=np.float64)
    flat_i, flat_o = ints.reshape(-1), out.reshape(-1)
    sc = np.broadcast_to(scale[:, None], ints.shape).reshape(-1)
    for k in range(flat_i.size):
        try:
            flat_o[k] = math.ldexp(float(flat_i[k]), int(sc[k]))
        except OverflowError:
            flat_o[k] = math.inf if flat_i[k] > 0 else -math.inf
    return out


def exact_edges(v0, v1, v2):
    """E1, E2 and N = E1 x E2 of float64 vertices, each exact then rounded once to float64.

    Returns
    -------
    e1, e2, n : ndarray of float64, shape (n, 3)
    n_zero : ndarray of bool
        The exact N is zero (degenerate triangle).
    """
    ints, k0 = to_scaled_ints(np.concatenate([v0, v1, v2], axis=1))
    a, b, c = ints[:, 0:3], ints[:, 3:6], ints[:, 6:9]
    e1i, e2i = b - a, c - a
    ni = _cross(e1i, e2i)
    n_zero = np.array([all(x == 0 for x in row) for row in ni], dtype=bool)
    return _to_float(e1i, k0), _to_float(e2i, k0), _to_float(ni, 2 * k0), n_zero


@dataclass
class TriangleRecords:
    """Encoded triangle records and what was left out.

    Attributes
    ----------
    fmt : FPFormat
    ids : ndarray of int64
        Index (in the input) of each kept triangle: the triangle ID.
    v0, v1, v2 : ndarray of float64, shape (k, 3)
        The original geometry of the kept triangles (what the exact reference uses).
    v0_bits, e1_bits, e2_bits, n_bits : ndarray of uint32, shape (k, 3)
        The record as Triangle Memory holds it.
    skipped : dict
        Reason -> number of triangles left out (every reason present, 0 when none).
    skipped_ids : dict
        Reason -> indices of the triangles left out.
    """

    fmt: FPFormat
    ids: np.ndarray
    v0: np.ndarray
    v1: np.ndarray
    v2: np.ndarray
    v0_bits: np.ndarray
    e1_bits: np.ndarray
    e2_bits: np.ndarray
    n_bits: np.ndarray
    skipped: dict = field(default_factory=dict)
    skipped_ids: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.ids)

    @property
    def n_skipped(self) -> int:
        return sum(self.skipped.values())


def make_triangles(vertices, fmt: FPFormat, *, on_bad: str = "raise",
                   check_domain: bool = False, max_coord: float | None = None
                   ) -> TriangleRecords:
    """Build encoded triangle records from vertices.

    Parameters
    ----------
    vertices : array_like of float, shape (k, 3, 3)
        ``vertices[i]`` is ``(V0, V1, V2)`` of triangle ``i`` in scene coordinates.
    fmt : FPFormat
        The format of Triangle Memory.
    on_bad : {"raise", "skip"}
        Raise on the first bad triangle, or leave bad triangles out and count them.
    check_domain : bool
        Also treat triangles outside the format's domain as bad (``out_of_domain``).
    max_coord : float, optional
        Also treat triangles with a coordinate beyond this bound as ``out_of_domain`` (the
        certified mode's domain, which has no minimum edge).

    Raises
    ------
    ValueError
        For a wrong shape or option, or (``on_bad="raise"``) a bad triangle, naming it and
        the reason.
    """
    if on_bad not in ("raise", "skip"):
        raise ValueError(f"on_bad must be 'raise' or 'skip', not {on_bad!r}")
    vs = np.asarray(vertices, dtype=np.float64)
    if vs.ndim != 3 or vs.shape[1:] != (3, 3):
        raise ValueError(f"vertices must have shape (k, 3, 3), not {vs.shape}")
    k = vs.shape[0]
    reason = np.full(k, "", dtype=object)
    finite = np.isfinite(vs).all(axis=(1, 2))
    reason[~finite] = "nonfinite"
    safe = np.where(finite[:, None, None], vs, 0.0)
    e1, e2, n, n_zero = exact_edges(safe[:, 0], safe[:, 1], safe[:, 2])
    reason[(reason == "") & n_zero] = "degenerate"
    n_bits = encode(n, fmt)
    flushed = ((n_bits.astype(np.int64) >> fmt.man_bits) & fmt.exp_max_field == 0).all(axis=1)
    reason[(reason == "") & flushed] = "flushed"
    if check_domain:
        dom = domain(fmt)
        too_far = (np.abs(safe) > dom.max_coord).any(axis=(1, 2))
        e3 = safe[:, 2] - safe[:, 1]
        edges = np.stack([np.linalg.norm(x, axis=1) for x in (e1, e2, e3)], axis=1)
        short = (edges < dom.min_edge).any(axis=1)
        reason[(reason == "") & (too_far | short)] = "out_of_domain"
    if max_coord is not None:
        reason[(reason == "") & (np.abs(safe) > max_coord).any(axis=(1, 2))] = "out_of_domain"
    bad = reason != ""
    if on_bad == "raise" and bad.any():
        i = int(np.flatnonzero(bad)[0])
        words = {"nonfinite": "has a NaN or infinite coordinate",
                 "degenerate": "is degenerate (zero area: repeated or collinear vertices)",
                 "flushed": f"has an area too small for {fmt.name} (N encodes as zero)",
                 "out_of_domain": f"is outside the domain of {fmt.name} (coordinates beyond "
                                  f"{domain(fmt).max_coord:g} or an edge shorter than "
                                  f"{domain(fmt).min_edge:g})"}
        raise ValueError(f"triangle {i} {words[reason[i]]}")
    keep = ~bad
    return TriangleRecords(
        fmt=fmt, ids=np.flatnonzero(keep).astype(np.int64),
        v0=vs[keep, 0].copy(), v1=vs[keep, 1].copy(), v2=vs[keep, 2].copy(),
        v0_bits=encode(vs[keep, 0], fmt), e1_bits=encode(e1[keep], fmt),
        e2_bits=encode(e2[keep], fmt), n_bits=n_bits[keep],
        skipped={r: int((reason == r).sum()) for r in REASONS},
        skipped_ids={r: np.flatnonzero(reason == r) for r in REASONS})
