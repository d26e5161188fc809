"""The certified intersection unit (``UnitConfig(mode="certified")``, issue 15 item 3): the
result stream carries each pair's ``outcome`` (0 miss, 1 certain hit, 2 uncertain), and with
the on-chip reduction a run's uncertain pairs leave the unit for the host (``outcome`` 2,
before the run's answers, ``outcome`` 1), so the certified render through the reduced unit
equals the unreduced one.

- the model: outcomes, ``hit`` and ``hits`` agree; the reduced stream against a beat-by-beat
  reference (uncertain pairs passed on, not blocked, not the excluded triangle; answers as the
  paper reduction of the certain hits);
- the RTL against the model, every field of every beat and every counter: the whole unit
  (unreduced and reduced, random runs with windows, gaps and back-pressure; a 6-bit exponent
  and 8-bit fraction format gives many uncertain pairs) and the reducer alone on random
  outcome streams (runs of uncertain pairs stall its output register);
- the host: on real render passes the certified resolution of the reduced stream equals that
  of the unreduced stream, and whole renders through the reduced model are equal;
- the command line: ``verilog``/``cosim``/``render`` with ``--mode certified [--reduce]`` and
  the one-line errors.
"""

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from raplas_hdl.fp import FP24, FPFormat
from raplas_hdl.model.intersection import result_dtype, run_runs
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.records import OUTCOME_HIT, OUTCOME_UNCERTAIN
from raplas_hdl.model.reduction import candidates, first_answers, reduce_run
from raplas_hdl.sim.cosim import unit_cosim
from raplas_hdl.sim.drive.reducer_harness import cosim_reducer, random_runs, window_bundle

#: a format with many uncertain pairs on the cosim's random scenes (about 2.5 % of pairs)
COARSE = FPFormat(6, 8)
CERT = UnitConfig(FP24, rows=2, cols=4, max_triangles=16, mode="certified", reduce=True)


def _cosim(fmt, reduce, n, seed=1, **options):
    c = unit_cosim("intersection-unit", fmt, {"rows": 2, "cols": 2, "mode": "certified",
                                              "reduce": reduce, **options})
    cases = c.random(n, seed)
    return c, cases, c.expected(cases)


# -- the model -------------------------------------------------------------------------------
def test_model_outcomes():
    c, cases, exp = _cosim(COARSE, False, 12)
    beats = np.concatenate([s for s, _ in exp["runs"]])
    assert beats.dtype == result_dtype(c.config) and "outcome" in beats.dtype.names
    real = beats[~beats["empty"].astype(bool)]
    counts = np.bincount(real["outcome"], minlength=3)
    assert counts[1] > 0 and counts[2] > 10 and counts.size == 3
    assert np.array_equal(beats["hit"], beats["outcome"] == OUTCOME_HIT)
    for s, ctr in exp["runs"]:
        assert ctr["hits"] == int((s["outcome"] == OUTCOME_HIT).sum())
    # the same pairs in the same order as the paper unit
    paper = run_runs(replace(c.config, mode="paper"), cases["scene"], cases["runs"])
    for (s, ctr), (p, pc) in zip(exp["runs"], paper):
        assert np.array_equal(s[["ray_id", "tri_id"]], p[["ray_id", "tri_id"]])
        assert {k: v for k, v in ctr.items() if k != "hits"} == \
            {k: v for k, v in pc.items() if k != "hits"}


def _random_outcomes(rng, beats, p_unc=0.3):
    from raplas_hdl.model.records import RESULT_CERTIFIED

    out = np.zeros(beats.size, RESULT_CERTIFIED.dtype())
    for name in beats.dtype.names:
        out[name] = beats[name]
    unc = rng.random(beats.size) < p_unc
    out["outcome"] = np.where(unc, OUTCOME_UNCERTAIN, np.where(beats["hit"], OUTCOME_HIT, 0))
    out["hit"] = out["outcome"] == OUTCOME_HIT
    out["tight"] = out["hit"] & (rng.random(beats.size) < 0.85)
    # near the ray's earlier beat: its t' a few ulps off, its det (folded by the reduction
    # only when certainly ordered)
    last = {}
    for i in range(beats.size):
        ray = int(beats["ray_id"][i])
        j = last.get(ray)
        if j is not None and rng.random() < 0.3 and 8 < int(out["t"][j]) & 0xFFFF < 0xFFF0:
            out["t"][i] = int(out["t"][j]) + int(rng.integers(-2, 3))
            out["det"][i] = out["det"][j]
        last[ray] = i
    if beats["empty"].any():
        out["outcome"] = out["hit"] = out["tight"] = 0
    return out


