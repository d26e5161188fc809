"""Shading: nearest-hit selection, Phong lighting, and soft shadows as ray bundles.

Nearest hit (:func:`nearest_hits`): of a ray's hits, only those with
``tmin <= t <= tmax`` count (a shadow ray also ignores its own triangle); the smallest
``t`` wins and equal ``t`` goes to the lowest triangle ID, so the choice does not depend
on the order of the unit's stream.

Lighting (the local model of the CPU ray-tracing seed, section 3.2.3)::

    I = ka * albedo * light  +  vis * light * (kd * albedo * max(0, N.L) + ks * max(0, R.V)^n)

with ``N`` the triangle's geometric normal turned towards the viewer, ``L`` the unit vector
to the light's centre, ``R = 2 (N.L) N - L`` the mirror direction, ``V`` the unit vector to
the eye, and ``vis`` the fraction of the light's lattice that the point sees.

Soft shadows (:func:`shadow_bundles`): from each shading point, one bundle to the
``rows`` x ``cols`` lattice of cell centres on the area light (the bundle's virtual screen
*is* the light). The origin is lifted off the surface by ``eps`` along the normal.
Shading points that get no bundle are counted, not errors:

- ``behind_light``: on or behind the light's plane (the light does not shine there, and
  the bundle would be degenerate);
- ``facing_away``: the surface faces away from the light's centre (``N.L <= 0``: no
  diffuse or specular term to shadow).

A shadow ray is blocked by a hit with ``eps <= t <= |P - X| - eps`` (``X`` its lattice
point: anything beyond the light does not shadow) on a triangle other than the point's
own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.bundles import RayBundle, bundle_geometry
from .scene import AreaLight, Material

__all__ = [
    "ShadowPlan",
    "blocked_rays",
    "face_normals",
    "light_hits",
    "nearest_hits",
    "phong",
    "shadow_bundles",
]


def face_normals(tris: np.ndarray) -> np.ndarray:
    """Unit geometric normals ``unit((V1-V0) x (V2-V0))`` (zero for degenerate ones)."""
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ln > 0, n / np.where(ln > 0, ln, 1.0), 0.0)


def nearest_hits(n_rays: int, ray_id, tri_id, hit, t, tmin=0.0, tmax=np.inf,
                 exclude_tri=None):
    """The nearest valid hit of every ray.

    Parameters
    ----------
    n_rays : int
    ray_id, tri_id : int arrays
        Pairs (any order).
    hit : bool array
    t : float array
        Hit distances (NaN where not a hit).
    tmin, tmax : float or per-ray array
        Accepted interval (inclusive).
    exclude_tri : int or per-ray array, optional
        A triangle ID to ignore per ray (-1: none).

    Returns
    -------
    tri : ndarray (n_rays,) int64
        Nearest triangle, -1 for none.
    t : ndarray (n_rays,) float64
        Its distance, ``inf`` for none.
    index : ndarray (n_rays,) int64
        Position of the winning pair in the input, -1 for none.
    """
    ray_id = np.asarray(ray_id, np.int64)
    tri_id = np.asarray(tri_id, np.int64)
    t = np.asarray(t, np.float64)
    ok = np.asarray(hit, bool) & np.isfinite(t)
    lo = np.broadcast_to(np.asarray(tmin, np.float64), (n_rays,))
    hi = np.broadcast_to(np.asarray(tmax, np.float64), (n_rays,))
    with np.errstate(invalid="ignore"):
        ok &= (t >= lo[ray_id]) & (t <= hi[ray_id])
    if exclude_tri is not None:
        ex = np.broadcast_to(np.asarray(exclude_tri, np.int64), (n_rays,))
        ok &= tri_id != ex[ray_id]
    idx = np.flatnonzero(ok)
    best_tri = np.full(n_rays, -1, np.int64)
    best_t = np.full(n_rays, np.inf)
    best_i = np.full(n_rays, -1, np.int64)
    if idx.size:
        order = idx[np.lexsort((tri_id[idx], t[idx], ray_id[idx]))]
        first = np.ones(order.size, bool)
        first[1:] = ray_id[order[1:]] != ray_id[order[:-1]]
        win = order[first]
        best_tri[ray_id[win]] = tri_id[win]
        best_t[ray_id[win]] = t[win]
        best_i[ray_id[win]] = win
    return best_tri, best_t, best_i


def phong(points, normals, albedo, eye, light: AreaLight, material: Material, visibility,
          ambient=None):
    """Phong colour of shading points.

    Parameters
    ----------
    points, normals, albedo : ndarray (n, 3)
        ``normals`` unit, facing the viewer.
    eye : ndarray (3,) or (n, 3)
        The eye, or per point the origin of the ray that found it.
    light : AreaLight
    material : Material
        Constants shared by every point, or one value per point in each field
        (:meth:`Scene.material_at <raplas_hdl.host.scene.Scene.material_at>`).
    visibility : ndarray (n,)
        Fraction of the light seen (1: unshadowed).
    ambient : ndarray (n,), optional
        Scale of the ambient term (ambient occlusion's unoccluded fraction; default 1).

    Returns
    -------
    ndarray (n, 3) float64 (linear, not clipped)
    """
    lc = np.asarray(light.colour, float)
    L = light.centre - points
    L /= np.linalg.norm(L, axis=1, keepdims=True)
    V = eye - points
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    ndl = np.einsum("ij,ij->i", normals, L)
    R = 2.0 * ndl[:, None] * normals - L
    rdv = np.clip(np.einsum("ij,ij->i", R, V), 0.0, None)
    ka, kd, ks = (np.asarray(k, float)[..., None]      # scalar or per point: (1,) or (n, 1)
                  for k in (material.ambient, material.diffuse, material.specular))
    n = np.asarray(material.shininess, float)
    diffuse = kd * albedo * np.clip(ndl, 0.0, None)[:, None]
    spec = ks * np.where(ndl > 0, rdv ** n, 0.0)[:, None]
    direct = (diffuse + spec) * np.asarray(visibility, float)[:, None]
    amb = ka * albedo if ambient is None else ka * albedo * np.asarray(ambient, float)[:, None]
    return (amb + direct) * lc


def light_hits(origins, dirs, light: AreaLight, t_hit) -> np.ndarray:
    """Rays that see the area light before their hit (host-only, float64): the light's
    parallelogram, crossed from its lit side at ``0 < t < t_hit``.

    ``origins`` (3,) or (n, 3), ``dirs`` (n, 3), ``t_hit`` (n,) (``inf``: no hit).
    """
    n = light.normal
    c = np.asarray(light.corner, float)
    u, v = np.asarray(light.edge_u, float), np.asarray(light.edge_v, float)
    dn = dirs @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((c - origins) @ n) / dn
    p = origins + t[:, None] * dirs - c
    a = (p @ u) / (u @ u)
    b = (p @ v) / (v @ v)
    return (dn < 0) & (t > 0) & (t < t_hit) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)


@dataclass
class ShadowPlan:
    """Shadow bundles of a set of shading points, as arrays (one pass).

    Attributes
    ----------
    point : ndarray (k,) int64
        Index (into the caller's shading points) of each bundle.
    origins : ndarray (k, 3)
        Bundle origins ``P + eps N``.
    centre, col_axis, row_axis : ndarray (3,)
        The light's screen, shared by every bundle.
    rows, cols : int
    tmax : ndarray (k, rows*cols)
        Per ray: distance to its lattice point minus ``eps``.
    behind_light, facing_away : int
        Shading points that got no bundle, by reason.
    """

    point: np.ndarray
    origins: np.ndarray
    centre: np.ndarray
    col_axis: np.ndarray
    row_axis: np.ndarray
    rows: int
    cols: int
    tmax: np.ndarray
    behind_light: int
    facing_away: int

    def __len__(self) -> int:
        return len(self.point)

    @property
    def bundles(self) -> list:
        """The bundles as :class:`~raplas_hdl.model.bundles.RayBundle` objects (one per
        point; for inspection, the renderer uses the arrays)."""
        return [RayBundle(o, self.centre, self.col_axis, self.row_axis, self.rows, self.cols)
                for o in self.origins]


def shadow_bundles(points, normals, light: AreaLight, rows: int, cols: int,
                   eps: float) -> ShadowPlan:
    """One ``rows`` x ``cols`` bundle per shading point towards the light's lattice.

    ``normals`` are unit normals facing the viewer; the origin is ``P + eps * N``. Points
    behind the light's plane (or numerically on it) and points facing away get none.
    """
    points = np.asarray(points, float).reshape(-1, 3)
    normals = np.asarray(normals, float).reshape(-1, 3)
    ln = light.normal
    lc = np.asarray(light.centre, float)
    origins = points + eps * normals
    in_front = (origins - lc) @ ln > 0.0
    facing = np.einsum("ij,ij->i", normals, lc - points) > 0.0
    want = np.flatnonzero(in_front & facing)
    behind = int(np.count_nonzero(~in_front))
    away = int(np.count_nonzero(in_front & ~facing))
    col_axis = 0.5 * np.asarray(light.edge_v, float)
    row_axis = 0.5 * np.asarray(light.edge_u, float)
    k = want.size
    g = bundle_geometry(origins[want], np.broadcast_to(lc, (k, 3)),
                        np.broadcast_to(col_axis, (k, 3)), np.broadcast_to(row_axis, (k, 3)),
                        rows, cols)
    ok = ~g["degenerate"] & g["finite"]
    behind += int(np.count_nonzero(~ok))      # numerically on the light's plane
    idx = want[ok]
    rel = g["points"][ok].reshape(-1, rows * cols, 3) - origins[idx][:, None, :]
    tmax = np.linalg.norm(rel, axis=2) - eps
    return ShadowPlan(idx.astype(np.int64), origins[idx], lc, col_axis, row_axis, rows, cols,
                      tmax, behind, away)


def blocked_rays(n_rays: int, ray_id, tri_id, hit, t, eps: float, tmax, own_tri: int):
    """Rays of one shadow bundle that some pair blocks (bool (n_rays,))."""
    tri, _, _ = nearest_hits(n_rays, ray_id, tri_id, hit, t, eps, tmax, own_tri)
    return tri >= 0
