"""Pinhole camera: tiles cover the image once, bundles reproduce the pixel rays."""

import numpy as np
import pytest

from raplas_hdl.host.camera import Camera
from raplas_hdl.model.bundles import RayBundle


@pytest.mark.parametrize("w, h, rows, cols", [(16, 16, 8, 8), (13, 7, 4, 3), (5, 9, 8, 8)])
def test_tiles_cover_image_once(w, h, rows, cols):
    cam = Camera((0.5, 1.0, 6.0), (0.0, 0.2, 0.0), (0, 1, 0), 50.0)
    count = np.zeros((h, w), int)
    pix = cam.pixel_points(w, h)
    for tile in cam.tiles(w, h, rows, cols):
        y, x = tile.pixels()
        v = tile.valid
        assert v.shape == (rows, cols)
        np.add.at(count, (y[v], x[v]), 1)
        assert not np.any((y[~v] < h) & (x[~v] < w))
        np.testing.assert_allclose(tile.points()[v], pix[y[v], x[v]], atol=1e-12)
        b = RayBundle(tile.origin, tile.centre, 0.5 * cols * tile.step_col,
                      0.5 * rows * tile.step_row, rows, cols)
        np.testing.assert_allclose(b.points, tile.points(), atol=1e-12)
    assert np.all(count == 1)


def test_camera_orientation():
    cam = Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), 90.0)
    f, r, u = cam.basis()
    np.testing.assert_allclose(f, [0, 0, -1])
    np.testing.assert_allclose(u, [0, 1, 0])
    np.testing.assert_allclose(r, [1, 0, 0])        # right = forward x up
    pix = cam.pixel_points(2, 2)
    assert pix[0, 0, 1] > 0 > pix[1, 0, 1]          # row 0 is the top
    assert pix[0, 0, 0] < 0 < pix[0, 1, 0]          # column 0 is the left


@pytest.mark.parametrize("kwargs, message", [
    ({"position": (0, 0, 0), "look_at": (0, 0, 0)}, "no direction"),
    ({"position": (0, 0, 0), "look_at": (0, 1, 0)}, "parallel"),
    ({"position": (0, 0, 0), "look_at": (1, 0, 0), "fov": 180}, "fov"),
    ({"position": (0, np.nan, 0), "look_at": (1, 0, 0)}, "finite"),
])
def test_bad_camera(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Camera(**kwargs)


def test_bad_tile_size():
    cam = Camera((0, 0, 5), (0, 0, 0))
    with pytest.raises(ValueError, match="tile size"):
        cam.tiles(8, 8, 0, 4)
    with pytest.raises(ValueError, match="image size"):
        cam.tiles(0, 8, 4, 4)
