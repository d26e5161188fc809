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


def test_stream_rounds_overlap_with_the_streams_and_totals_of_runs_one_at_a_time():
    """The backend's stream rounds are overlapped (the next command while a run goes): the
    same streams as runs one at a time and as the model, the same counter totals, fewer
    clocks; the result beats counted from the streams are those of the model's per-run
    counters; the round's beats decoded at once equal them decoded run by run."""
    from raplas_hdl.engine.passes import COUNTER_NAMES, result_beats, stream_beats
    from raplas_hdl.model.intersection import run_runs

    scene = get_scene("soup", n=16)
    st = RenderSettings(8, 8, rows=2, cols=2, shadow_rows=2, shadow_cols=2, tris_per_sphere=4,
                        batch_spheres=4, chunk=4096, progress=False)
    backend = make_backend("rtl", FP24, mode="paper", sim="verilator")
    seen, run_runs_rtl = [], backend.run_runs

    def spy(config, runs, overlap=False):
        seen.append((config, list(runs), overlap))
        return run_runs_rtl(config, runs, overlap=overlap)

    backend.run_runs = spy
    render(scene, backend, st)
    config, runs, overlap = max(seen, key=lambda s: len(s[1]))
    assert overlap and len(runs) >= 8 and all(o for _, _, o in seen)
    sessions = backend.sessions(config)

    def clocked(ovl):
        c0 = sum(s.cycles for s in sessions)
        out = run_runs_rtl(config, runs, overlap=ovl)
        return out, sum(s.cycles for s in sessions) - c0

    (apart, c_apart), (over, c_over) = clocked(False), clocked(True)
    model = run_runs(config, backend.scene_memory, runs)
    assert c_over < c_apart
    for (s_a, _), (s_o, _), (s_m, _) in zip(apart, over, model):
        np.testing.assert_array_equal(s_o, s_a)
        np.testing.assert_array_equal(s_o, s_m)
    for name in COUNTER_NAMES:
        want = sum(c[name] for _, c in model)
        assert sum(c[name] for _, c in over) == want == sum(c[name] for _, c in apart), name
    assert [c["pairs_issued"] for _, c in apart] == [c["pairs_issued"] for _, c in model]
    per_run = np.array([[c[n] for n in COUNTER_NAMES] for _, c in model])
    assert stream_beats(backend._convert_all(over)) == result_beats(per_run)
    # the round's beats decoded at once, with a run that has no sphere (one empty beat)
    both = over + run_runs(config, backend.scene_memory, [(runs[0][0], np.zeros(0, np.int64))])
    whole = backend._convert_all(both)
    assert whole[-1].ray_id.size == 0 and any(r.hit.any() for r in whole)
    for r, (s, c) in zip(whole, both):              # as run by run
        one = backend._convert(s, c)
        for f in ("ray_id", "tri_id", "hit", "t", "u", "v", "flags"):
            np.testing.assert_array_equal(getattr(r, f), getattr(one, f))
        assert r.counters == one.counters
    backend.close()
