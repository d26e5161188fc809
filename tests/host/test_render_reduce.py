"""Rendering through the on-chip reduction (issue 15, item 3, the host side).

``ModelBackend(reduce=True)`` and ``RtlBackend(reduce=True)`` hand the unit each bundle's
window (``tmin`` rounded up, per-ray ``tmax`` rounded down, the excluded triangle, the
any-hit bit) and fold only the ANSWER beats that leave it. A render through them must equal
the render without the reduction on every pixel: the image, the nearest triangle and its
``t``, the visibility. The model's reduced path must also count the same unit counters
(it has no early-out) and far fewer output beats; the RTL's any-hit early-out may issue fewer
pairs, never more, and culls the same spheres. Then the command-line options: ``--reduce``
of ``render``, ``verilog`` and ``cosim``, and the cosim's comparison of ANSWER beats.
"""

import functools
import subprocess
import sys

import numpy as np
import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.host.backends import ModelBackend, make_backend
from raplas_hdl.host.output import format_summary
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene

PIXELS = ("image", "tri_id", "t", "visibility")
EXACT = ("spheres", "plane_tests", "pairs_skipped")


def _settings(size, **kw):
    return RenderSettings(size, size, rows=2, cols=2, shadow_rows=2, shadow_cols=2,
                          tris_per_sphere=4, batch_spheres=4, progress=False, **kw)


@functools.cache
def _model(scene, size, reduce=False, **kw):
    backend = make_backend("model", FP24, mode="paper", reduce=reduce)
    return render(get_scene(scene), backend, _settings(size, **kw)), backend


def _same_pixels(a, b):
    for name in PIXELS:
        x, y = getattr(a, name), getattr(b, name)
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name


@pytest.mark.parametrize("scene, size", [("cornell", 16), ("stanford-bunny", 16)])
def test_model_reduce_equals_unreduced(scene, size):
    plain, pb = _model(scene, size)
    red, rb = _model(scene, size, True)
    assert (plain.tri_id >= 0).any() and (np.nan_to_num(plain.visibility, nan=1.0) < 1).any()
    _same_pixels(red, plain)
    assert red.stats["unit"] == plain.stats["unit"]
    # the same unreduced traffic counted both ways, and the answers far fewer
    assert rb.beats["result"] == pb.beats["result"] >= plain.stats["unit"]["pairs_issued"]
    assert 0 < rb.beats["answer"] < rb.beats["result"] // 4
    assert pb.beats["answer"] == 0
    assert red.stats["output_beats"] == rb.beats and "output_beats" not in plain.stats
    assert f"{rb.beats['answer']:,} answer beats" in format_summary(red)
    # the warm-up pass counts nothing: every issued pair is one beat, plus runs without pairs
    assert rb.beats["result"] - plain.stats["unit"]["pairs_issued"] < plain.stats["unit"][
        "spheres"]


def test_model_reduce_secondary_rays():
    """Reflection, refraction, glossy and AO passes (nearest and any-hit) through the
    reduction equal the unreduced render, layers included."""
    kw = {"depth": 2, "glossy_rows": 2, "glossy_cols": 2, "ao_rows": 2, "ao_cols": 2}
    plain, _ = _model("small", 12, **kw)
    red, _ = _model("small", 12, True, **kw)
    _same_pixels(red, plain)
    assert plain.layers and set(red.layers) == set(plain.layers)
    for name, layer in plain.layers.items():
        assert np.array_equal(red.layers[name], layer, equal_nan=layer.dtype.kind == "f"), name


def _rtl_equals_model(sim, size):
    plain, _ = _model("cornell", size)
    backend = make_backend("rtl", FP24, mode="paper", sim=sim, reduce=True)
    try:
        red = render(get_scene("cornell"), backend, _settings(size))
        configs = list(backend.session_stats)
    finally:
        backend.close()
    assert configs and all(c.reduce for c in configs)
    _same_pixels(red, plain)
    got, want = red.stats["unit"], plain.stats["unit"]
    assert {k: got[k] for k in EXACT} == {k: want[k] for k in EXACT}
    assert got["pairs_issued"] <= want["pairs_issued"]      # the any-hit early-out
    _, model = _model("cornell", size, True)
    assert backend.beats["answer"] == model.beats["answer"] > 0
    assert backend.beats["result"] <= model.beats["result"]
    assert backend.beats["answer"] < backend.beats["result"] // 10
    return backend


