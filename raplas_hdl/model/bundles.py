"""Ray bundles and their row and column planes: the bundle the unit takes (NumPy).

A bundle is an origin ``O`` and a ``rows`` x ``cols`` lattice on a virtual screen with
centre ``S`` and two axis vectors: ``col_axis`` (``a``, along a row, from column to
column) and ``row_axis`` (``b``, from row to row). Both are *half extents*: lattice point
``(i, j)`` is ::

    P[i, j] = S + x_j * a + y_i * b,   x_j = (2j + 1)/cols - 1,   y_i = (2i + 1)/rows - 1

(pixel centres of a ``rows`` x ``cols`` tile spanning ``S +- a +- b``). Ray ``(i, j)``
runs from ``O`` through ``P[i, j]``; its ID is ``i*cols + j``.

Row plane ``i`` holds ``O`` and every lattice point of row ``i``: its normal is
``(P[i, 0] - O) x a`` normalised; column plane ``j`` holds ``O`` and column ``j``:
normal ``(P[0, j] - O) x b`` normalised. A plane is ``n . x + p = 0`` with ``|n| = 1``.
Plane IDs: rows ``0 .. rows-1`` first, then columns ``rows .. rows+cols-1``. Ray ``(i, j)``
is the line where row plane ``i`` meets column plane ``j``.

Encoding (all coordinates are the host's normalised scene coordinates, raplas.md
"Coordinates"):

- ``O`` and the unit directions ``D`` with the format's rounding;
- the normals *toward zero* (each component's magnitude never grows), so that
  ``|n_enc| <= |n| = 1``: the plane test never scales a sphere's distance up;
- the offsets from the *encoded* normal and origin: ``p = -(n_enc . O_enc)`` in float64
  (nearly exact: the products are exact for ``man_bits <= 25``), then encoded with the
  format's rounding, so the encoded plane misses the encoded origin by at most about
  one rounding of ``p``. :mod:`raplas_hdl.host.culling` accounts for what is left.

Nothing here imports Amaranth.
"""

from __future__ import annotations

import numpy as np

from raplas_hdl.fp import FPFormat
from raplas_hdl.fp import model as fpm

from .records import PLANE

__all__ = ["RayBundle", "bundle_geometry", "encode_toward_zero", "encode_bundle_arrays",
           "encode_bundles", "vec3"]

#: A bundle whose origin is closer to the screen plane than this fraction of the
#: screen's size (or whose axes are closer to parallel than this sine) is degenerate.
_DEGENERATE_REL = 1e-9


def encode_toward_zero(x, fmt: FPFormat) -> np.ndarray:
    """Encode float64 values rounding toward zero (magnitudes never grow)."""
    x = np.asarray(x, dtype=np.float64)
    up = fpm.encode(x, fmt, direction="up")
    down = fpm.encode(x, fmt, direction="down")
    return np.where(x < 0, up, down).astype(np.uint32)


def vec3(name, value) -> np.ndarray:
    """``value`` as a finite float64 3-vector, else ``ValueError`` naming ``name``."""
    v = np.asarray(value, dtype=np.float64)
    if v.shape != (3,):
        raise ValueError(f"{name} must be a 3-vector, not shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite (no NaN or inf), not {v.tolist()}")
    return v


