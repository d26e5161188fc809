"""Every ray type through the RTL equals the golden model bit for bit, under both simulators.

The shipped ``small`` scene (116 triangles: a glossy floor, two walls, a mirror panel, a glass
ball, a diffuse block under an area light) rendered with primary, shadow, reflection,
refraction (depth 2: into the ball and out again), glossy and ambient-occlusion rays. The
primary, shadow, glossy and AO bundles are all 2x2 and the reflection and refraction rays
are 1x1 bundles, so the render needs two unit configurations: two live simulations, each
built once per simulator and cached under ``build/sim``. The image, the nearest triangle
and ``t`` of every pixel, the visibility, every first-bounce layer (``reflection_tri``,
``refraction_tri``, ``glossy_hit``, ``ao``), the unit's counters and the per-ray-type
counters must be equal; every ray type must run and hit something, so that a broken type
cannot pass by being absent. Verilator renders 32x32 pixels; Icarus, some 30x slower on
this unit, renders 6x6. A missing simulator is an error, not a skip.
"""

import functools

import numpy as np
import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.host.backends import make_backend
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene

RAY_TYPES = ("primary", "shadow", "reflection", "refraction", "glossy", "ao")
LAYERS = ("reflection_tri", "refraction_tri", "glossy_hit", "ao")


def _settings(width, height):
    return RenderSettings(width, height, rows=2, cols=2, shadow_rows=2, shadow_cols=2,
                          glossy_rows=2, glossy_cols=2, ao_rows=2, ao_cols=2, depth=2,
                          tris_per_sphere=4, batch_spheres=4, chunk=4096, progress=False)


@functools.cache
def _scene():
    return get_scene("small")


@functools.cache
def _model(size):
    return render(_scene(), make_backend("model", FP24, mode="paper"), _settings(*size))


def _per_type(result):
    return {name: dict(v) for name, v in result.stats["ray_types"].items()}


# Icarus runs in the full suite; make test keeps Verilator's larger frame
@pytest.mark.parametrize("sim, size", [pytest.param("icarus", (6, 6), marks=pytest.mark.full),
                                       ("verilator", (32, 32))])
def test_rtl_render_every_ray_type_equals_model(sim, size):
    model = _model(size)
    types = _per_type(model)
    assert set(types) == set(RAY_TYPES)
    for name in RAY_TYPES:
        assert types[name]["rays"] > 0 and types[name]["hits"] > 0, (name, types[name])
    assert set(model.layers) >= set(LAYERS)
    for name in ("reflection_tri", "refraction_tri"):
        assert (model.layers[name] >= 0).any(), name
    assert np.nanmax(model.layers["glossy_hit"]) > 0
    assert np.nanmin(model.layers["ao"]) < 1

    backend = make_backend("rtl", FP24, mode="paper", sim=sim)
    try:
        rtl = render(_scene(), backend, _settings(*size))
        sizes = {(c.rows, c.cols) for c in backend.session_stats}
    finally:
        backend.close()
    assert sizes == {(2, 2), (1, 1)}
    for name in ("image", "tri_id", "t", "visibility"):
        a, b = getattr(rtl, name), getattr(model, name)
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), name
    assert set(rtl.layers) == set(model.layers)
    for name, layer in model.layers.items():
        a = rtl.layers[name]
        assert np.array_equal(a, layer, equal_nan=a.dtype.kind == "f"), name
    unit_rtl = {k: v for k, v in rtl.stats["unit"].items() if not k.startswith(("_", "cycles"))}
    assert unit_rtl == model.stats["unit"]
    assert _per_type(rtl) == types
