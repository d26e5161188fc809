"""The sweep's model backend: a pass cut into slices renders and counts as the whole pass."""

import numpy as np

from raplas_hdl.bench import instrumented
from raplas_hdl.fp import FP24
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene

SETTINGS = RenderSettings(width=32, height=32, rows=4, cols=4, shadow_rows=2, shadow_cols=2,
                          progress=False)


def test_a_pass_in_slices_renders_and_counts_as_whole(monkeypatch):
    scene = get_scene("cornell")
    whole = instrumented.SweepBackend(FP24, "paper", sample_pairs=10**9)
    ref = render(scene, whole, SETTINGS)
    # slices of about an eighth of the budget, the budget twice the render's pairs
    monkeypatch.setattr(instrumented, "MIN_SLICE_PAIRS", 1)
    sliced = instrumented.SweepBackend(FP24, "paper", sample_pairs=10**9,
                                       pair_budget=2 * whole.pairs_issued)
    slices = []
    sliced.on_slice.append(lambda batch, run_b, *rest: slices.append(len(run_b)))
    res = render(scene, sliced, SETTINGS)
    assert len(slices) > 2 * len(whole.device_passes())          # passes really were cut
    np.testing.assert_array_equal(res.image, ref.image)
    np.testing.assert_array_equal(res.tri_id, ref.tri_id)
    assert res.stats["unit"] == ref.stats["unit"]
    assert sliced.pairs_issued == whole.pairs_issued > 0
    assert sliced.device_passes() == whole.device_passes()
    assert ([r["ids"] for r in sliced.sampler.records] != []
            and sum(len(r["ids"]) for r in sliced.sampler.records)
            == sum(len(r["ids"]) for r in whole.sampler.records))


def test_the_budget_stops_the_render_near_it(monkeypatch):
    monkeypatch.setattr(instrumented, "MIN_SLICE_PAIRS", 1)
    backend = instrumented.SweepBackend(FP24, "paper", pair_budget=2000)
    try:
        render(get_scene("cornell"), backend, SETTINGS)
    except instrumented.PairBudgetExceeded as exc:
        assert exc.budget == 2000 and 2000 < exc.pairs <= 2000 + 2000
    else:
        raise AssertionError("the render went over its budget without stopping")
