"""The render pipeline, its backends and the ``render`` command."""

import json

import numpy as np
import pytest

from raplas_hdl.cli import main
from raplas_hdl.fp import FP24, FP32
from raplas_hdl.host.backends import BackendUnavailable, RtlBackend, make_backend
from raplas_hdl.host.output import compare, format_summary
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene


def _settings(**kw):
    base = {"width": 24, "height": 24, "rows": 8, "cols": 8, "shadow_rows": 2, "shadow_cols": 2,
                "batch_spheres": 4, "progress": False}
    base.update(kw)
    return RenderSettings(**base)


@pytest.fixture(scope="module")
def spheres():
    return get_scene("spheres", subdivisions=1, floor_subdiv=2)


@pytest.fixture(scope="module")
def reference(spheres):
    return render(spheres, make_backend("float64"), _settings())


def test_model_fp32_close_to_float64(spheres, reference):
    res = render(spheres, make_backend("model", FP32, mode="paper"), _settings())
    cmp = compare(res, reference)
    assert cmp["hit_differs"] == 0.0
    assert cmp["tri_differs"] <= 0.01
    assert cmp["psnr"] > 40.0
    assert reference.stats["pixels_hit"] > 0.5 * 24 * 24


def test_early_out_and_hierarchy_do_not_change_the_image(spheres):
    be = make_backend("model", FP24, mode="paper")
    small = {"width": 16, "height": 16}
    base = render(spheres, be, _settings(**small))
    no_eo = render(spheres, be, _settings(early_out=False, **small))
    flat = render(spheres, be, _settings(hierarchy=False, **small))
    for other in (no_eo, flat):
        np.testing.assert_array_equal(other.image, base.image)
        np.testing.assert_array_equal(other.tri_id, base.tri_id)
        np.testing.assert_array_equal(other.visibility, base.visibility)
    assert base.stats["early_out_pairs_skipped"] > 0
    assert no_eo.stats["early_out_pairs_skipped"] == 0
    assert base.stats["pairs_issued"] < no_eo.stats["pairs_issued"]
    assert flat.stats["host_plane_tests"] == 0
    assert base.stats["hierarchy"]["triangles_dropped"][1] > 0


def test_summary_counts(reference):
    st = reference.stats
    n_px = 24 * 24
    assert st["primary_rays"] == n_px and st["primary_bundles"] == 9
    assert st["shadow_bundles"] + st["points_behind_light"] + st["points_facing_away"] \
        == st["pixels_hit"]
    assert st["shadow_rays"] == 4 * st["shadow_bundles"]
    assert st["brute_force_pairs"] == st["rays"] * st["triangles"]
    assert 0 < st["pairs_issued"] < 0.2 * st["brute_force_pairs"]
    assert st["plane_tests"] == st["host_plane_tests"] + st["unit"]["plane_tests"]
    text = format_summary(reference, compare(reference, reference))
    for word in ("rays", "bundles", "spheres", "plane tests", "pairs", "hits", "events",
                 "time", "PSNR inf"):
        assert word in text
    # the event counters count operations (summed over the issued pairs), not pairs
    assert "(operations)" in text and "(pairs)" not in text
    # the shadows darken some pixels, and the unshadowed ones are fully lit
    vis = reference.visibility[np.isfinite(reference.visibility)]
    assert vis.min() < 0.5 and vis.max() == 1.0


def test_rtl_backend_errors(monkeypatch):
    monkeypatch.setattr(RtlBackend, "DRIVER", "sim.no_such_driver")
    with pytest.raises(BackendUnavailable, match="driver"):
        RtlBackend(FP24, sim="icarus")
    with pytest.raises((BackendUnavailable, ValueError)):
        make_backend("rtl", FP24, sim="no-such-simulator")
    with pytest.raises(ValueError, match="unknown backend"):
        make_backend("gpu")


def test_render_command(tmp_path):
    out = tmp_path / "soup.png"
    ids = tmp_path / "ids.npz"
    js = tmp_path / "s.json"
    diff = tmp_path / "diff.png"
    rc = main(["render", "--scene", "soup", "--size", "16x12", "--backend", "model",
               "--format", "FP24", "--rounding", "chop", "--shadow", "2x2", "--tile", "4x8",
               "--no-progress",
               "--diff", str(diff), "--ids", str(ids), "--json", str(js), "-o", str(out)])
    assert rc == 0
    from PIL import Image

    assert Image.open(out).size == (16, 12) and Image.open(diff).size == (16, 12)
    data = np.load(ids)
    assert data["tri_id"].shape == (12, 16) and (data["tri_id"] >= 0).any()
    summary = json.loads(js.read_text())
    assert summary["comparison"]["psnr"] != 0 and summary["stats"]["primary_rays"] == 192
    # no --mode: the certified render (its stats), whose triangles are R's
    assert "certified" in summary["stats"], sorted(summary["stats"])


def test_render_mode_default_is_certified(tmp_path, capsys):
    from raplas_hdl.cli import build_parser, demo
    from raplas_hdl.cli.render import check

    for cmd, checker in ((["render", "-o", str(tmp_path / "x.png")], check),
                         (["demo"], demo.check)):
        args = build_parser().parse_args(cmd)
        assert args.mode is None
        checker(args)
        assert args.mode == "certified"
    # a format the certified mode cannot take: one line, naming the default and the way out
    for cmd in (["render", "--size", "8x8", "-o", str(tmp_path / "x.png")],
                ["demo", "--no-verilog", "--out-dir", str(tmp_path / "d")]):
        assert main([*cmd, "--exp-bits", "10", "--man-bits", "16"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--mode certified (the default)" in err[0] \
            and "exp_bits <= 9" in err[0] and "--mode paper" in err[0], err
        assert not (tmp_path / "x.png").exists() and not (tmp_path / "d").exists()
    # given explicitly, no "(the default)"; paper takes the format
    assert main(["render", "--mode", "certified", "--exp-bits", "10", "--man-bits", "16",
                 "-o", str(tmp_path / "x.png")]) == 2
    assert "(the default)" not in capsys.readouterr().err
    args = build_parser().parse_args(["render", "--mode", "paper", "--exp-bits", "10",
                                      "--man-bits", "16", "-o", str(tmp_path / "x.png")])
    check(args)
    assert args.mode == "paper"


def test_render_command_errors(tmp_path, capsys):
    assert main(["render", "--scene", "nope", "-o", str(tmp_path / "x.png")]) == 2
    assert "unknown scene" in capsys.readouterr().err
    assert main(["render", "--size", "12", "-o", str(tmp_path / "x.png")]) == 2
    bad = tmp_path / "bad.obj"
    bad.write_text("")
    assert main(["render", "--scene", str(bad), "-o", str(tmp_path / "x.png")]) == 2
    assert "empty" in capsys.readouterr().err


def test_demo_command(tmp_path, capsys):
    rc = main(["demo", "--size", "8x8", "--shadow", "2x2", "--no-verilog", "--no-progress",
               "--out-dir", str(tmp_path)])
    assert rc == 0
    for name in ("cornell_model.png", "cornell_float64.png", "cornell_diff.png",
                 "cornell_summary.json"):
        assert (tmp_path / name).exists()
    out = capsys.readouterr().out
    assert "vs float64: PSNR" in out and "brute force" in out
