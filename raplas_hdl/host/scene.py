"""The scene record: a triangle list with its colours, materials, camera and light
(:class:`Scene`, with :class:`Material` and :class:`AreaLight`), and the load
normalisation into the format's coordinates.

The load normalisation of ``docs/raplas.md`` ("Coordinates") is
:meth:`Scene.normalised`: a translation that centres the bounding box of everything the
accelerator sees (triangles, camera, light), then a power-of-two scale so that every
coordinate lies in ``[-bound, bound]`` with the largest magnitude above ``bound/2``.
The power-of-two scale is exact in every format, so the normalised float64 vertices are
"the original geometry" of the exact reference; the translation and scale are kept so
that results can be mapped back.

Scenes are made by :mod:`.scenes` (procedural ones, mesh files) and :mod:`.scene_file`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .camera import Camera

__all__ = ["DEFAULT_BOUND", "AreaLight", "Material", "Scene"]

#: Default bound of the normalisation: every scene coordinate lies in [-8, 8]. With
#: edges of a few hundredths and coordinates up to 8, det ~ |E|^2 and t' ~ |E|^2 |T|
#: stay far from both ends of even FP16's range (2^-14 .. 2^15).
DEFAULT_BOUND = 8.0


@dataclass(frozen=True)
class AreaLight:
    """A rectangular area light emitting towards ``normal``.

    Points are ``corner + a*edge_u + b*edge_v`` for ``a, b`` in ``[0, 1]``; it emits on the
    side of ``normal = unit(edge_u x edge_v)``.

    ``kind`` is ``"area"``, or ``"point"`` for a point light of a scene file: the renderer
    shades and shadows with a light's lattice, so a point light is a small square (its
    ``centre`` the point) facing a stated direction, and lights the half-space in front of
    it; its soft shadows are then hard ones.
    """

    corner: tuple
    edge_u: tuple
    edge_v: tuple
    colour: tuple = (1.0, 1.0, 1.0)
    kind: str = "area"

    def __post_init__(self):
        n = np.cross(np.asarray(self.edge_u, float), np.asarray(self.edge_v, float))
        if not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0.0:
            raise ValueError("area light edges must be finite and not parallel")

    @property
    def normal(self) -> np.ndarray:
        n = np.cross(np.asarray(self.edge_u, float), np.asarray(self.edge_v, float))
        return n / np.linalg.norm(n)

    @property
    def centre(self) -> np.ndarray:
        return (np.asarray(self.corner, float) + 0.5 * np.asarray(self.edge_u, float)
                + 0.5 * np.asarray(self.edge_v, float))

    def corners(self) -> np.ndarray:
        c, u, v = (np.asarray(x, float) for x in (self.corner, self.edge_u, self.edge_v))
        return np.array([c, c + u, c + v, c + u + v])

    def lattice(self, rows: int, cols: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cell centres of a ``rows`` x ``cols`` lattice: ``(corner00, step_row, step_col)``.

        Point ``(i, j)`` is ``corner00 + i*step_row + j*step_col``.
        """
        if rows < 1 or cols < 1:
            raise ValueError(f"light lattice must be at least 1x1, not {rows}x{cols}")
        u, v = np.asarray(self.edge_u, float), np.asarray(self.edge_v, float)
        sr, sc = u / rows, v / cols
        return np.asarray(self.corner, float) + 0.5 * sr + 0.5 * sc, sr, sc

    def transformed(self, translation, scale: float) -> AreaLight:
        t = np.asarray(translation, float)
        return AreaLight(tuple((np.asarray(self.corner, float) + t) * scale),
                         tuple(np.asarray(self.edge_u, float) * scale),
                         tuple(np.asarray(self.edge_v, float) * scale), self.colour, self.kind)

    def moved(self, centre) -> AreaLight:
        """The same light with its centre at ``centre``."""
        return self.transformed(np.asarray(centre, float) - self.centre, 1.0)


@dataclass(frozen=True)
class Material:
    """Phong constants and the secondary-ray properties of a surface (the colour is per
    triangle, :attr:`Scene.colours`).

    Attributes
    ----------
    ambient, diffuse, specular, shininess : float
        Phong constants ``ka``, ``kd``, ``ks``, ``n``.
    reflectivity : float
        Fraction of the light a mirror reflection carries, in ``[0, 1]``.
    transparency : float
        Fraction a refracted ray carries, in ``[0, 1]``; ``reflectivity + transparency``
        is at most 1.
    ior : float
        Index of refraction of the inside (the outside is 1).
    gloss_angle : float
        Half-angle in degrees of the cone of glossy reflection around the mirror
        direction (0: a perfect mirror), below 90.
    name : str
    """

    ambient: float = 0.12
    diffuse: float = 0.8
    specular: float = 0.25
    shininess: float = 24.0
    reflectivity: float = 0.0
    transparency: float = 0.0
    ior: float = 1.0
    gloss_angle: float = 0.0
    name: str = "default"


