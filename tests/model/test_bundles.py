"""Ray bundles: lattice, plane and ray IDs, geometry, encoding, degenerate bundles."""

from __future__ import annotations

import numpy as np
import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.fp import model as fpm
from raplas_hdl.model.bundles import RayBundle, encode_bundles

GOOD = dict(origin=[0.1, -0.2, -3.0], centre=[0, 0, 0], col_axis=[0.5, 0, 0],
            row_axis=[0, 0.4, 0.1])


@pytest.mark.parametrize("rows,cols", [(1, 1), (4, 4), (3, 7), (64, 64), (1, 64)])
def test_geometry(rows, cols):
    b = RayBundle(**GOOD, rows=rows, cols=cols)
    assert b.plane_n.shape == (rows + cols, 3) and b.directions.shape == (rows * cols, 3)
    assert np.allclose(np.linalg.norm(b.plane_n, axis=1), 1, atol=1e-15)
    assert np.allclose(np.linalg.norm(b.directions, axis=1), 1, atol=1e-15)
    # every plane holds O; ray (i, j) = ID i*cols + j lies in row plane i and column plane j
    assert np.allclose(b.plane_n @ b.origin + b.plane_p, 0, atol=1e-14)
    row, col = b.ray_planes()
    assert np.all(row == np.arange(rows * cols) // cols)
    assert np.all(col == rows + np.arange(rows * cols) % cols)
    assert np.abs(np.sum(b.plane_n[row] * b.directions, 1)).max() < 1e-14
    assert np.abs(np.sum(b.plane_n[col] * b.directions, 1)).max() < 1e-14
    i, j = 1 % rows, (cols - 1)
    d = b.points[i, j] - b.origin
    assert np.allclose(b.directions[b.ray_id(i, j)], d / np.linalg.norm(d))
    # the lattice spans the screen's pixel centres
    assert np.allclose(b.points.mean(axis=(0, 1)), b.centre)


def test_encoding():
    b = RayBundle(**GOOD, rows=5, cols=3)
    n, p = b.encode_planes(FP24)
    nd = fpm.decode(n, FP24)
    assert np.all(np.abs(nd) <= np.abs(b.plane_n))             # toward zero
    assert np.all(np.sum(nd * nd, axis=1) <= 1.0)
    o, d = b.encode_rays(FP24)
    assert np.array_equal(o, fpm.encode(b.origin, FP24))
    assert np.array_equal(d, fpm.encode(b.directions, FP24))
    # the plane offset comes from the encoded normal and origin
    od = fpm.decode(o, FP24)
    assert np.abs(nd @ od + fpm.decode(p, FP24)).max() <= 2 * FP24.ulp * np.linalg.norm(od)
    words = b.pack_planes(FP24)
    w = FP24.width
    assert [(x >> 3 * w) for x in words] == [int(v) for v in p]
    assert [(x & FP24.mask) for x in words] == [int(v) for v in n[:, 0]]
    # batch encoding equals one at a time
    other = RayBundle([1.0, 2, 3], [0, 0, 0], [0, 0.2, 0], [0, 0, 0.3], 2, 6)
    for (bn, bp, bo, bd), one in zip(encode_bundles([b, other], FP24), (b, other)):
        n1, p1 = one.encode_planes(FP24)
        o1, d1 = one.encode_rays(FP24)
        assert np.array_equal(bn, n1) and np.array_equal(bp, p1)
        assert np.array_equal(bo, o1) and np.array_equal(bd, d1)


@pytest.mark.parametrize("change,message", [
    (dict(rows=0), "rows must be at least 1"),
    (dict(cols=-2), "cols must be at least 1"),
    (dict(rows=2.5), "rows must be an integer"),
    (dict(col_axis=[0, 0, 0]), "col_axis has zero length"),
    (dict(row_axis=[0, 0, 0]), "row_axis has zero length"),
    (dict(row_axis=[1.0, 0, 0]), "parallel"),
    (dict(origin=[0.3, 0.4, 0.1]), "origin lies on the screen plane"),
    (dict(origin=[np.nan, 0, 0]), "origin must be finite"),
    (dict(centre=[np.inf, 0, 0]), "centre must be finite"),
    (dict(col_axis=[1.0, 0]), "col_axis must be a 3-vector"),
])
def test_degenerate(change, message):
    args = dict(GOOD, rows=4, cols=4)
    args.update(change)
    with pytest.raises(ValueError, match=message):
        RayBundle(**args)