def _reference(cfg, beats, bundle):
    """The certified reduction one beat at a time (model/ordering.py): a beat is passed on
    when it is uncertain or a certain hit that is not tight, or a tight hit near tmin or
    tmax, unless it is of the excluded triangle or (any-hit) its ray is blocked; a tight hit
    certainly inside the window is a candidate; in a nearest-hit run a candidate near the
    ray's answer is passed on, a certainly nearer one (exact rationals) replaces it. Returns
    the passed beats' indices and ``{ray: answer index}``."""
    from fractions import Fraction

    from raplas_hdl.fp import model as fpm
    from raplas_hdl.model.ordering import near, product_key
    from raplas_hdl.model.reduction import inf_pattern

    fmt = cfg.fmt
    ok = candidates(fmt, beats, bundle.tmin, bundle.window_tmax(cfg), bundle.exclude)
    tmax = np.asarray(bundle.window_tmax(cfg), np.int64)
    one = ((1 << (fmt.exp_bits - 1)) - 1) << fmt.man_bits
    sg = fmt.width - 1
    e_max = (1 << fmt.exp_bits) - 1

    def key(x, y, sign):
        s, mag = product_key(fmt, np.array([x]), np.array([y]), np.array([sign]))
        return s, mag

    def ratio(i):
        t, d = fpm.decode(np.array([beats["t"][i], beats["det"][i]], np.uint32), fmt)
        return Fraction(float(t)) / Fraction(float(d))

    best, passed = {}, []
    for i, b in enumerate(beats):
        if b["empty"]:
            continue
        ray, t, det = int(b["ray_id"]), int(b["t"]), int(b["det"])
        excl = int(b["tri_id"]) == bundle.exclude
        hit, tight = b["outcome"] == OUTCOME_HIT, bool(b["tight"])
        blocked = bundle.any_hit and ray in best
        unc = (b["outcome"] == OUTCOME_UNCERTAIN or (hit and not tight)) and not excl
        base = (hit and tight and not excl and (t >> fmt.man_bits) & e_max != e_max
                and (det >> fmt.man_bits) & e_max not in (0, e_max))
        k_num = key(t, one, (t >> sg) ^ (det >> sg))
        near_w = base and bool(
            near(fmt, k_num, key(bundle.tmin, det, bundle.tmin >> sg))
            or (tmax[ray] != inf_pattern(fmt)
                and near(fmt, key(int(tmax[ray]), det, int(tmax[ray]) >> sg), k_num)))
        if unc or near_w:
            if not blocked:
                passed.append(i)
            continue
        if not (ok[i] and tight) or blocked:
            continue
        if ray not in best:
            best[ray] = i
            continue
        k = best[ray]
        kn = key(t, int(beats["det"][k]), (t >> sg) ^ (det >> sg))
        kc = key(int(beats["t"][k]), det, (int(beats["t"][k]) >> sg) ^ (int(beats["det"][k]) >> sg))
        if near(fmt, kn, kc):
            passed.append(i)
        elif ratio(i) < ratio(k):
            best[ray] = i
    return passed, best


def reducer_runs(cfg, n_runs, seed):
    rng = np.random.default_rng([seed, 15])
    return [(_random_outcomes(rng, beats), bundle)
            for beats, bundle in random_runs(cfg, n_runs, seed, beats_per_run=4 * cfg.n_rays)]