def _normalise(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


class RayBundle:
    """A ``rows`` x ``cols`` bundle of rays from one origin through a virtual screen.

    Parameters
    ----------
    origin : array_like, shape (3,)
        The common origin ``O``.
    centre : array_like, shape (3,)
        Centre ``S`` of the virtual screen.
    col_axis : array_like, shape (3,)
        Half-extent vector ``a`` of the screen along a row (column direction).
    row_axis : array_like, shape (3,)
        Half-extent vector ``b`` of the screen across rows.
    rows, cols : int
        Lattice size, each at least 1.

    Attributes
    ----------
    rows, cols : int
    n_planes : int
        ``rows + cols``.
    points : ndarray, shape (rows, cols, 3)
        Lattice points (float64).
    directions : ndarray, shape (rows*cols, 3)
        Unit ray directions in ray-ID order (float64).
    plane_n : ndarray, shape (rows+cols, 3)
        Unit plane normals in plane-ID order (float64).
    plane_p : ndarray, shape (rows+cols,)
        Plane offsets ``-n . O`` (float64).

    Raises
    ------
    ValueError
        Naming the problem: a size below 1 or not an integer, a non-finite or mis-shaped
        vector, a zero-length axis, parallel axes, or an origin on the screen plane.
    """

    def __init__(self, origin, centre, col_axis, row_axis, rows: int, cols: int):
        for name, value in (("rows", rows), ("cols", cols)):
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool):
                raise ValueError(f"{name} must be an integer, not {value!r}")
            if value < 1:
                raise ValueError(f"{name} must be at least 1, not {value}")
        self.rows, self.cols = int(rows), int(cols)
        self.origin = vec3("origin", origin)
        self.centre = vec3("centre", centre)
        a = self.col_axis = vec3("col_axis", col_axis)
        b = self.row_axis = vec3("row_axis", row_axis)
        la, lb = np.linalg.norm(a), np.linalg.norm(b)
        if la == 0.0:
            raise ValueError("col_axis has zero length")
        if lb == 0.0:
            raise ValueError("row_axis has zero length")
        normal = np.cross(a, b)
        if np.linalg.norm(normal) <= _DEGENERATE_REL * la * lb:
            raise ValueError("col_axis and row_axis are parallel: the screen has no area")
        unit = normal / np.linalg.norm(normal)
        height = abs(float(np.dot(self.origin - self.centre, unit)))
        if height <= _DEGENERATE_REL * max(la, lb):
            raise ValueError("the origin lies on the screen plane: the rays would not span "
                             "a bundle")
        g = bundle_geometry(self.origin[None], self.centre[None], a[None], b[None], self.rows,
                            self.cols)
        self.points = g["points"][0]
        self.directions = g["directions"][0]
        self.plane_n = g["plane_n"][0]
        self.plane_p = g["plane_p"][0]
        if not g["finite"][0]:
            raise ValueError("the bundle's geometry overflows float64")

    # ------------------------------------------------------------------------------
    @property
    def n_planes(self) -> int:
        return self.rows + self.cols

    @property
    def n_rays(self) -> int:
        return self.rows * self.cols

    def ray_id(self, i, j):
        """ID of ray ``(i, j)``: ``i*cols + j``."""
        return np.asarray(i) * self.cols + np.asarray(j)

    def ray_planes(self):
        """Row-plane and column-plane IDs of every ray, in ray-ID order."""
        ids = np.arange(self.n_rays)
        return ids // self.cols, self.rows + ids % self.cols

    def encode_planes(self, fmt: FPFormat):
        """The planes as bit patterns.

        Returns
        -------
        n : ndarray of uint32, shape (rows+cols, 3)
            Normals, encoded toward zero.
        p : ndarray of uint32, shape (rows+cols,)
            Offsets ``-(n_enc . O_enc)`` (float64) encoded with the format's rounding.
        """
        n, p, _, _ = encode_bundles([self], fmt)[0]
        return n, p

    def encode_rays(self, fmt: FPFormat):
        """The rays as bit patterns: origin (3,) and directions (rows*cols, 3), in ID order."""
        _, _, o, d = encode_bundles([self], fmt)[0]
        return o, d

    def pack_planes(self, fmt: FPFormat) -> list:
        """Plane words for the array's write port, in plane-ID order (Python ints): the
        record :data:`raplas_hdl.model.records.PLANE` (``nx | ny<<W | nz<<2W | p<<3W``)."""
        n, p = self.encode_planes(fmt)
        return PLANE.bind(fmt).pack({"nx": n[:, 0], "ny": n[:, 1], "nz": n[:, 2], "p": p})

    def __repr__(self):
        return (f"RayBundle(rows={self.rows}, cols={self.cols}, origin={self.origin.tolist()}, "
                f"centre={self.centre.tolist()})")


