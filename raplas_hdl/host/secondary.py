"""Secondary rays: mirror reflection, refraction, glossy reflection and ambient occlusion,
as whole passes of bundles (docs/secondary-rays.md).

Every ray here goes to the accelerator through
:func:`~raplas_hdl.host.tracing.nearest_pass` or
:func:`~raplas_hdl.host.tracing.any_hit_pass`, a generation at a time, never a bundle at a
time.

Whitted recursion (:func:`whitted`). Generation 0 is the primary shading points; the
points of generation ``k < depth`` spawn

- a **reflection** ray, ``R = I - 2 N (N.I)``, with weight ``w * reflectivity``;
- a **refraction** ray by Snell's law with weight ``w * transparency``. The side is read
  from the sign of ``N.I`` (``N`` the triangle's geometric normal, meshes wound outwards):
  ``N.I < 0`` enters the material (``eta = 1/ior``), otherwise it leaves it
  (``eta = ior``). With ``c = -n.I`` (``n`` the normal facing ``I``) and
  ``k = 1 - eta^2 (1 - c^2)``: ``T = eta I + (eta c - sqrt(k)) n``; ``k < 0`` is total
  internal reflection: no refraction ray, its weight goes to the reflection ray.

Each is a 1x1 bundle of its own: origin ``P + eps n`` (reflection) or ``P - eps n``
(refraction), ``tmin = eps``, its own triangle excluded; its screen is centred on
``O + D`` with half-extent axes of length 1 perpendicular to ``D`` (the one lattice point is
the screen's centre, so the ray is ``D`` whatever the axes; the row and column planes
both hold the ray). A hit is shaded with Phong and a shadow bundle like a primary point
(eye: the ray's origin) and becomes a point of generation ``k + 1`` with the ray's weight;
a miss (or a ray that meets the area light first) brings the background (or the light's
colour). The pixel accumulates weight x colour over its paths.

Glossy reflection (``glossy_rows`` x ``glossy_cols`` > 0, materials with
``gloss_angle > 0`` and a reflection weight): instead of the mirror ray, one bundle per
point on a screen centred on ``O + R`` perpendicular to ``R`` with half extent
``tan(gloss_angle)`` (the screen's edge midpoints lie ``gloss_angle`` off the mirror
direction); rays that point below the surface are disabled. Hits are shaded with Phong
without shadows (eye: the origin), misses bring the background or the light; the mean
over the enabled rays is weighted by the reflection weight. Glossy rays do not recurse.

Ambient occlusion (:meth:`Tracer.occlusion`, primary points only): one ``ao_rows`` x
``ao_cols`` bundle from ``P + eps n`` through a screen centred on ``O + n`` perpendicular
to ``n`` with half extent ``tan(ao_angle)``: the square circumscribes the base of the cone
of half-angle ``ao_angle`` (the lattice's outermost rays lie ``atan((1 - 1/cols)
tan(ao_angle))`` off ``n`` along an axis, up to ``atan(sqrt(2) (1 - 1/cols)
tan(ao_angle))`` on the diagonal). Any-hit with ``tmax = ao_distance * 2 * bound``, the
own triangle excluded, early-out rounds; the ambient term is scaled by the unoccluded
fraction.

Nothing here imports Amaranth.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.bundles import bundle_geometry
from .shading import light_hits, phong, shadow_bundles
from .tracing import any_hit_pass, nearest_pass

__all__ = ["Tracer", "perpendicular_axes", "reflect", "refract", "whitted"]


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def reflect(incident, normal) -> np.ndarray:
    """Mirror directions ``I - 2 N (N.I)`` (rows of unit vectors)."""
    return incident - 2.0 * _dot(normal, incident)[:, None] * normal


def refract(incident, normal, ior):
    """Snell's law at surfaces of index ``ior`` (outside 1).

    Parameters
    ----------
    incident : ndarray (n, 3)
        Unit directions ``I``.
    normal : ndarray (n, 3)
        Geometric unit normals ``N`` (pointing out of the material).
    ior : ndarray (n,)

    Returns
    -------
    transmitted : ndarray (n, 3)
        Unit directions ``T`` (zero where ``tir``).
    tir : ndarray (n,) bool
        Total internal reflection.
    entering : ndarray (n,) bool
        ``N.I < 0``: the ray enters the material.
    """
    c = _dot(normal, incident)
    entering = c < 0
    n = np.where(entering[:, None], normal, -normal)
    eta = np.where(entering, 1.0 / np.asarray(ior, float), np.asarray(ior, float))
    ci = np.abs(c)
    k = 1.0 - eta ** 2 * (1.0 - ci ** 2)
    tir = k < 0
    t = eta[:, None] * incident + (eta * ci - np.sqrt(np.clip(k, 0.0, None)))[:, None] * n
    ln = np.linalg.norm(t, axis=1, keepdims=True)
    t = np.where(tir[:, None], 0.0, t / np.where(ln > 0, ln, 1.0))
    return t, tir, entering


def perpendicular_axes(d):
    """Unit vectors ``a``, ``b`` perpendicular to the unit rows of ``d`` with
    ``a x b = d``."""
    d = np.asarray(d, float)
    e = np.eye(3)[np.argmin(np.abs(d), axis=1)]
    a = np.cross(e, d)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    return a, np.cross(d, a)


def _screens(directions, half):
    """Screen centre offsets and axes of bundles around unit ``directions``."""
    a, b = perpendicular_axes(directions)
    h = np.broadcast_to(np.asarray(half, float), (len(directions),))[:, None]
    return h * a, h * b


class Tracer:
    """The renderer's state that secondary rays need: the backend with the scene loaded,
    the counters, the settings.

    Parameters
    ----------
    backend : Backend
    scene : Scene
        Normalised.
    settings : RenderSettings
    tally : Tally
    normals : ndarray (F, 3)
        Unit geometric normals of the triangles.
    eps : float
        Lift of secondary origins and their ``tmin``.
    timer : callable
        ``timer(name)`` context manager.
    bar : tqdm
        The progress bar (its total grows with each pass).
    """

    def __init__(self, backend, scene, settings, tally, normals, eps, timer, bar):
        self.backend, self.scene, self.s, self.tally = backend, scene, settings, tally
        self.normals, self.eps, self.timer, self.bar = normals, eps, timer, bar
        self.background = np.asarray(scene.background, float)
        self.light_colour = np.asarray(scene.light.colour, float)

    def _grow(self, n):
        self.bar.total = (self.bar.total or 0) + int(n)
        self.bar.refresh()

    def hit_frame(self, tri, dirs):
        """Unit normals of triangles ``tri`` turned against ``dirs``."""
        nrm = self.normals[tri].copy()
        nrm[_dot(nrm, dirs) > 0] *= -1.0
        return nrm

    def shadows(self, pts, nrm, tri, on_chunk=None, plan=None):
        """Fraction of the light each point sees (shadow bundles, any hit, early-out).

        Returns ``(vis, plan)``; points that get no bundle (behind the light, facing away)
        see none of it. ``plan``: the points' :func:`shadow_bundles` if already made.
        """
        s = self.s
        vis = np.ones(len(pts))
        if not s.shadows:
            return vis, None
        if plan is None:
            with self.timer("shading"):
                plan = shadow_bundles(pts, nrm, self.scene.light, s.shadow_rows,
                                      s.shadow_cols, self.eps)
        vis[:] = 0.0
        n = len(plan)
        if n:
            self._grow(n)
            blocked = any_hit_pass(
                self.backend, plan.origins, np.broadcast_to(plan.centre, (n, 3)),
                np.broadcast_to(plan.col_axis, (n, 3)), np.broadcast_to(plan.row_axis, (n, 3)),
                s.shadow_rows, s.shadow_cols, tally=self.tally, kind="shadow", chunk=s.chunk,
                tmin=self.eps, tmax=plan.tmax, exclude=tri[plan.point], early_out=s.early_out,
                batch_spheres=s.batch_spheres, timer=self.timer, progress=self.bar.update,
                on_chunk=on_chunk)
            vis[plan.point] = 1.0 - blocked.mean(axis=1)
        return vis, plan

    def occlusion(self, pts, nrm, tri):
        """Unoccluded fraction of each point's ambient-occlusion bundle (NaN where the
        settings ask for none)."""
        s = self.s
        n = len(pts)
        if not s.ao_rows or not n:
            return np.full(n, np.nan)
        col, row = _screens(nrm, math.tan(math.radians(s.ao_angle)))
        origins = pts + self.eps * nrm
        R = s.ao_rows * s.ao_cols
        tmax = np.full((n, R), s.ao_distance * 2.0 * s.bound)
        self._grow(n)
        blocked = any_hit_pass(self.backend, origins, origins + nrm, col, row, s.ao_rows,
                               s.ao_cols, tally=self.tally, kind="ao", chunk=s.chunk,
                               tmin=self.eps, tmax=tmax, exclude=tri, early_out=s.early_out,
                               batch_spheres=s.batch_spheres, timer=self.timer,
                               progress=self.bar.update)
        return 1.0 - blocked.mean(axis=1)

    def colour(self, origins, dirs, t, tri, shadows=True):
        """What rays bring back: Phong at their hits (with shadow bundles when
        ``shadows``; eye: the origin), the background where they miss, the light's colour
        where they meet the area light first.

        Returns ``(colour (n, 3), points, normals)`` (points and normals of the hits, rows
        where ``tri >= 0``).
        """
        hit = tri >= 0
        h = np.flatnonzero(hit)
        pts = origins[h] + t[h, None] * dirs[h]
        nrm = self.hit_frame(tri[h], dirs[h])
        vis = self.shadows(pts, nrm, tri[h])[0] if shadows and h.size else np.ones(h.size)
        with self.timer("shading"):
            out = np.broadcast_to(self.background, (len(tri), 3)).copy()
            sc = self.scene
            if h.size:
                out[h] = phong(pts, nrm, sc.colours[tri[h]], origins[h], sc.light,
                               sc.material_at(tri[h]), vis)
            sees = light_hits(origins, dirs, sc.light, np.where(hit, t, np.inf))
            out[sees] = self.light_colour
        return out, pts, nrm

    def single(self, kind, origins, dirs, exclude):
        """One 1x1 bundle per ray (reflection or refraction): the nearest hits, and the
        rays as the unit saw them."""
        n = len(origins)
        col, row = _screens(dirs, 1.0)
        self._grow(n)
        res = nearest_pass(self.backend, origins, origins + dirs, col, row, 1, 1,
                           tally=self.tally, kind=kind, chunk=self.s.chunk, tmin=self.eps,
                           tmax=np.full((n, 1), np.inf), exclude=exclude, keep_rays=True,
                           timer=self.timer, progress=self.bar.update)
        return res.origin, res.directions[:, 0], res.t[:, 0], res.tri[:, 0]

    def glossy(self, pts, nrm, mirror, angle, tri):
        """Each point's glossy bundle around its ``mirror`` direction: mean colour of the
        enabled rays (Phong without shadows at hits) and the fraction that hit (NaN where
        no ray is enabled)."""
        s = self.s
        rows, cols = s.glossy_rows, s.glossy_cols
        n = len(pts)
        col, row = _screens(mirror, np.tan(np.radians(angle)))
        origins = pts + self.eps * nrm
        g = bundle_geometry(np.zeros((n, 3)), mirror, col, row, rows, cols)
        enable = np.einsum("brk,bk->br", g["directions"], nrm) > 0
        self._grow(n)
        res = nearest_pass(self.backend, origins, origins + mirror, col, row, rows, cols,
                           tally=self.tally, kind="glossy", chunk=s.chunk, enable=enable,
                           tmin=self.eps, tmax=np.full((n, rows * cols), np.inf),
                           exclude=tri, keep_rays=True, timer=self.timer,
                           progress=self.bar.update)
        R = rows * cols
        o = np.repeat(res.origin, R, axis=0)
        c, _, _ = self.colour(o, res.directions.reshape(-1, 3), res.t.reshape(-1),
                              res.tri.reshape(-1), shadows=False)
        c = c.reshape(n, R, 3)
        k = enable.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = (c * enable[..., None]).sum(axis=1) / np.maximum(k, 1)[:, None]
            frac = np.where(k > 0, ((res.tri >= 0) & enable).sum(axis=1) / k, np.nan)
        return mean, frac


def whitted(tracer: Tracer, pix, pts, nrm, tri, dirs, weight, n_pixels: int):
    """The secondary rays of the primary shading points, generation by generation.

    Parameters
    ----------
    tracer : Tracer
    pix : ndarray (n,) int64
        Flat pixel index of each primary point.
    pts, nrm, tri, dirs : ndarray
        The points, their normals facing the eye, their triangles, the primary directions.
    weight : ndarray (n,)
        Path weight of each point (0: spawns nothing).
    n_pixels : int

    Returns
    -------
    add : ndarray (n_pixels, 3)
        Colour the secondary paths add to each pixel.
    layers : dict
        ``reflection_tri``, ``refraction_tri`` (n_pixels,) int64 (-2: no such ray, -1:
        miss), ``glossy_hit`` (n_pixels,) float (NaN: none) of the depth-1 rays.
    """
    s, sc = tracer.s, tracer.scene
    add = np.zeros((n_pixels, 3))
    layers = {"reflection_tri": np.full(n_pixels, -2, np.int64),
              "refraction_tri": np.full(n_pixels, -2, np.int64)}
    if s.glossy_rows:
        layers["glossy_hit"] = np.full(n_pixels, np.nan)
    eps = tracer.eps
    w = np.asarray(weight, float)
    for gen in range(s.depth):
        if not pix.size:
            break
        with tracer.timer("shading"):
            mat = sc.material_at(tri)
            refl = w * mat.reflectivity
            trans = w * mat.transparency
            trans_dir, tir, _ = refract(dirs, tracer.normals[tri], mat.ior)
            refl = np.where(tir, refl + trans, refl)
            trans = np.where(tir, 0.0, trans)
            glossy = (refl > 0) & (mat.gloss_angle > 0) & (s.glossy_rows > 0)
            mirror = reflect(dirs, nrm)
        nxt = []
        for kind, sel, origin, direction, wt in (
                ("reflection", np.flatnonzero((refl > 0) & ~glossy), pts + eps * nrm, mirror,
                 refl),
                ("refraction", np.flatnonzero(trans > 0), pts - eps * nrm, trans_dir, trans)):
            if not sel.size:
                continue
            o, d, t, hit_tri = tracer.single(kind, origin[sel], direction[sel], tri[sel])
            c, hp, hn = tracer.colour(o, d, t, hit_tri)
            np.add.at(add, pix[sel], wt[sel, None] * c)
            if gen == 0:
                layers[f"{kind}_tri"][pix[sel]] = hit_tri
            h = np.flatnonzero(hit_tri >= 0)
            nxt.append((pix[sel][h], hp, hn, hit_tri[h], d[h], wt[sel][h]))
        g = np.flatnonzero(glossy)
        if g.size:
            mean, frac = tracer.glossy(pts[g], nrm[g], mirror[g], mat.gloss_angle[g], tri[g])
            np.add.at(add, pix[g], refl[g, None] * mean)
            if gen == 0:
                layers["glossy_hit"][pix[g]] = frac
        if not nxt:
            break
        pix, pts, nrm, tri, dirs, w = (np.concatenate(x) for x in zip(*nxt))
    return add, layers
