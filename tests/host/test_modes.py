"""Render modes: a mode registered from here alone renders, and the registry's errors."""

import numpy as np
import pytest

from raplas_hdl.engine.passes import COUNTER_NAMES
from raplas_hdl.fp import FP24
from raplas_hdl.host.backends import ModelBackend, make_backend
from raplas_hdl.host.modes import PaperMode, RenderMode, get_mode, mode_names, register_mode
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene

SETTINGS = RenderSettings(width=16, height=16, rows=4, cols=4, shadow_rows=2, shadow_cols=2,
                          progress=False)


class CountingMode(PaperMode):
    """The paper mode, counting the passes and pairs it folds and reporting them."""

    name = "test-counting"

    def new_stats(self):
        return {"passes": 0, "pairs": 0}

    def trace_compiled(self, backend, batch, *args):
        ctr = super().trace_compiled(backend, batch, *args)
        backend.mode_stats["passes"] += 1
        backend.mode_stats["pairs"] += int(ctr[:, COUNTER_NAMES.index("pairs_issued")].sum())
        return ctr

    def report(self, backend, stats):
        stats["counting"] = dict(backend.mode_stats)


register_mode(CountingMode())


def test_a_registered_mode_renders_as_its_parent_and_reports():
    scene = get_scene("cornell")
    paper = render(scene, make_backend("model", FP24, mode="paper"), SETTINGS)
    backend = make_backend("model", FP24, mode="test-counting")
    assert backend.mode == "paper" and "test-counting" in backend.describe()
    counted = render(scene, backend, SETTINGS)
    np.testing.assert_array_equal(counted.image, paper.image)
    np.testing.assert_array_equal(counted.tri_id, paper.tri_id)
    c = counted.stats["counting"]
    # the warm-up pass is not counted; a primary pass and the shadow rounds are
    assert c["passes"] >= 2
    assert c["pairs"] == paper.stats["pairs_issued"] > 0
    assert "counting" not in paper.stats


def test_observers_see_every_pass():
    scene = get_scene("cornell")
    backend = ModelBackend(FP24, "paper")
    seen = []
    backend.observers.append(lambda batch, run_b, *rest: seen.append((batch.n_bundles,
                                                                      len(run_b), rest[-1])))
    res = render(scene, backend, SETTINGS)
    assert len(seen) >= 3          # the warm-up, the primary pass, a shadow round
    assert seen[1][2] is False and seen[-1][2] is True     # nearest, then any-hit
    assert all(b > 0 and 0 < n <= b for b, n, _ in seen[1:])
    assert res.stats["shadow_bundles"] > 0


def test_built_in_modes_in_order():
    assert mode_names()[:3] == ("paper", "conservative", "certified")
    assert get_mode("certified").unit_mode == "certified"


def test_unknown_mode_is_one_line():
    with pytest.raises(ValueError, match=r"^mode must be one of paper, conservative, "
                                         r"certified.*not 'nope'$"):
        make_backend("model", FP24, mode="nope")


def test_a_name_is_registered_once():
    class Other(RenderMode):
        name = "test-counting"

    with pytest.raises(ValueError, match="already registered"):
        register_mode(Other())

    class BadUnit(RenderMode):
        name = "test-bad-unit"
        unit_mode = "exact"

    with pytest.raises(ValueError, match="mode must be one of"):
        register_mode(BadUnit())
    assert "test-bad-unit" not in mode_names()


def test_a_mode_without_reduction_refuses_reduce():
    class Plain(RenderMode):
        name = "test-plain"

    register_mode(Plain())
    with pytest.raises(ValueError, match="on-chip reduction has no test-plain mode"):
        ModelBackend(FP24, "test-plain", reduce=True)


def test_the_cli_renders_with_a_registered_mode(tmp_path, capsys):
    """``render --mode`` takes the registry's names, so the mode registered above renders
    from the command line with no change to the CLI; an unknown name is one line, exit 2."""
    from raplas_hdl.cli import main

    out = tmp_path / "c.png"
    assert main(["render", "--scene", "cornell", "--size", "16x16", "--mode", "test-counting",
                 "-o", str(out)]) == 0
    assert out.exists() and "test-counting" in capsys.readouterr().out
    assert main(["render", "--mode", "no-such-mode", "-o", str(tmp_path / "d.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mode must be one of paper, conservative, certified, " in err[0]
    assert "test-counting" in err[0] and err[0].endswith("not 'no-such-mode'")