@dataclass
class Scene:
    """A triangle scene with its camera, light and material.

    Attributes
    ----------
    name : str
    vertices : ndarray (V, 3) float64
    faces : ndarray (F, 3) int64
        Vertex indices; triangle ``k`` is ``vertices[faces[k]]`` and has ID ``k``.
    colours : ndarray (F, 3) float64
        Diffuse albedo in ``[0, 1]``.
    camera : Camera
    light : AreaLight
    material : Material
        The default Phong constants (what a renderer that shades every triangle alike
        uses).
    background : tuple
        Colour of pixels whose primary ray hits nothing.
    translation, scale : ndarray (3,), float
        Scene coordinates are ``(original + translation) * scale``; identity until
        :meth:`normalised` is applied.
    materials : tuple of Material
        The materials table (default: ``(material,)``).
    material_ids : ndarray (F,) int64
        Index into ``materials`` of every triangle (default: all 0).
    render_defaults : dict
        Render settings the scene asks for (a scene file's ``[render]`` table:
        ``depth``, ``glossy``, ``ao``, ``ao_angle``, ``ao_distance``); options override them.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    colours: np.ndarray
    camera: Camera
    light: AreaLight
    material: Material = field(default_factory=Material)
    background: tuple = (0.05, 0.05, 0.08)
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0
    materials: tuple = ()
    material_ids: np.ndarray | None = None
    render_defaults: dict = field(default_factory=dict)

    def __post_init__(self):
        v = np.asarray(self.vertices, dtype=np.float64)
        f = np.asarray(self.faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"scene {self.name!r}: vertices must have shape (V, 3), "
                             f"not {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"scene {self.name!r}: faces must have shape (F, 3), not {f.shape}")
        if len(f) == 0:
            raise ValueError(f"scene {self.name!r} has no triangles")
        if f.min() < 0 or f.max() >= len(v):
            raise ValueError(f"scene {self.name!r}: a face refers to a vertex that does not "
                             f"exist (indices {f.min()}..{f.max()}, {len(v)} vertices)")
        if not np.all(np.isfinite(v[f])):
            raise ValueError(f"scene {self.name!r}: a triangle has a NaN or infinite vertex")
        c = np.broadcast_to(np.asarray(self.colours, dtype=np.float64), (len(f), 3)).copy()
        self.vertices, self.faces, self.colours = v, f, c
        self.translation = np.asarray(self.translation, dtype=np.float64)
        self.materials = tuple(self.materials) or (self.material,)
        ids = np.zeros(len(f), np.int64) if self.material_ids is None else \
            np.asarray(self.material_ids, dtype=np.int64)
        if ids.shape != (len(f),):
            raise ValueError(f"scene {self.name!r}: material_ids must have shape ({len(f)},), "
                             f"not {ids.shape}")
        if ids.min() < 0 or ids.max() >= len(self.materials):
            raise ValueError(f"scene {self.name!r}: a material ID is outside the "
                             f"{len(self.materials)} materials")
        self.material_ids = ids

    @property
    def n_triangles(self) -> int:
        return len(self.faces)

    def material_at(self, tri) -> Material:
        """The Phong constants of triangles ``tri`` as one :class:`Material` whose fields
        are arrays (one value per entry of ``tri``), for
        :func:`~raplas_hdl.host.shading.phong`."""
        ids = self.material_ids[np.asarray(tri, np.int64)]
        table = {k: np.array([getattr(m, k) for m in self.materials], np.float64)
                 for k in ("ambient", "diffuse", "specular", "shininess", "reflectivity",
                           "transparency", "ior", "gloss_angle")}
        return Material(**{k: v[ids] for k, v in table.items()}, name="per-triangle")

    @property
    def triangles(self) -> np.ndarray:
        """Vertices of every triangle, shape ``(F, 3, 3)``: ``[k] = (V0, V1, V2)``."""
        return self.vertices[self.faces]

    def points_of_interest(self) -> np.ndarray:
        """Everything the accelerator sees: used vertices, the eye and the light corners."""
        return np.vstack([self.vertices[np.unique(self.faces)],
                          np.asarray(self.camera.position, float)[None],
                          self.light.corners()])

    def normalised(self, bound: float = DEFAULT_BOUND) -> Scene:
        """The load normalisation: centre, then scale by a power of two into ``bound``.

        After it, every coordinate of the triangles, the camera position and the light
        lies in ``[-bound, bound]`` and the largest magnitude exceeds ``bound/2``.
        Normalising twice gives the same scene.

        Raises
        ------
        ValueError
            If ``bound`` is not a positive finite number or the scene is a single point.
        """
        if not (bound > 0 and math.isfinite(bound)):
            raise ValueError(f"bound must be positive and finite, not {bound}")
        pts = self.points_of_interest()
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        size = float(np.max(hi - lo))
        if not size > 0.0:
            raise ValueError(f"scene {self.name!r} has zero extent")
        # The translation is snapped to a power-of-two grid 2**-12 of the size, so that
        # a normalised scene (centred to within half a grid step) normalises to itself.
        q = 2.0 ** (math.ceil(math.log2(size)) - 12)
        t = np.round(-0.5 * (lo + hi) / q) * q
        extent = float(np.max(np.abs(pts + t)))
        k = math.floor(math.log2(bound / extent))
        s = 2.0 ** k
        while extent * s > bound:
            s /= 2.0
        while extent * s * 2.0 <= bound:
            s *= 2.0
        return replace(self, vertices=(self.vertices + t) * s,
                       camera=self.camera.transformed(t, s),
                       light=self.light.transformed(t, s),
                       translation=(self.translation + t / self.scale),
                       scale=self.scale * s)

    def __repr__(self):
        return (f"Scene({self.name!r}, {self.n_triangles} triangles, scale=2^"
                f"{math.log2(self.scale):g})")