def test_reduce_model_against_reference():
    cfg = CERT
    n_unc = n_any_drop = n_loose = n_near_fold = n_near_w = 0
    for beats, bundle in reducer_runs(cfg, 80, seed=3):
        got = reduce_run(cfg, beats, bundle)
        unc, best = _reference(cfg, beats, bundle)
        k = len(unc)
        assert np.array_equal(got["outcome"][:k], np.full(k, OUTCOME_UNCERTAIN))
        for name in ("ray_id", "tri_id", "t", "u", "v", "det", "flags"):
            assert np.array_equal(got[name][:k], beats[name][unc]), name
        rest = got[k:]
        rays = sorted(best)
        if rays:
            assert rest.size == len(rays)
            assert rest["ray_id"].tolist() == rays
            for name in ("tri_id", "t", "u", "v", "det", "flags"):
                assert np.array_equal(rest[name], beats[name][[best[r] for r in rays]]), name
            assert (rest["outcome"] == OUTCOME_HIT).all() and not rest["empty"].any()
        else:
            assert rest.size == 1 and rest["empty"][0] and rest["outcome"][0] == 0
        assert got["last"].sum() == 1 and got["last"][-1] == 1 and not got["empty"][:-1].any()
        n_unc += k
        sel = beats[unc]
        n_loose += int(((sel["outcome"] == OUTCOME_HIT) & (sel["tight"] == 0)).sum())
        tight = sel[(sel["outcome"] == OUTCOME_HIT) & (sel["tight"] == 1)]
        n_near_fold += 0 if bundle.any_hit else int(tight.size)
        n_near_w += int(tight.size) if bundle.any_hit else 0
        if bundle.any_hit:
            dropped = np.ones(beats.size, bool)
            dropped[unc] = False
            n_any_drop += int((dropped & (beats["outcome"] == OUTCOME_UNCERTAIN)
                               & (beats["tri_id"] != bundle.exclude)).sum())
    # every kind of passing on happens: uncertain, loose certain hits, tight ones near the
    # window (any-hit runs) or near a ray's answer or the window (nearest-hit runs)
    assert n_unc > 100 and n_any_drop > 0 and n_loose > 10 and n_near_fold > 10 \
        and n_near_w > 0, (n_unc, n_any_drop, n_loose, n_near_fold, n_near_w)


def test_reduce_model_any_hit_uncertain_does_not_block():
    """In an any-hit run an uncertain pair neither answers nor blocks its ray."""
    cfg = CERT
    beats = np.zeros(3, result_dtype(cfg))
    one = int(np.asarray(__import__("raplas_hdl.fp.model", fromlist=["encode"]).encode(
        np.array([1.0]), FP24))[0])
    beats["ray_id"] = 1
    beats["tri_id"] = [3, 4, 5]
    beats["t"] = beats["det"] = one
    beats["outcome"] = [OUTCOME_UNCERTAIN, OUTCOME_HIT, OUTCOME_UNCERTAIN]
    beats["hit"] = beats["tight"] = beats["outcome"] == OUTCOME_HIT
    beats["last"][-1] = 1
    got = reduce_run(cfg, beats, window_bundle(cfg, any_hit=True))
    assert got["outcome"].tolist() == [OUTCOME_UNCERTAIN, OUTCOME_HIT]
    assert got["tri_id"].tolist() == [3, 4]
    ok = candidates(cfg.fmt, beats, 0, np.full(cfg.n_rays, 0x7F0000), -1)
    assert first_answers(cfg.n_rays, beats["ray_id"], ok)[1] == 1


# -- the RTL ---------------------------------------------------------------------------------
def _unit_cosim(simulator, fmt, reduce, n, seed=1, **options):
    c, cases, exp = _cosim(fmt, reduce, n, seed, **options)
    got, info = c.simulate(cases, simulator, valid_density=1.0, stall_density=0.4, seed=seed)
    bad = [(k, m) for k, m in enumerate(c.mismatches(exp, got)) if m]
    assert not bad, "\n".join(f"run {k}:\n" + "\n".join(m) for k, m in bad[:3])
    beats = np.concatenate([s for s, _ in exp["runs"]])
    return beats, info


