"""``raplas-hdl bench --quick``: the sweep runs end to end and its report says what issue 6
asks (every metric at every point, FP32 more accurate than FP16 on every scene, positive
costs, the FP24 synthesis targets, the device frame time and link traffic recomputed from
the counters, a capped point flagged). One run (module fixture, under a minute with warm
caches; a few minutes on a cold one: numba compile and Yosys for the FP24 multiplier and
plane-sphere tester included).
Under pytest-xdist the workers share the one run through a lock file (the recipe of the
pytest-xdist documentation), so ``make test`` runs the sweep once."""

import fcntl
import math

import pytest

from raplas_hdl.bench.pareto import pareto_front
from raplas_hdl.bench.report import load_results
from raplas_hdl.bench.metrics import CAPPED_METRICS, MODEL_METRICS, missing_metrics
from raplas_hdl.cli import main
from raplas_hdl.model.records import RESULT


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
    results = load_results(out / "results.json")     # non-finite values back to floats
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
    model = [p for p in _model(results) if not p["capped"]]
    assert model and all(set(MODEL_METRICS) <= set(p) for p in model)
    assert all(set(CAPPED_METRICS) <= set(p) for p in _model(results) if p["capped"])


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
        for k in ("t_total", "cpu_total") + (() if p.get("capped") else
                                              ("rays_per_s", "pairs_per_s")):
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
                    "## Hardware cost per format", "**Command**", "**Machine**",
                    "## Frame time on the device", "**Capped points**"):
        assert heading in text, f"report lacks {heading!r}"
    for name in ("results.csv", "pareto_time.png", "pareto_hw.png", "pareto_device.png",
                 "error_by_format.png"):
        assert (out / name).stat().st_size > 1000, f"{name} missing or empty"
    assert results["fronts"], "no Pareto front in results.json"


