"""The stress campaign (issue 6, point 2) on a tiny scale: it runs, resumes without redoing
work, an interrupted campaign resumed equals an uninterrupted one, the merged counts are
the sums of the shards, and the project's guarantees hold (in-domain culling never rejects
a sphere a ray's line meets; the conservative mode has no in-domain false miss or leak)."""

from __future__ import annotations

import json

import pytest

from raplas_hdl.cli import main
from raplas_hdl.verify import campaign
from raplas_hdl.verify.campaign import CampaignParams, Shard

#: Two formats (different geometry scales), two roundings of one, every family, both
#: sphere kinds: 2 shards per group.
TINY = CampaignParams(formats=("FP16/rtz", "FP24/rne", "FP24/chop"), rays_per_family=60,
                      shard_rays=30, bundles=30, shard_bundles=15, seed=11)


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    """One uninterrupted tiny campaign over two worker processes, merged."""
    out = tmp_path_factory.mktemp("campaign_full")
    info = campaign.run_campaign(TINY, out, jobs=2, progress=False)
    return out, info, campaign.merge(TINY, out, "test", {"wall_s": info["wall_s"]})


def test_plan_is_sharded_and_seeded():
    shards = campaign.plan(TINY)
    n_fmt = 3
    assert len(shards) == n_fmt * (len(TINY.families) * 2 + len(campaign.KINDS) * 2)
    assert len({campaign.shard_path("x", s).name for s in shards}) == len(shards)
    a = Shard("raytri", "FP24/rtz", "thin", 3, 10, 5)
    # the three roundings of a format see the same geometry; any other change moves it
    assert a.derived_seed() == Shard("raytri", "FP24/chop", "thin", 3, 10, 5).derived_seed()
    for other in (Shard("raytri", "FP32/rtz", "thin", 3, 10, 5),
                  Shard("raytri", "FP24/rtz", "far", 3, 10, 5),
                  Shard("raytri", "FP24/rtz", "thin", 4, 10, 5),
                  Shard("raytri", "FP24/rtz", "thin", 3, 10, 6)):
        assert other.derived_seed() != a.derived_seed()
    # the version is part of the key: a new version never reuses an old file
    assert Shard("raytri", "FP24/rtz", "thin", 3, 10, 5, version=campaign.VERSION + 1) \
        .digest() != a.digest()


def test_tiny_campaign_runs_and_keeps_the_guarantees(full_run):
    out, info, doc = full_run
    assert info["run"] == info["shards"] and info["pending"] == 0 and info["reused"] == 0
    g = doc["guarantees"]
    assert g["culling_false_rejections"] == 0, "plane culling rejected a sphere a ray meets"
    assert g["conservative_false_misses"] == 0, "conservative mode missed an R hit in domain"
    assert g["conservative_leaks"] == 0, "conservative mode leaked through a shared edge"
    assert g["ok"]
    rows = {(r["format"], r["mode"]): r for r in doc["ray_triangle"]}
    assert set(rows) == {(f, m) for f in ("FP16/rtz", "FP24/rne", "FP24/chop")
                         for m in campaign.MODES}
    # the paper mode does make errors at the shared edges: the check can fail
    assert rows[("FP24/rne", "paper")]["false_misses"] > 0
    assert rows[("FP24/rne", "paper")]["t_rel_median"] < 1e-3
    cull = {r["format"]: r for r in doc["culling"]}
    for fmt, r in cull.items():
        assert r["bundles"] == 2 * TINY.bundles and r["bundles_out_of_budget"] == 0, fmt
        assert r["line_hits"] > 1000, fmt
        assert 0.1 < r["culled_fraction"] < 0.9, fmt
    # without the inflation the same spheres are rejected by mistake (the check has teeth)
    assert sum(r["false_rejections_raw"] for r in cull.values()) > 0


def test_counts_are_sums_over_shards(full_run):
    out, _, doc = full_run
    shards = campaign.plan(TINY)
    files = [json.loads(campaign.shard_path(out, s).read_text()) for s in shards]
    assert all(f["key"] == s.key() for f, s in zip(files, shards))
    rt = [f["result"] for f, s in zip(files, shards) if s.task == "raytri"]
    cu = [f["result"] for f, s in zip(files, shards) if s.task == "culling"]
    tot = doc["totals"]
    assert tot["shards"] == len(shards)
    assert tot["raytri_pairs"] == sum(r["paper"]["cases"] for r in rt)
    assert tot["raytri_pairs"] == sum(r["conservative"]["cases"] for r in rt)
    assert tot["sphere_tests"] == sum(r["sphere_tests"] for r in cu)
    assert tot["cases"] == tot["raytri_pairs"] + tot["sphere_tests"]
    # 60 rays per family; shared_edge 2 and shared_vertex 6 pairs per ray
    per_fmt = 60 * (len(TINY.families) - 2 + 2 + 6)
    for row in doc["ray_triangle"]:
        assert row["cases"] == per_fmt
        assert row["in_domain"] + row["unguaranteed"] + row["skipped"] == row["cases"]
        for key in ("false_hits", "false_misses", "leaks", "r_hits", "in_domain"):
            assert row[key] == sum(f[key] for f in row["families"].values()), key
        assert row["t_rel_max"] == max(f["t_rel_max"] for f in row["families"].values())
        assert row["t_rel_median"] <= row["t_rel_p99"] <= row["t_rel_max"]
    for row in doc["culling"]:
        for key in ("sphere_tests", "line_hits", "false_rejections", "plane_tests"):
            assert row[key] == sum(k[key] for k in row["kinds"].values()), key
        assert row["line_hits"] <= row["sphere_tests"]


