"""``raplas-hdl bench --quick``: the sweep runs end to end and its report says what issue 6
asks (every metric at every point, FP32 more accurate than FP16 on every scene, positive
costs, the FP24 synthesis targets). One run (module fixture, about 3 minutes on a cold
cache: numba compile and Yosys for the FP24 multiplier and plane-sphere tester included).
Under pytest-xdist the workers share the one run through a lock file (the recipe of the
pytest-xdist documentation), so ``make test`` runs the sweep once."""

import fcntl
import json
import math

import pytest

from raplas_hdl.bench.pareto import pareto_front
from raplas_hdl.bench.sweep import MODEL_METRICS, missing_metrics
from raplas_hdl.cli import main


@pytest.fixture(scope="module")
def quick(tmp_path_factory, worker_id):
    # one directory for all xdist workers of this session (the parent of each worker's)
    root = tmp_path_factory.getbasetemp()
    if worker_id != "master":
        root = root.parent
    out = root / "bench-quick"
    report = out / "bench.md"
    with open(root / "bench-quick.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (out / "results.json").exists():
            assert main(["bench", "--quick", "--quiet", "--out-dir", str(out),
                         "--report", str(report)]) == 0
        fcntl.flock(lock, fcntl.LOCK_UN)
    results = json.loads((out / "results.json").read_text())
    return out, report, results


def _model(results):
    return [p for p in results["points"] if p["backend"] == "model"]


def _by(results, fmt, scene):
    r0, m = results["spec"]["roundings"][0], "paper"
    hits = [p for p in _model(results) if p["format"] == fmt and p["scene"] == scene
            and p["rounding"] == r0 and p["mode"] == m and p["grid"] == "main"]
    assert len(hits) == 1, f"expected one {fmt} {r0} paper point on {scene}, got {len(hits)}"
    return hits[0]


def test_bench_quick_covers_the_quick_axes(quick):
    _, _, results = quick
    model = _model(results)
    assert {p["format"] for p in model} >= {"FP16", "FP24", "FP32"}
    assert len({p["scene"] for p in model}) >= 2
    assert {p["backend"] for p in results["points"]} == {"float64", "model"}


def test_bench_quick_every_point_has_every_metric(quick):
    _, _, results = quick
    for p in results["points"]:
        bad = missing_metrics(p)
        assert not bad, f"{p['backend']} {p['format']} {p['scene']}: missing {bad}"
    model = _model(results)
    assert model and all(set(MODEL_METRICS) <= set(p) for p in model)


def test_bench_quick_fp32_t_error_below_fp16_on_each_scene(quick):
    _, _, results = quick
    for scene in {p["scene"] for p in _model(results)}:
        lo, hi = _by(results, "FP32", scene), _by(results, "FP16", scene)
        assert lo["t_pairs"] > 0 and hi["t_pairs"] > 0, f"{scene}: no in-domain hit pairs"
        assert lo["t_rel_median"] < hi["t_rel_median"], (
            f"{scene}: median rel. error of t FP32 {lo['t_rel_median']:.3g} is not below "
            f"FP16 {hi['t_rel_median']:.3g}")


def test_bench_quick_fp32_pixel_error_below_fp16_on_each_scene(quick):
    _, _, results = quick
    for scene in {p["scene"] for p in _model(results)}:
        lo, hi = _by(results, "FP32", scene), _by(results, "FP16", scene)
        assert lo["tri_differs_in_domain"] < hi["tri_differs_in_domain"], (
            f"{scene}: in-domain pixels whose triangle differs FP32 "
            f"{lo['tri_differs_in_domain']:.4f} not below FP16 {hi['tri_differs_in_domain']:.4f}")


def test_bench_quick_cost_columns_positive(quick):
    _, _, results = quick
    for p in results["points"]:
        for k in ("t_total", "rays_per_s", "pairs_per_s"):
            assert p[k] > 0, f"{p['backend']} {p['format']} {p['scene']}: {k} = {p[k]}"
        if p["backend"] == "model":
            for k in ("hw_dsp48", "hw_luts", "hw_ffs", "hw_slices", "hw_cost"):
                assert p[k] > 0, f"{p['format']}/{p['rounding']}: {k} = {p[k]}"


def test_bench_quick_fp24_multiplier_uses_one_dsp48(quick):
    _, _, results = quick
    assert results["synth_checks"]["fp-mul"]["dsp48"] == 1


def test_bench_quick_fp24_plane_sphere_tester_at_most_3_dsp48(quick):
    _, _, results = quick
    assert results["synth_checks"]["plane-sphere-tester"]["dsp48"] <= 3


def test_bench_quick_writes_report_and_plots(quick):
    out, report, results = quick
    text = report.read_text()
    for heading in ("## Pareto fronts", "### What \"cost\" means", "## Against R",
                    "## Hardware cost per format", "**Command**", "**Machine**"):
        assert heading in text, f"report lacks {heading!r}"
    for name in ("results.csv", "pareto_time.png", "pareto_hw.png", "error_by_format.png"):
        assert (out / name).stat().st_size > 1000, f"{name} missing or empty"
    assert results["fronts"], "no Pareto front in results.json"


def test_pareto_front_keeps_only_nondominated_rows():
    rows = [{"e": 3.0, "c": 1.0}, {"e": 2.0, "c": 2.0}, {"e": 2.5, "c": 3.0},
            {"e": 1.0, "c": 4.0}, {"e": 1.0, "c": 5.0}, {"e": math.nan, "c": 0.5}]
    assert pareto_front(rows, "e", "c") == [0, 1, 3]
