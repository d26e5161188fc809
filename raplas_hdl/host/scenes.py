"""Scenes: procedural ones and mesh files, normalised into the format's coordinates.

A :class:`Scene` is a triangle list (float64 vertices, integer faces, a diffuse colour
per triangle) with a pinhole camera, one rectangular area light and Phong material
constants: ``material`` (shared by every triangle of the procedural scenes) and a
materials table with a material ID per triangle (scene files give each mesh its own).
Scenes come from :func:`get_scene`:

- ``cornell``: the Cornell box (walls subdivided into a grid, two blocks);
- ``spheres``: meshed spheres and a torus standing on a floor;
- ``terrain``: a seeded height field;
- ``soup``: seeded random triangles above a floor;
- a path to an ``.obj``, ``.ply``, ``.stl``, ``.gltf`` or ``.glb`` file (read with
  trimesh), placed on a floor (``up`` names the mesh's up axis);
- a scene file (``.toml``: camera, light, materials, meshes with transforms; see
  :mod:`.scene_file` and ``docs/scenes.md``), or the name of a shipped one
  (:data:`SCENE_FILES`: ``showcase``).

The load normalisation of ``docs/raplas.md`` ("Coordinates") is
:meth:`Scene.normalised`: a translation that centres the bounding box of everything the
accelerator sees (triangles, camera, light), then a power-of-two scale so that every
coordinate lies in ``[-bound, bound]`` with the largest magnitude above ``bound/2``.
The power-of-two scale is exact in every format, so the normalised float64 vertices are
"the original geometry" of the exact reference; the translation and scale are kept so
that results can be mapped back.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace

import numpy as np

from .camera import Camera

__all__ = [
    "DEFAULT_BOUND",
    "MESHES",
    "MESH_DIR",
    "SCENES",
    "SCENE_DIR",
    "SCENE_FILES",
    "SCENE_SUFFIXES",
    "AreaLight",
    "Material",
    "Scene",
    "cornell_box",
    "get_scene",
    "load_mesh",
    "mesh_scene",
    "soup_scene",
    "spheres_scene",
    "terrain_scene",
    "up_rotation",
]

#: Default bound of the normalisation: every scene coordinate lies in [-8, 8]. With
#: edges of a few hundredths and coordinates up to 8, det ~ |E|^2 and t' ~ |E|^2 |T|
#: stay far from both ends of even FP16's range (2^-14 .. 2^15).
DEFAULT_BOUND = 8.0

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".gltf", ".glb")
#: Scene files (:mod:`.scene_file`).
SCENE_SUFFIXES = (".toml",)

_DATA_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data")


def _shipped(folder: str, suffixes) -> dict:
    return {os.path.splitext(f)[0]: os.path.join(folder, f)
            for f in sorted(os.listdir(folder)) if os.path.splitext(f)[1] in suffixes} \
        if os.path.isdir(folder) else {}


#: The meshes shipped with the package (licence notes in its README.md).
MESH_DIR = os.path.join(_DATA_DIR, "meshes")
#: Shipped meshes by name (the file stem): ``stanford-bunny``, ``teapot``, ...
MESHES = _shipped(MESH_DIR, MESH_SUFFIXES)
#: The scene files shipped with the package.
SCENE_DIR = os.path.join(_DATA_DIR, "scenes")
#: Shipped scene files by name (the file stem): ``showcase``.
SCENE_FILES = _shipped(SCENE_DIR, SCENE_SUFFIXES)


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


# -- building blocks -------------------------------------------------------------------

def _quad_grid(origin, eu, ev, n: int):
    """A parallelogram ``origin + a*eu + b*ev`` split into ``2*n*n`` triangles, facing
    ``eu x ev``."""
    origin, eu, ev = (np.asarray(x, float) for x in (origin, eu, ev))
    a = np.linspace(0.0, 1.0, n + 1)
    grid = origin + a[:, None, None] * eu + a[None, :, None] * ev
    verts = grid.reshape(-1, 3)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    i00, i10, i01, i11 = idx[:-1, :-1], idx[1:, :-1], idx[:-1, 1:], idx[1:, 1:]
    faces = np.concatenate([np.stack([i00, i10, i11], -1).reshape(-1, 3),
                            np.stack([i00, i11, i01], -1).reshape(-1, 3)])
    return verts, faces


class _Builder:
    """Collects meshes with a colour each."""

    def __init__(self):
        self.verts, self.faces, self.cols = [], [], []
        self.n = 0

    def add(self, verts, faces, colour):
        verts = np.asarray(verts, float)
        faces = np.asarray(faces, np.int64)
        self.verts.append(verts)
        self.faces.append(faces + self.n)
        self.cols.append(np.broadcast_to(np.asarray(colour, float), (len(faces), 3)))
        self.n += len(verts)

    def add_trimesh(self, mesh, colour):
        self.add(mesh.vertices, mesh.faces, colour)

    def arrays(self):
        return (np.vstack(self.verts), np.vstack(self.faces), np.vstack(self.cols))


def _box(size, transform, subdiv: int):
    import trimesh

    m = trimesh.creation.box(extents=size, transform=transform)
    for _ in range(max(0, subdiv)):
        m = m.subdivide()
    return m


# -- procedural scenes -----------------------------------------------------------------

def cornell_box(subdiv: int = 4) -> Scene:
    """The Cornell box (the classic 555-unit data, Y up), walls split into ``subdiv`` x
    ``subdiv`` quads (2 triangles each), and the short and tall blocks."""
    import trimesh

    if subdiv < 1:
        raise ValueError(f"subdiv must be at least 1, not {subdiv}")
    w, h, d = 555.0, 548.8, 559.2
    white, red, green = (0.73, 0.73, 0.73), (0.65, 0.06, 0.05), (0.12, 0.45, 0.15)
    b = _Builder()
    # Faces oriented towards the inside of the box.
    b.add(*_quad_grid((0, 0, 0), (0, 0, d), (w, 0, 0), subdiv), white)       # floor (+y)
    b.add(*_quad_grid((0, h, 0), (w, 0, 0), (0, 0, d), subdiv), white)       # ceiling (-y)
    b.add(*_quad_grid((0, 0, d), (0, h, 0), (w, 0, 0), subdiv), white)       # back (-z)
    b.add(*_quad_grid((w, 0, 0), (0, h, 0), (0, 0, d), subdiv), red)         # x = 555 (-x)
    b.add(*_quad_grid((0, 0, 0), (0, 0, d), (0, h, 0), subdiv), green)       # x = 0 (+x)
    rot = trimesh.transformations.rotation_matrix
    short = rot(math.radians(-17), (0, 1, 0))
    short[:3, 3] = (185.0, 82.5, 169.0)
    tall = rot(math.radians(17), (0, 1, 0))
    tall[:3, 3] = (368.0, 165.0, 351.0)
    b.add_trimesh(_box((165.0, 165.0, 165.0), short, 1), white)
    b.add_trimesh(_box((165.0, 330.0, 165.0), tall, 1), white)
    v, f, c = b.arrays()
    cam = Camera((278.0, 273.0, -800.0), (278.0, 273.0, 0.0), (0.0, 1.0, 0.0), 39.3)
    light = AreaLight((213.0, 548.0, 227.0), (130.0, 0.0, 0.0), (0.0, 0.0, 105.0),
                      (1.0, 0.92, 0.8))
    return Scene("cornell", v, f, c, cam, light, background=(0.0, 0.0, 0.0))


def _floor(b: _Builder, half: float, y: float, n: int, colour=(0.6, 0.6, 0.6)):
    b.add(*_quad_grid((-half, y, -half), (0, 0, 2 * half), (2 * half, 0, 0), n), colour)


def spheres_scene(subdivisions: int = 2, floor_subdiv: int = 4) -> Scene:
    """Three meshed spheres (icospheres) and a torus on a floor."""
    import trimesh

    b = _Builder()
    _floor(b, 4.0, 0.0, floor_subdiv)
    for centre, radius, colour in (((-1.6, 0.7, 0.4), 0.7, (0.8, 0.25, 0.2)),
                                   ((0.2, 0.5, -0.9), 0.5, (0.2, 0.45, 0.85)),
                                   ((1.5, 0.9, 0.8), 0.9, (0.85, 0.8, 0.3))):
        s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
        s.apply_translation(centre)
        b.add_trimesh(s, colour)
    t = trimesh.creation.torus(major_radius=0.8, minor_radius=0.25, major_sections=24,
                               minor_sections=12)
    t.apply_transform(trimesh.transformations.rotation_matrix(math.radians(70), (1, 0, 0)))
    t.apply_translation((0.1, 1.05, 1.4))
    b.add_trimesh(t, (0.3, 0.75, 0.4))
    v, f, c = b.arrays()
    cam = Camera((0.5, 3.2, 7.0), (0.0, 0.6, 0.0), (0.0, 1.0, 0.0), 40.0)
    light = AreaLight((-1.5, 5.0, -0.5), (1.5, 0.0, 0.0), (0.0, 0.0, 1.5))
    return Scene("spheres", v, f, c, cam, light)


def terrain_scene(n: int = 24, seed: int = 1) -> Scene:
    """A ``n`` x ``n`` quad height field of seeded random sinusoids."""
    if n < 2:
        raise ValueError(f"terrain size n must be at least 2, not {n}")
    rng = np.random.default_rng(seed)
    verts, faces = _quad_grid((-3.0, 0.0, -3.0), (0.0, 0.0, 6.0), (6.0, 0.0, 0.0), n)
    x, z = verts[:, 0], verts[:, 2]
    y = np.zeros_like(x)
    for _ in range(6):
        kx, kz = rng.normal(0.0, 1.2, 2)
        y += rng.uniform(0.1, 0.35) * np.sin(kx * x + kz * z + rng.uniform(0, 2 * np.pi))
    verts = verts.copy()
    verts[:, 1] = y
    hmean = y[faces].mean(axis=1)
    a = (hmean - y.min()) / max(np.ptp(y), 1e-9)
    colours = np.stack([0.25 + 0.5 * a, 0.55 - 0.1 * a, 0.2 + 0.5 * a ** 2], axis=1)
    cam = Camera((0.0, 3.5, 6.5), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 45.0)
    light = AreaLight((-2.0, 6.0, -1.0), (2.0, 0.0, 0.0), (0.0, 0.0, 2.0))
    return Scene("terrain", verts, faces, colours, cam, light)


def soup_scene(n: int = 200, seed: int = 1) -> Scene:
    """``n`` seeded random triangles in a cube above a floor (overlapping, any size)."""
    if n < 1:
        raise ValueError(f"soup size n must be at least 1, not {n}")
    rng = np.random.default_rng(seed)
    b = _Builder()
    _floor(b, 4.0, 0.0, 2)
    centres = rng.uniform((-1.5, 0.4, -1.5), (1.5, 2.6, 1.5), (n, 3))
    size = np.exp(rng.uniform(np.log(0.08), np.log(0.6), (n, 1, 1)))
    tris = centres[:, None, :] + size * rng.normal(0.0, 1.0, (n, 3, 3))
    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    tris = tris[area > 1e-6]
    colours = rng.uniform(0.2, 0.9, (len(tris), 3))
    for tri, col in zip(tris, colours):
        b.add(tri, [[0, 1, 2]], col)
    v, f, c = b.arrays()
    cam = Camera((0.0, 2.5, 6.5), (0.0, 1.2, 0.0), (0.0, 1.0, 0.0), 42.0)
    light = AreaLight((-1.0, 5.0, -1.0), (2.0, 0.0, 0.0), (0.0, 0.0, 2.0))
    return Scene("soup", v, f, c, cam, light)


# -- mesh files ------------------------------------------------------------------------

def load_mesh(path) -> tuple[np.ndarray, np.ndarray]:
    """Read an OBJ, PLY or STL file into ``(vertices (V, 3), faces (F, 3))`` with trimesh.

    Polygons are triangulated; several objects in one file are concatenated.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        For an unsupported suffix, a file trimesh cannot parse, or one with no triangles
        (an empty file, points or lines only).
    """
    import trimesh

    path = os.fspath(path)
    if os.path.isdir(path):
        raise ValueError(f"mesh file {path!r} is a directory")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"mesh file {path!r} does not exist")
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in MESH_SUFFIXES:
        raise ValueError(f"mesh file {path!r}: unsupported type {suffix!r} "
                         f"(use {', '.join(MESH_SUFFIXES)})")
    if os.path.getsize(path) == 0:
        raise ValueError(f"mesh file {path!r} is empty")
    try:
        loaded = trimesh.load(path, file_type=suffix[1:], force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for malformed input
        why = " ".join(str(exc).split())[:200]     # one line, however trimesh words it
        raise ValueError(f"mesh file {path!r} is malformed: {type(exc).__name__}: {why}") \
            from exc
    faces = getattr(loaded, "faces", None)
    verts = getattr(loaded, "vertices", None)
    if faces is None or verts is None or len(faces) == 0:
        raise ValueError(f"mesh file {path!r} contains no triangles")
    try:
        verts = np.asarray(verts, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
    except (TypeError, ValueError):
        raise ValueError(f"mesh file {path!r} is malformed: ragged vertices or faces") \
            from None
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"mesh file {path!r}: faces are not triangles")
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise ValueError(f"mesh file {path!r} is malformed: vertices need 3 coordinates")
    if faces.min() < 0 or faces.max() >= len(verts):
        raise ValueError(f"mesh file {path!r} is malformed: a face refers to vertex "
                         f"{int(faces.max()) + 1} of {len(verts)}")
    if not np.all(np.isfinite(verts[np.unique(faces)])):
        raise ValueError(f"mesh file {path!r} has NaN or infinite vertex coordinates")
    return verts, faces


def up_rotation(up) -> np.ndarray:
    """The 3x3 rotation that turns the direction ``up`` to ``+y`` (the shortest one; half
    a turn about ``x`` for ``-y``).

    Raises
    ------
    ValueError
        For a zero or non-finite vector.
    """
    u = np.asarray(up, dtype=np.float64)
    n = float(np.linalg.norm(u)) if u.shape == (3,) else 0.0
    if not (n > 0.0 and math.isfinite(n)):
        raise ValueError(f"up must be a non-zero finite 3-vector, not {np.asarray(up).tolist()}")
    u = u / n
    y = np.array([0.0, 1.0, 0.0])
    c = float(u @ y)
    if c < -1.0 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    k = np.cross(u, y)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + kx + kx @ kx / (1.0 + c)


def mesh_scene(path, colour=(0.78, 0.72, 0.62), floor: bool = True, up=(0.0, 1.0, 0.0)
               ) -> Scene:
    """A mesh file turned so that its axis ``up`` points up (``+y``), scaled to a height of
    about 2, standing on a floor, lit from above-left and seen from the front at a slight
    elevation."""
    verts, faces = load_mesh(path)
    verts = verts @ up_rotation(up).T
    used = verts[np.unique(faces)]
    lo, hi = used.min(axis=0), used.max(axis=0)
    size = float(np.max(hi - lo))
    if size == 0.0:
        raise ValueError(f"mesh file {path!r} has zero extent")
    s = 2.0 / size
    verts = (verts - np.array([(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2])) * s
    top = (hi[1] - lo[1]) * s
    b = _Builder()
    if floor:
        _floor(b, 2.5, 0.0, 2)
    b.add(verts, faces, colour)
    v, f, c = b.arrays()
    name = os.path.splitext(os.path.basename(os.fspath(path)))[0]
    cam = Camera((0.9, 0.5 * top + 1.4, 4.2), (0.0, 0.45 * top, 0.0), (0.0, 1.0, 0.0), 38.0)
    light = AreaLight((-1.8, top + 2.5, 0.2), (1.2, 0.0, 0.0), (0.0, 0.0, 1.2))
    return Scene(name, v, f, c, cam, light)


#: Procedural scenes by name.
SCENES = {
    "cornell": cornell_box,
    "spheres": spheres_scene,
    "terrain": terrain_scene,
    "soup": soup_scene,
}


def _is_scene_file(spec: str) -> bool:
    return spec in SCENE_FILES or os.path.splitext(spec)[1].lower() in SCENE_SUFFIXES


def get_scene(spec: str, bound: float | None = DEFAULT_BOUND, **options) -> Scene:
    """A scene by name (``cornell``, ``spheres``, ``terrain``, ``soup``), the name of a
    shipped mesh (:data:`MESHES`: ``stanford-bunny``, ``teapot``, ...) or a mesh path, a
    scene file (``.toml``) or the name of a shipped one (:data:`SCENE_FILES`:
    ``showcase``), normalised into ``[-bound, bound]`` (``bound=None`` leaves it in its own
    units). ``options`` go to the builder (:func:`mesh_scene` takes ``up``; a scene file
    takes the overrides of :func:`~raplas_hdl.host.scene_file.load_scene_file`).

    Raises
    ------
    ValueError
        For an unknown name, what :func:`load_mesh` raises for a file, or a malformed scene
        file (one line naming the file and the line or key).
    """
    if spec in SCENES:
        scene = SCENES[spec](**options)
    elif spec in MESHES:
        scene = mesh_scene(MESHES[spec], **options)
    elif _is_scene_file(spec):
        from .scene_file import load_scene_file

        scene = load_scene_file(SCENE_FILES.get(spec, spec), **options)
    elif os.path.splitext(spec)[1].lower() in MESH_SUFFIXES or os.path.exists(spec):
        scene = mesh_scene(spec, **options)
    else:
        raise ValueError(f"unknown scene {spec!r}: use one of "
                         f"{', '.join([*SCENES, *MESHES, *SCENE_FILES])}, a path to an "
                         f"{'/'.join(s[1:].upper() for s in MESH_SUFFIXES)} file or a "
                         "scene file (.toml)")
    return scene if bound is None else scene.normalised(bound)