def test_rtl_reduce_render_icarus():
    """cornell 6x6, 2x2 primary and shadow bundles, through the reduced unit's Verilog."""
    _rtl_equals_model("icarus", 6)


@pytest.mark.full
def test_rtl_reduce_render_verilator():
    _rtl_equals_model("verilator", 16)


def test_reduce_refused():
    with pytest.raises(ValueError, match="float64 backend"):
        make_backend("float64", reduce=True)
    with pytest.raises(ValueError, match="conservative"):
        ModelBackend(FP24, "conservative", reduce=True)


# -- the command line ---------------------------------------------------------------------

def _cli(*argv):
    res = subprocess.run([sys.executable, "-m", "raplas_hdl", *map(str, argv)],
                         capture_output=True, text=True, timeout=600, check=False)
    return res.returncode, res.stdout, res.stderr


@pytest.mark.parametrize("argv, needle", [
    (["render", "--reduce", "--backend", "float64"], "--reduce does not apply to --backend "
                                                     "float64"),
    (["render", "--reduce", "--mode", "conservative"], "--reduce has no conservative mode"),
    (["render", "--reduce", "--exp-bits", "6", "--man-bits", "25"], "man_bits <= 24"),
    (["verilog", "fp-add", "--reduce"], "--reduce does not apply to unit fp-add"),
    (["cosim", "intersection-unit", "--reduce", "--sim", "icarus", "--vectors", "x.vec"],
     "--vectors does not apply with --reduce"),
    (["cosim", "ray-triangle", "--reduce", "--sim", "icarus"],
     "--reduce does not apply to unit ray-triangle"),
])
def test_cli_errors(tmp_path, argv, needle):
    rc, out, err = _cli(*argv, "-o", tmp_path / "x.png") if argv[0] == "render" else \
        _cli(*argv, *(["-o", tmp_path / "x.v"] if argv[0] == "verilog" else []))
    assert rc == 2 and out == "", out
    assert err.count("\n") == 1 and err.startswith(f"raplas-hdl {argv[0]}: error:"), err
    assert needle in err, err


def test_verilog_reduce_builds_reduced_unit():
    """``verilog intersection-unit --reduce`` reaches the unit's configuration (the
    emission itself is the unit's own tests' work)."""
    from raplas_hdl.rtl.units import build_unit

    _, comp, opts = build_unit("intersection-unit", FP24, rows=2, cols=2, reduce=True)
    assert opts["reduce"] is True and comp.config.reduce
    _, comp, _ = build_unit("intersection-unit", FP24, rows=2, cols=2)
    assert not comp.config.reduce


def test_cosim_compares_answers():
    """The cosim of the reduced unit flags a changed ANSWER field and an any-hit counter
    above the model's, and accepts fewer issued pairs in an any-hit run."""
    from raplas_hdl.sim.cosim import unit_cosim

    u = unit_cosim("intersection-unit", FP24, {"rows": 2, "cols": 2, "tris_per_sphere": 2,
                                               "reduce": True})
    cases = u.random(12, 3)
    want = u.expected(cases)
    assert any(want["any_hit"]) and not all(want["any_hit"])
    assert all(s.dtype.names[-1] == "empty" for s, _ in want["runs"])
    k = next(i for i, (s, _) in enumerate(want["runs"]) if not s["empty"].any())
    a = next(i for i, h in enumerate(want["any_hit"]) if h
             and want["runs"][i][1]["pairs_issued"] > 0)
    assert u.mismatches(want, want) == [None] * 12
    runs = [(s.copy(), dict(c)) for s, c in want["runs"]]
    runs[k][0]["t"][0] ^= 1
    runs[a][1]["pairs_issued"] -= 1           # the early-out dropped a pair: accepted
    bad = u.mismatches(want, {"runs": runs})
    assert [i for i, m in enumerate(bad) if m] == [k]
    assert any("t " in line and "differs" in line for line in bad[k])
    runs = [(s.copy(), dict(c)) for s, c in want["runs"]]
    runs[a][1]["pairs_issued"] += 1
    bad = u.mismatches(want, {"runs": runs})
    assert [i for i, m in enumerate(bad) if m] == [a]


@pytest.mark.full
def test_cosim_reduce_icarus():
    rc, out, err = _cli("cosim", "intersection-unit", "--reduce", "--sim", "icarus", "--rows",
                        "2", "--cols", "2", "--tris-per-sphere", "2", "--random", "8")
    assert rc == 0, out + err
    assert "cases: 8\n" in out and "mismatches: 0\n" in out, out
