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

The scene record and its normalisation are :mod:`.scene`'s; the meshes and the building
blocks :mod:`.meshes`'.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..paths import DATA_DIR, shipped
from .camera import Camera
from .meshes import MESH_SUFFIXES, MESHES, MeshBuilder, box_mesh, load_mesh, quad_grid, up_rotation
from .scene import DEFAULT_BOUND, AreaLight, Scene
from .scene_file import load_scene_file

__all__ = ["SCENES", "SCENE_DIR", "SCENE_FILES", "SCENE_SUFFIXES", "cornell_box", "get_scene",
           "mesh_scene", "soup_scene", "spheres_scene", "terrain_scene"]

#: Scene files (:mod:`.scene_file`).
SCENE_SUFFIXES = (".toml",)
#: The scene files shipped with the package.
SCENE_DIR = os.path.join(DATA_DIR, "scenes")
#: Shipped scene files by name (the file stem): ``showcase``.
SCENE_FILES = shipped(SCENE_DIR, SCENE_SUFFIXES)


# -- procedural scenes -----------------------------------------------------------------

def cornell_box(subdiv: int = 4) -> Scene:
    """The Cornell box (the classic 555-unit data, Y up), walls split into ``subdiv`` x
    ``subdiv`` quads (2 triangles each), and the short and tall blocks."""
    import trimesh     # lazy: trimesh loads only to read a mesh file

    if subdiv < 1:
        raise ValueError(f"subdiv must be at least 1, not {subdiv}")
    w, h, d = 555.0, 548.8, 559.2
    white, red, green = (0.73, 0.73, 0.73), (0.65, 0.06, 0.05), (0.12, 0.45, 0.15)
    b = MeshBuilder()
    # Faces oriented towards the inside of the box.
    b.add(*quad_grid((0, 0, 0), (0, 0, d), (w, 0, 0), subdiv), white)       # floor (+y)
    b.add(*quad_grid((0, h, 0), (w, 0, 0), (0, 0, d), subdiv), white)       # ceiling (-y)
    b.add(*quad_grid((0, 0, d), (0, h, 0), (w, 0, 0), subdiv), white)       # back (-z)
    b.add(*quad_grid((w, 0, 0), (0, h, 0), (0, 0, d), subdiv), red)         # x = 555 (-x)
    b.add(*quad_grid((0, 0, 0), (0, 0, d), (0, h, 0), subdiv), green)       # x = 0 (+x)
    rot = trimesh.transformations.rotation_matrix
    short = rot(math.radians(-17), (0, 1, 0))
    short[:3, 3] = (185.0, 82.5, 169.0)
    tall = rot(math.radians(17), (0, 1, 0))
    tall[:3, 3] = (368.0, 165.0, 351.0)
    b.add_trimesh(box_mesh((165.0, 165.0, 165.0), short, 1), white)
    b.add_trimesh(box_mesh((165.0, 330.0, 165.0), tall, 1), white)
    v, f, c = b.arrays()
    cam = Camera((278.0, 273.0, -800.0), (278.0, 273.0, 0.0), (0.0, 1.0, 0.0), 39.3)
    light = AreaLight((213.0, 548.0, 227.0), (130.0, 0.0, 0.0), (0.0, 0.0, 105.0),
                      (1.0, 0.92, 0.8))
    return Scene("cornell", v, f, c, cam, light, background=(0.0, 0.0, 0.0))


def _floor(b: MeshBuilder, half: float, y: float, n: int, colour=(0.6, 0.6, 0.6)):
    b.add(*quad_grid((-half, y, -half), (0, 0, 2 * half), (2 * half, 0, 0), n), colour)


def spheres_scene(subdivisions: int = 2, floor_subdiv: int = 4) -> Scene:
    """Three meshed spheres (icospheres) and a torus on a floor."""
    import trimesh     # lazy: trimesh loads only to read a mesh file

    b = MeshBuilder()
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
    verts, faces = quad_grid((-3.0, 0.0, -3.0), (0.0, 0.0, 6.0), (6.0, 0.0, 0.0), n)
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
    b = MeshBuilder()
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
    b = MeshBuilder()
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
        scene = load_scene_file(SCENE_FILES.get(spec, spec), **options)
    elif os.path.splitext(spec)[1].lower() in MESH_SUFFIXES or os.path.exists(spec):
        scene = mesh_scene(spec, **options)
    else:
        raise ValueError(f"unknown scene {spec!r}: use one of "
                         f"{', '.join([*SCENES, *MESHES, *SCENE_FILES])}, a path to an "
                         f"{'/'.join(s[1:].upper() for s in MESH_SUFFIXES)} file or a "
                         "scene file (.toml)")
    return scene if bound is None else scene.normalised(bound)
