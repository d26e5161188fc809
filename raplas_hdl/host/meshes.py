"""Triangle meshes: mesh files read with trimesh (:func:`load_mesh`, the shipped ones in
:data:`MESHES`), and the building blocks of procedural scenes (:func:`quad_grid`,
:func:`box_mesh`, :class:`MeshBuilder`)."""

from __future__ import annotations

import math
import os

import numpy as np

from ..paths import DATA_DIR, shipped

__all__ = ["MESHES", "MESH_DIR", "MESH_SUFFIXES", "MeshBuilder", "box_mesh", "load_mesh",
           "quad_grid", "up_rotation"]

#: Mesh files :func:`load_mesh` reads (with trimesh).
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".gltf", ".glb")
#: The meshes shipped with the package (licence notes in its README.md).
MESH_DIR = os.path.join(DATA_DIR, "meshes")
#: Shipped meshes by name (the file stem): ``stanford-bunny``, ``teapot``, ...
MESHES = shipped(MESH_DIR, MESH_SUFFIXES)


# -- building blocks of procedural scenes ---------------------------------------------------

def quad_grid(origin, eu, ev, n: int):
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


class MeshBuilder:
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


def box_mesh(size, transform, subdiv: int):
    import trimesh     # lazy: trimesh loads only to read a mesh file

    m = trimesh.creation.box(extents=size, transform=transform)
    for _ in range(max(0, subdiv)):
        m = m.subdivide()
    return m


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
    import trimesh     # lazy: trimesh loads only to read a mesh file

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