@pytest.mark.parametrize("reduce", [False, True], ids=["stream", "reduce"])
def test_unit_cosim_icarus(reduce):
    # reduced, a 10-bit fraction: at 8 bits almost no certain hit is tight (t' and det known
    # to 2**-2), and every one leaves the unit passed on
    beats, _ = _unit_cosim("icarus", FPFormat(6, 10) if reduce else COARSE, reduce, 12)
    assert (beats["outcome"] == OUTCOME_UNCERTAIN).sum() > 10
    assert (beats["outcome"] == OUTCOME_HIT).sum() > 0


@pytest.mark.full
@pytest.mark.parametrize("reduce", [False, True], ids=["stream", "reduce"])
@pytest.mark.parametrize("simulator, fmt, options", [
    ("icarus", COARSE, {"rows": 4, "cols": 4}),
    ("verilator", COARSE, {"rows": 4, "cols": 4}),
    ("verilator", FP24, {"rows": 4, "cols": 4}),
    ("verilator", COARSE, {"lanes": 2}),
], ids=["icarus-e6m8-4x4", "verilator-e6m8-4x4", "verilator-fp24-4x4",
        "verilator-e6m8-2x2-lanes2"])
def test_unit_cosim_long(simulator, reduce, fmt, options):
    _unit_cosim(simulator, fmt, reduce, 40, seed=5, **options)


def _reducer_check(simulator, n_runs, seed, cfg=CERT, **kw):
    runs = reducer_runs(cfg, n_runs, seed)
    got, want, _ = cosim_reducer(simulator, cfg, runs, seed=seed,
                                 build_key="reducer_certified", **kw)
    assert got.size == want.size
    for name in want.dtype.names:
        bad = np.flatnonzero(got[name] != want[name])
        assert bad.size == 0, (name, bad[:5], got[bad[:3]], want[bad[:3]])
    assert (want["outcome"] == OUTCOME_UNCERTAIN).sum() > 3 * n_runs
    assert (want["outcome"] == OUTCOME_HIT).sum() > n_runs


def test_reducer_cosim_icarus():
    _reducer_check("icarus", 30, seed=1, valid_density=0.9, stall_density=0.5)


@pytest.mark.full
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_reducer_cosim_long(simulator):
    _reducer_check(simulator, 400, seed=2, valid_density=0.7,
                   stall_density=0.6)


# -- the host --------------------------------------------------------------------------------
def _settings(size):
    from raplas_hdl.host.render import RenderSettings

    return RenderSettings(size, size, rows=2, cols=2, shadow_rows=2, shadow_cols=2,
                          tris_per_sphere=4, batch_spheres=4, progress=False)


def test_real_passes_resolve_alike():
    """Every pass of a certified cornell render (primary and shadow rounds, recorded by
    host/reduction_passes.py): the host's resolution of the reduced unit's answers and
    uncertain pairs equals its resolution of every pair's outcome, tri_id and t."""
    from raplas_hdl.host.reduction_passes import pass_runs, recorded_runs, resolve_streams

    backend, passes = recorded_runs("cornell", _settings(12), COARSE, mode="certified")
    kinds, n_unc, n_hit = set(), 0, 0
    for rec in passes:
        cfg = backend.config(rec.batch.rows, rec.batch.cols)
        assert cfg.mode == "certified"
        runs = pass_runs(backend, rec, cfg)
        plain = [s for s, _ in run_runs(cfg, backend.scene_memory, runs)]
        red = [a for a, _ in run_runs(replace(cfg, reduce=True), backend.scene_memory, runs)]
        tri_p, t_p = resolve_streams(backend, rec, plain)
        tri_r, t_r = resolve_streams(backend, rec, red)
        assert np.array_equal(tri_p, tri_r) and np.array_equal(t_p, t_r)
        kinds.add(rec.any_hit)
        n_unc += sum(int((a["outcome"] == OUTCOME_UNCERTAIN).sum()) for a in red)
        n_hit += int((tri_p >= 0).sum())
    assert kinds == {False, True} and n_unc > 50 and n_hit > 50


