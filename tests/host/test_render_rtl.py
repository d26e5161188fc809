"""An RTL render equals the model render bit for bit, under both simulators.

A small scene (a soup of 16 triangles on a floor): 2x2 primary bundles and 2x2 soft-shadow
bundles (one unit configuration for the whole render; the same
configuration, so the same cached simulator build, as the 2x2 bundles of
``host/test_render_secondary_rtl.py``; two live simulations of it share each round, and
one alone on Verilator), with
early-out rounds, through the intersection unit's Verilog (the job-stream harness of
:mod:`raplas_hdl.sim.drive.unit_harness`: the scene loaded once, then one round of runs per pass
and early-out batch) and through the golden model. Image, nearest triangle per pixel,
visibility and the unit's counters must agree. Verilator renders 32x32 pixels; Icarus,
some 30x slower on this unit, renders 8x4. A missing simulator is an error, not a skip.
"""

import numpy as np
import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.host.backends import make_backend
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene


@pytest.mark.parametrize("sim, size, instances", [("icarus", (8, 4), 2),
                                                  ("verilator", (32, 32), 2),
                                                  ("verilator", (32, 32), 1)])
def test_rtl_render_equals_model(sim, size, instances):
    scene = get_scene("soup", n=16)
    st = RenderSettings(*size, rows=2, cols=2, shadow_rows=2, shadow_cols=2, tris_per_sphere=4,
                        batch_spheres=4, chunk=4096, progress=False)
    model = render(scene, make_backend("model", FP24, mode="paper"), st)
    backend = make_backend("rtl", FP24, mode="paper", sim=sim)
    backend.instances = instances
    rtl = render(scene, backend, st)
    np.testing.assert_array_equal(rtl.tri_id, model.tri_id)
    np.testing.assert_array_equal(rtl.image, model.image)
    np.testing.assert_array_equal(rtl.visibility, model.visibility)
    unit_rtl = {k: v for k, v in rtl.stats["unit"].items() if not k.startswith(("_", "cycles"))}
    assert unit_rtl == model.stats["unit"]
    assert model.stats["shadow_bundles"] > 0 and model.stats["hits"] > 0
    # one configuration's live simulations served the primary pass and every shadow round
    (stats,) = backend.session_stats.values()
    assert stats["instances"] == instances
    assert stats["rounds"] >= 3 * instances and stats["cycles"] > 0
    backend.close()
    assert not backend._sessions


def test_rounds_are_shared_in_order_and_balanced():
    """A round's runs go to the instances as contiguous shares of about equal sphere
    counts (the results are put back in run order by concatenation)."""
    backend = make_backend("rtl", FP24, mode="paper", sim="icarus")
    sizes = [5, 1, 1, 9, 2, 2, 3, 7, 1, 4]
    runs = [(k, np.arange(n)) for k, n in enumerate(sizes)]
    for instances in (1, 2, 3):
        backend.instances = instances
        shares = backend._shares(runs)
        assert len(shares) == min(instances, len(runs))
        assert [r[0] for s in shares for r in s] == list(range(len(runs)))
        load = [sum(1 + r[1].size for r in s) for s in shares]
        assert max(load) - min(load) <= 1 + max(sizes)
    backend.instances = 4
    assert [len(s) for s in backend._shares(runs[:2])] == [1, 1]
    from raplas_hdl.host.backends.rtl import RtlBackend

    with pytest.raises(ValueError, match="instances"):
        RtlBackend(FP24, "paper", sim="icarus", instances=0)