def bundle_geometry(origins, centres, col_axes, row_axes, rows: int, cols: int) -> dict:
    """The float64 geometry of ``B`` bundles of one size at once (module docstring).

    Parameters
    ----------
    origins, centres, col_axes, row_axes : array_like, shape (B, 3)
    rows, cols : int

    Returns
    -------
    dict
        ``points`` (B, rows, cols, 3), ``directions`` (B, rows*cols, 3) unit vectors in
        ray-ID order, ``plane_n`` (B, rows+cols, 3) unit normals in plane-ID order,
        ``plane_p`` (B, rows+cols) offsets ``-n . O``, ``finite`` (B,) bool (False where
        the geometry overflows float64), ``degenerate`` (B,) bool (parallel axes, or the
        origin on the screen plane: :class:`RayBundle` refuses these).
    """
    o = np.asarray(origins, np.float64)
    c = np.asarray(centres, np.float64)
    a = np.asarray(col_axes, np.float64)
    b = np.asarray(row_axes, np.float64)
    x = (2.0 * np.arange(cols) + 1.0) / cols - 1.0
    y = (2.0 * np.arange(rows) + 1.0) / rows - 1.0
    points = (c[:, None, None, :] + x[None, None, :, None] * a[:, None, None, :]
              + y[None, :, None, None] * b[:, None, None, :])
    rel = points - o[:, None, None, :]
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        directions = _normalise(rel.reshape(len(o), rows * cols, 3))
        row_n = _normalise(np.cross(rel[:, :, 0, :], a[:, None, :]))
        col_n = _normalise(np.cross(rel[:, 0, :, :], b[:, None, :]))
        plane_n = np.concatenate([row_n, col_n], axis=1)
        plane_p = -np.einsum("bpk,bk->bp", plane_n, o)
        la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
        normal = np.cross(a, b)
        ln = np.linalg.norm(normal, axis=1)
        unit = normal / np.where(ln > 0, ln, 1.0)[:, None]
        height = np.abs(np.einsum("bk,bk->b", o - c, unit))
    degenerate = ((la == 0) | (lb == 0) | (ln <= _DEGENERATE_REL * la * lb)
                  | (height <= _DEGENERATE_REL * np.maximum(la, lb)))
    finite = (np.isfinite(directions).all(axis=(1, 2)) & np.isfinite(plane_n).all(axis=(1, 2)))
    return {"points": points, "directions": directions, "plane_n": plane_n, "plane_p": plane_p,
            "finite": finite, "degenerate": degenerate}


def encode_bundle_arrays(origins, plane_n, directions, fmt: FPFormat):
    """Encode ``B`` bundles of one size given as arrays (:func:`bundle_geometry`).

    Returns
    -------
    n : ndarray of uint32, shape (B, P, 3)
        Normals, encoded toward zero.
    p : ndarray of uint32, shape (B, P)
        Offsets ``-(n_enc . O_enc)`` (float64) encoded with the format's rounding.
    o : ndarray of uint32, shape (B, 3)
    d : ndarray of uint32, shape (B, R, 3)
    """
    n = encode_toward_zero(plane_n, fmt)
    o = fpm.encode(np.asarray(origins, np.float64), fmt)
    p = fpm.encode(-np.sum(fpm.decode(n, fmt) * fpm.decode(o, fmt)[:, None, :], axis=2), fmt)
    d = fpm.encode(directions, fmt)
    return n, p, o, d


def encode_bundles(bundles, fmt: FPFormat):
    """Encode many bundles at once (a few array calls for all of them).

    Returns
    -------
    list of (n, p, o, d)
        Per bundle: plane normals (P, 3) and offsets (P,) as :meth:`RayBundle.encode_planes`
        makes them, the origin (3,) and the directions (rows*cols, 3), all ``uint32``.
    """
    bundles = list(bundles)
    if not bundles:
        return []
    planes = np.array([b.n_planes for b in bundles])
    rays = np.array([b.n_rays for b in bundles])
    n = encode_toward_zero(np.concatenate([b.plane_n for b in bundles]), fmt)
    o = fpm.encode(np.array([b.origin for b in bundles]), fmt)
    o_rep = np.repeat(fpm.decode(o, fmt), planes, axis=0)
    p = fpm.encode(-np.sum(fpm.decode(n, fmt) * o_rep, axis=1), fmt)
    d = fpm.encode(np.concatenate([b.directions for b in bundles]), fmt)
    p_at, r_at = np.cumsum(planes)[:-1], np.cumsum(rays)[:-1]
    return list(zip(np.split(n, p_at), np.split(p, p_at), o, np.split(d, r_at)))
