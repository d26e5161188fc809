"""A pinhole camera, and the primary rays of an image as ``rows`` x ``cols`` bundles.

The camera follows the CPU ray-tracing seed (section 3.3): a position, a viewing
direction, an up vector and (derived) a left/right vector. The image plane sits at
distance 1 in front of the camera; pixel ``(y, x)`` of a ``width`` x ``height`` image
is the ray from the camera position through

    position + forward + ((x + 0.5) - width/2) * s * right - ((y + 0.5) - height/2) * s * up

with ``s = 2 tan(fov/2) / height`` (``fov`` is the vertical field of view). The image is
cut into tiles of ``rows`` x ``cols`` pixels; each tile is one ray bundle whose lattice
points are exactly those pixel points, so ray ``(i, j)`` of a tile's bundle (ray ID
``i*cols + j``) is pixel ``(y0 + i, x0 + j)``. Tiles at the right and bottom edge of an
image whose size is not a multiple of the tile keep the full lattice; the lattice
points outside the image are marked invalid (the host disables those rays).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.bundles import vec3

__all__ = ["Camera", "Tile"]


@dataclass(frozen=True)
class Tile:
    """One image tile: the lattice of a primary ray bundle.

    Attributes
    ----------
    y0, x0 : int
        Image coordinates of lattice point ``(0, 0)``.
    rows, cols : int
        Lattice size (the bundle size, also for clipped edge tiles).
    origin : ndarray (3,)
        The camera position (every ray's origin).
    corner : ndarray (3,)
        Lattice point ``(0, 0)`` on the image plane.
    step_row, step_col : ndarray (3,)
        Lattice steps: point ``(i, j) = corner + i*step_row + j*step_col``.
    valid : ndarray (rows, cols) bool
        Lattice points inside the image.
    """

    y0: int
    x0: int
    rows: int
    cols: int
    origin: np.ndarray
    corner: np.ndarray
    step_row: np.ndarray
    step_col: np.ndarray
    valid: np.ndarray = field(repr=False)

    @property
    def centre(self) -> np.ndarray:
        """The lattice centre (a lattice point only when rows and cols are odd)."""
        return (self.corner + 0.5 * (self.rows - 1) * self.step_row
                + 0.5 * (self.cols - 1) * self.step_col)

    def points(self) -> np.ndarray:
        """All lattice points, shape ``(rows, cols, 3)``."""
        i = np.arange(self.rows, dtype=np.float64)[:, None, None]
        j = np.arange(self.cols, dtype=np.float64)[None, :, None]
        return self.corner + i * self.step_row + j * self.step_col

    def pixels(self) -> tuple[np.ndarray, np.ndarray]:
        """Image coordinates ``(y, x)`` of the lattice points, each ``(rows, cols)`` int."""
        y, x = np.meshgrid(np.arange(self.rows) + self.y0, np.arange(self.cols) + self.x0,
                           indexing="ij")
        return y, x


@dataclass(frozen=True)
class Camera:
    """A pinhole camera.

    Parameters
    ----------
    position : array_like (3,)
        Eye point.
    look_at : array_like (3,)
        A point the camera looks at (defines the direction).
    up : array_like (3,)
        Approximate up vector; it is orthogonalised against the direction.
    fov : float
        Vertical field of view in degrees, in (0, 180).

    Raises
    ------
    ValueError
        For non-finite vectors, ``look_at == position``, ``up`` parallel to the direction
        or a field of view out of range.
    """

    position: tuple
    look_at: tuple
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = 40.0

    def __post_init__(self):
        p = vec3("position", self.position)
        la = vec3("look_at", self.look_at)
        vec3("up", self.up)
        if not 0.0 < float(self.fov) < 180.0:
            raise ValueError(f"fov must be between 0 and 180 degrees, not {self.fov}")
        if np.linalg.norm(la - p) == 0.0:
            raise ValueError("look_at equals position: the camera has no direction")
        self.basis()

    @property
    def direction(self) -> np.ndarray:
        d = vec3("look_at", self.look_at) - vec3("position", self.position)
        return d / np.linalg.norm(d)

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Orthonormal ``(forward, right, up)``; right = forward x up."""
        f = self.direction
        r = np.cross(f, vec3("up", self.up))
        n = np.linalg.norm(r)
        if n < 1e-12:
            raise ValueError("up is parallel to the viewing direction")
        r = r / n
        u = np.cross(r, f)
        return f, r, u

    def transformed(self, translation, scale: float) -> Camera:
        """The same camera after the scene map ``x -> (x + translation) * scale``."""
        t = vec3("translation", translation)
        return Camera(tuple((vec3("position", self.position) + t) * scale),
                      tuple((vec3("look_at", self.look_at) + t) * scale),
                      tuple(vec3("up", self.up)), self.fov)

    def _screen(self, width: int, height: int):
        if int(width) < 1 or int(height) < 1:
            raise ValueError(f"image size must be at least 1x1, not {width}x{height}")
        f, r, u = self.basis()
        s = 2.0 * np.tan(np.radians(float(self.fov)) / 2.0) / height
        p = vec3("position", self.position)
        corner = p + f + (0.5 - width / 2.0) * s * r - (0.5 - height / 2.0) * s * u
        return p, corner, -s * u, s * r

    def pixel_points(self, width: int, height: int) -> np.ndarray:
        """Image-plane points of every pixel, shape ``(height, width, 3)``."""
        _, corner, sr, sc = self._screen(width, height)
        y = np.arange(height, dtype=np.float64)[:, None, None]
        x = np.arange(width, dtype=np.float64)[None, :, None]
        return corner + y * sr + x * sc

    def tiles(self, width: int, height: int, rows: int, cols: int) -> list[Tile]:
        """Cut a ``width`` x ``height`` image into ``rows`` x ``cols`` bundles.

        Tiles are listed row-major (top to bottom, left to right).
        """
        if int(rows) < 1 or int(cols) < 1:
            raise ValueError(f"tile size must be at least 1x1, not {rows}x{cols}")
        p, corner, sr, sc = self._screen(width, height)
        out = []
        for y0 in range(0, height, rows):
            for x0 in range(0, width, cols):
                valid = np.zeros((rows, cols), dtype=bool)
                valid[:min(rows, height - y0), :min(cols, width - x0)] = True
                out.append(Tile(y0, x0, rows, cols, p.copy(), corner + y0 * sr + x0 * sc,
                                sr.copy(), sc.copy(), valid))
        return out