def test_rerun_does_no_work_and_gives_the_same_json(full_run, tmp_path):
    out, _, doc = full_run
    info = campaign.run_campaign(TINY, out, jobs=2, progress=False)
    assert info["run"] == 0 and info["reused"] == info["shards"]
    again = campaign.merge(TINY, out, "test", {"wall_s": info["wall_s"]})
    a, b = dict(doc), dict(again)
    for k in ("date", "run"):
        a.pop(k), b.pop(k)
    assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)
    campaign.write_outputs(again, tmp_path / "c.json", tmp_path / "c.md")
    assert json.loads((tmp_path / "c.json").read_text())["totals"] == doc["totals"]
    assert "| FP24/rne | conservative |" in (tmp_path / "c.md").read_text()


def test_interrupted_campaign_resumes_to_the_same_result(full_run, tmp_path):
    _, _, doc = full_run
    k = 7
    info = campaign.run_campaign(TINY, tmp_path, jobs=1, max_shards=k, progress=False)
    assert info["run"] == k and info["pending"] == info["shards"] - k
    with pytest.raises(ValueError, match="missing"):
        campaign.merge(TINY, tmp_path)
    # a half-written file of a killed worker and a corrupt shard are redone, not trusted
    (tmp_path / ".raytri_x.json.123.tmp").write_text("{")
    victim = campaign.shard_path(tmp_path, campaign.plan(TINY)[0])
    victim.write_text('{"key": {"task": "culling"}, "result": {}}')
    info = campaign.run_campaign(TINY, tmp_path, jobs=1, progress=False)
    assert info["run"] == info["shards"] - k + 1 and info["pending"] == 0
    assert not list(tmp_path.glob(".*.tmp"))
    resumed = campaign.merge(TINY, tmp_path)
    assert campaign.results_of(resumed) == campaign.results_of(doc)


def test_cli_campaign(tmp_path, capsys):
    args = ["stress", "campaign", "--formats", "FP20/rtz", "--families", "random,grazing",
            "--rays-per-family", "40", "--shard-rays", "20", "--bundles", "10",
            "--shard-bundles", "10", "--out-dir", str(tmp_path / "shards"), "--jobs", "1",
            "--results", str(tmp_path / "r.json"), "--report", str(tmp_path / "r.md"),
            "--no-progress"]
    assert main(args + ["--max-shards", "2"]) == 0
    assert "incomplete" in capsys.readouterr().out and not (tmp_path / "r.json").exists()
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "2 reused" in text and "false rejections 0" in text
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["command"].startswith("raplas-hdl stress campaign --formats FP20/rtz ")
    assert "--rays-per-family 40" in doc["command"]
    assert doc["totals"]["raytri_pairs"] == 80 and doc["guarantees"]["ok"]
    assert "## Plane culling" in (tmp_path / "r.md").read_text()


def test_bad_parameters():
    with pytest.raises(ValueError, match="rounding"):
        CampaignParams(roundings=("up",))
    with pytest.raises(ValueError, match="family"):
        CampaignParams(families=("bogus",))
    with pytest.raises(ValueError, match="shard_rays"):
        CampaignParams(shard_rays=0)
    with pytest.raises(ValueError, match="jobs"):
        campaign.run_campaign(CampaignParams(rays_per_family=1, bundles=0,
                                             formats=("FP24/rtz",), families=("random",)),
                              "build/never", jobs=0)


def test_quantiles_from_histogram():
    import numpy as np
    rel = np.array([0.0, 1e-6, 2e-6, 3e-6, 1e-3])
    h = campaign._hist(rel)
    assert sum(h.values()) == 5
    med = campaign.quantile_from_hist(h, 0.5, 1e-3)
    assert 2e-6 <= med <= 2e-6 * 2 ** (1 / 16)
    assert campaign.quantile_from_hist(h, 0.99, 1e-3) == 1e-3
    assert campaign.quantile_from_hist({}, 0.5) == 0.0
    assert campaign.quantile_from_hist(campaign._hist(np.zeros(3)), 0.5) == 0.0