def _cycles(passes, mode):
    """The device model of docs/bench.md, written out again: per run P plane loads, G
    clocks per sphere, the array's latency G + 18 (the tester's 17 and the decoder), one
    clock per pair, the ray-triangle latency (41 paper, 47 conservative)."""
    l_rt = 41 if mode == "paper" else 47
    total = 0
    for q in passes:
        planes = q["rows"] + q["cols"]
        g = -(-planes // q["testers"])
        assert g == q["passes"], f"{q}: passes {q['passes']}, expected {g}"
        total += q["runs"] * (planes + g + 18 + l_rt) + q["spheres"] * g + q["pairs"]
    return total


def test_bench_quick_device_frame_time_recomputed_from_counters(quick):
    _, _, results = quick
    clock = results["device"]["clock_mhz"] * 1e6
    fitting = 0
    for p in _model(results):
        name = f"{p['grid']} {p['format']} {p['mode']} {p['scene']}"
        cycles = _cycles(p["device_passes"], p["mode"])
        assert p["device_cycles"] == cycles, f"{name}: cycles {p['device_cycles']} != {cycles}"
        if not p["capped"]:
            assert sum(q["pairs"] for q in p["device_passes"]) == p["pairs_issued"], name
            assert sum(q["spheres"] for q in p["device_passes"]) == p["unit_spheres"], name
        assert p["device_cycles_overlap"] <= p["device_cycles"], name
        if p["device_units"] == 0:
            assert p["device_frame_s"] == math.inf and p["device_fps"] == 0, name
            continue
        fitting += 1
        expected = cycles / p["device_units"] / clock
        assert p["device_frame_s"] > 0, f"{name}: device frame time {p['device_frame_s']}"
        assert p["device_frame_s"] == pytest.approx(expected, rel=1e-12), (
            f"{name}: frame {p['device_frame_s']} s != cycles/units/clock {expected} s")
        assert p["device_fps"] == pytest.approx(1.0 / expected, rel=1e-12), name
    assert fitting >= 4, "fewer than 4 quick points fit on the device"


def test_bench_quick_fp32_unit_does_not_fit_and_fp24_is_the_synthesised_one(quick):
    _, _, results = quick
    assert results["costs"]["FP24/rtz"]["device"]["basis"] == "synthesised"
    assert results["costs"]["FP24/rtz"]["device"]["units"] >= 1
    assert results["costs"]["FP32/rtz"]["device"]["units"] == 0


def test_bench_quick_link_traffic_is_pairs_times_beat_bits(quick):
    _, _, results = quick
    for p in _model(results):
        name = f"{p['grid']} {p['format']} {p['scene']}"
        bits = RESULT.bind(p["link_params"]).size
        assert p["link_beat_bits"] == bits, f"{name}: beat {p['link_beat_bits']} != {bits}"
        assert p["link_params"]["W"] == {"FP16": 16, "FP24": 24, "FP32": 32}[p["format"]]
        assert p["link_bits"] == p["pairs_issued"] * bits, (
            f"{name}: link bits {p['link_bits']} != {p['pairs_issued']} pairs x {bits}")
        assert p["link_bits_per_s"] == pytest.approx(p["link_bits"] * p["device_fps"],
                                                     rel=1e-12), name


def test_bench_quick_capped_point_is_flagged(quick):
    _, report, results = quick
    capped = [p for p in _model(results) if p["grid"] == "cap"]
    assert len(capped) == 1, f"expected one cap point, got {len(capped)}"
    p = capped[0]
    assert p["capped"] is True and p["max_pairs"] == results["spec"]["probe_cap"] == 1000
    assert p["capped_reason"], "a capped point says why"
    assert p["pairs_issued"] > p["max_pairs"], "a capped point's pairs are over its cap"
    assert not missing_metrics(p), f"capped point lacks {missing_metrics(p)}"
    assert not any(q["capped"] for q in _model(results) if q["grid"] == "main"), (
        "a main quick point came out capped")
    assert "**capped**" in report.read_text()


def test_bench_quick_pair_sample_streams_match_the_trace(quick):
    _, _, results = quick
    for p in _model(results):
        if p["capped"]:
            continue
        name = f"{p['format']} {p['scene']}"
        assert p["sample_stream_mismatch"] == 0, f"{name}: streamed runs differ from trace"
        assert 0 < p["pairs_sampled"] <= results["spec"]["pair_sample"] + 20000, name


def test_bench_report_handles_capped_points_in_every_grid(quick, tmp_path):
    """A capped point in the main grid (the real sizes have them: conservative FP16 on a
    mesh) has no pixel errors: the report, plots and fronts still come out, and its
    configuration takes no part in the fronts."""
    import copy

    from raplas_hdl.bench.pareto import aggregate, fronts
    from raplas_hdl.bench.report import write_outputs
    from raplas_hdl.bench.metrics import CAPPED_METRICS

    _, _, results = quick
    res = copy.deepcopy(results)
    victim = next(p for p in res["points"] if p["backend"] == "model" and p["grid"] == "main"
                  and p["format"] == "FP16")
    keep = set(CAPPED_METRICS) | {"grid", "backend", "format", "rounding", "mode", "scene",
                                  "bundle", "size", "bound", "device_passes", "link_params"}
    for k in [k for k in victim if k not in keep]:
        del victim[k]
    victim.update(capped=True, capped_reason="synthetic")
    files = write_outputs(res, tmp_path, tmp_path / "bench.md", command="test")
    assert all(f.exists() for f in files)
    assert "synthetic" in (tmp_path / "bench.md").read_text()
    rows = aggregate(res["points"])
    capped = [i for i, r in enumerate(rows) if r["capped"]]
    assert capped and not any(i in idx for idx in fronts(rows).values() for i in capped)


def test_device_model_latencies_match_the_rtl():
    from raplas_hdl.bench import cost
    from raplas_hdl.fp import FP24
    from raplas_hdl.rtl.plane_sphere import PlaneSphereArray
    from raplas_hdl.rtl.ray_triangle import RayTriangleUnit

    for mode in ("paper", "conservative"):
        rtu = RayTriangleUnit(FP24, mode=mode)
        rtu._MustUse__silence = True                  # built only to be inspected
        assert rtu.latency == cost.rt_latency(mode), mode
    for rows, cols in ((4, 4), (8, 8), (3, 3)):
        arr = PlaneSphereArray(FP24, rows=rows, cols=cols, testers=cost.DEVICE_TESTERS)
        arr._MustUse__silence = True
        g = -(-(rows + cols) // cost.DEVICE_TESTERS)
        assert arr.latency == cost.array_latency(g), (rows, cols)


def test_pareto_front_keeps_only_nondominated_rows():
    rows = [{"e": 3.0, "c": 1.0}, {"e": 2.0, "c": 2.0}, {"e": 2.5, "c": 3.0},
            {"e": 1.0, "c": 4.0}, {"e": 1.0, "c": 5.0}, {"e": math.nan, "c": 0.5}]
    assert pareto_front(rows, "e", "c") == [0, 1, 3]
