"""The conservative mode's render: the unit's hits are a superset of R's, re-checked on the host.

The conservative unit never misses a hit of the exact reference R inside its domain, but it
also reports false hits in a band around every triangle (docs/conservative-mode.md). Folded
as real hits, these took the pixel wherever a neighbour is coplanar (equal ``t``, lower ID)
or nearer, and blocked shadow rays: the showcase at 24x24 was at PSNR 15.9 dB against
float64, the nearest triangle differing on 49 % of pixels. The render now resolves each of
the unit's hits as an uncertain pair (the certified mode's float64 filter and exact
resolution), so a conservative render is R's.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.host.backends import ModelBackend
from raplas_hdl.host.reference import compare_reference, exact_reference
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene
from tests.support.render import RAW_CONSERVATIVE

SMALL = RenderSettings(width=16, height=16, progress=False, record_rays=True)


@pytest.mark.parametrize("name", ["showcase", "soup"])
def test_conservative_render_equals_exact_reference(name):
    scene = get_scene(name)
    settings = RenderSettings.for_scene(scene, width=16, height=16, progress=False,
                                        record_rays=True, depth=0, glossy_rows=0,
                                        glossy_cols=0, ao_rows=0, ao_cols=0)
    result = render(scene, ModelBackend(FP24, mode="conservative"), settings)
    ref = exact_reference(result, scene.triangles, "tree")
    assert compare_reference(result, ref) == {"pixels": 256, "tri_id_differ": 0,
                                              "visibility_differ": 0}
    # the unit's hits really were a superset: folded raw, the same render is not R's
    raw = render(scene, ModelBackend(FP24, mode=RAW_CONSERVATIVE), settings)
    assert compare_reference(raw, exact_reference(raw, scene.triangles, "tree"))[
        "tri_id_differ"] > 0


def test_reduce_refuses_conservative(tmp_path):
    """The on-chip reduction would pick the nearest of the superset: refused, one line."""
    with pytest.raises(ValueError, match="no conservative mode"):
        ModelBackend(FP24, "conservative", reduce=True)
    res = subprocess.run([sys.executable, "-m", "raplas_hdl", "render", "--reduce", "--mode",
                          "conservative", "-o", str(tmp_path / "x.png")],
                         capture_output=True, text=True, timeout=600, check=False)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.count("\n") == 1, res.stderr
    assert res.stderr.startswith("raplas-hdl render: error: --reduce has no conservative mode")


def test_rtl_conservative_render_equals_model_and_reference():
    """The RTL's conservative stream goes through the same filter and resolution, in stream
    order: the render equals the model's bit for bit, and R (Icarus, 8x4 pixels)."""
    import numpy as np

    from raplas_hdl.host.backends import make_backend

    scene = get_scene("soup", n=16)
    st = RenderSettings(8, 4, rows=2, cols=2, shadow_rows=2, shadow_cols=2, tris_per_sphere=4,
                        batch_spheres=4, chunk=4096, progress=False, record_rays=True)
    model = render(scene, make_backend("model", FP24, mode="conservative"), st)
    backend = make_backend("rtl", FP24, mode="conservative", sim="icarus")
    try:
        rtl = render(scene, backend, st)
    finally:
        backend.close()
    np.testing.assert_array_equal(rtl.tri_id, model.tri_id)
    np.testing.assert_array_equal(rtl.t, model.t)
    np.testing.assert_array_equal(rtl.image, model.image)
    np.testing.assert_array_equal(rtl.visibility, model.visibility)
    assert model.stats["hits"] > 0 and rtl.stats["hits"] == model.stats["hits"]
    assert compare_reference(rtl, exact_reference(rtl, scene.triangles, "exact")) == {
        "pixels": 32, "tri_id_differ": 0, "visibility_differ": 0}