@pytest.mark.parametrize("scene, fmt", [("cornell", COARSE), ("stanford-bunny", FP24)])
def test_model_render_reduce_equals_unreduced(scene, fmt):
    from raplas_hdl.host.backends import make_backend
    from raplas_hdl.host.output import format_summary
    from raplas_hdl.host.render import render
    from raplas_hdl.host.scenes import get_scene

    out = {}
    for reduce in (False, True):
        backend = make_backend("model", fmt, mode="certified", reduce=reduce)
        out[reduce] = render(get_scene(scene), backend, _settings(12)), backend
    (plain, _), (red, rb) = out[False], out[True]
    for name in ("image", "tri_id", "t", "visibility"):
        x, y = getattr(plain, name), getattr(red, name)
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name
    assert (plain.tri_id >= 0).sum() > 50
    assert red.stats["unit"]["pairs_issued"] == plain.stats["unit"]["pairs_issued"]
    assert 0 < rb.beats["uncertain"] < rb.beats["answer"] < rb.beats["result"] // 4
    assert "answer beats left the unit" in format_summary(red)


def _rtl_render(simulator, reduce):
    from raplas_hdl.host.backends import make_backend
    from raplas_hdl.host.render import render
    from raplas_hdl.host.scenes import get_scene

    out = {}
    for name in ("model", "rtl"):
        backend = make_backend(name, COARSE, mode="certified", sim=simulator, reduce=reduce)
        try:
            out[name] = render(get_scene("cornell"), backend, _settings(6)), backend
        finally:
            getattr(backend, "close", lambda: None)()
    (m, mb), (r, rb) = out["model"], out["rtl"]
    for name in ("image", "tri_id", "t", "visibility"):
        x, y = getattr(m, name), getattr(r, name)
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name
    return mb, rb


@pytest.mark.full
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_rtl_render_reduce_equals_model(simulator):
    """A small certified render through the reduced unit's RTL equals the model's."""
    mb, rb = _rtl_render(simulator, True)
    assert rb.beats["uncertain"] > 0 and rb.beats["result"] == mb.beats["result"]


@pytest.mark.full
def test_rtl_render_equals_model():
    """The unreduced certified unit's RTL stream, every pair resolved on the host, renders as
    the model backend's certified pass (another bound variant: other uncertain pairs)."""
    mb, rb = _rtl_render("icarus", False)
    assert rb.mode_stats["uncertain"] > 0 and rb.mode_stats["certified_hits"] > 0


# -- the command line ------------------------------------------------------------------------
def _cli(*args):
    return subprocess.run([sys.executable, "-m", "raplas_hdl", *args], capture_output=True,
                          text=True)


@pytest.mark.parametrize("args, message", [
    (("verilog", "intersection-unit", "--mode", "certified", "--format", "e10m13", "-o",
      "x.v"), "--mode certified: the certified mode needs exp_bits <= 9"),
    (("render", "--scene", "cornell", "--size", "4x4", "--mode", "certified", "--format",
      "e10m13", "-o", "x.png"), "--mode certified: the certified mode needs exp_bits <= 9"),
    (("render", "--scene", "cornell", "--size", "4x4", "--mode", "conservative", "--reduce",
      "-o", "x.png"), "--reduce has no conservative mode"),
    (("cosim", "intersection-unit", "--mode", "certified", "--reduce", "--format", "e10m13",
      "--random", "2"), "--mode certified: the certified mode needs exp_bits <= 9"),
])
def test_cli_errors(tmp_path, args, message):
    r = subprocess.run([sys.executable, "-m", "raplas_hdl", *args], capture_output=True,
                       text=True, cwd=tmp_path)
    assert r.returncode == 2 and message in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not list(tmp_path.iterdir())


def test_cli_render_certified_reduce(tmp_path):
    import json

    out = tmp_path / "c.png"
    r = _cli("render", "--scene", "cornell", "--size", "8x8", "--tile", "2x2", "--shadow",
             "2x2", "--mode", "certified", "--reduce", "-o", str(out), "--json",
             str(tmp_path / "c.json"))
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "c.json").read_text())
    beats = doc["output_beats"] if "output_beats" in doc else doc["stats"]["output_beats"]
    assert 0 < beats["answer"] < beats["result"]
    assert "answer beats left the unit" in r.stdout
