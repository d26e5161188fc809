"""Campaigns and the bench on a Dask cluster (issue 16, item 4): a tiny stress campaign and a
slice of the quick bench on a two-worker ``LocalCluster`` give the results of one process;
an interrupted run resumes from its shard files whatever ran them; ``--scheduler`` reaches
an existing cluster; without Dask the options are a one-line error saying how to install it.

The cluster is a ``LocalCluster(processes=True)`` of two single-threaded workers, started
once for the module: worker processes as in the default process pool (numba's threading
layer is not safe for kernels launched from threads of one process, and a campaign's Python
parts would share one GIL), and the shards cross process boundaries as on a real cluster.
"""

from __future__ import annotations

import json
import re
import sys

import pytest

from raplas_hdl import cluster
from raplas_hdl.cli import main
from raplas_hdl.verify import campaign
from raplas_hdl.verify.campaign import CampaignParams

#: Two formats, every family and both sphere kinds, two shards per group (28 shards).
SMALL = CampaignParams(formats=("FP16/rtz", "FP24/rne"), rays_per_family=16, shard_rays=8,
                       bundles=8, shard_bundles=4, seed=5)


@pytest.fixture(scope="module")
def dask_ex():
    """A two-worker LocalCluster (processes) behind the project's executor."""
    with cluster.DaskExecutor(n_workers=2) as ex:
        ex.connect()
        yield ex


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    """The campaign in this process, one shard after the other, merged."""
    out = tmp_path_factory.mktemp("serial")
    info = campaign.run_campaign(SMALL, out, jobs=1, progress=False)
    assert info["run"] == info["shards"] and info["executor"] == "this process"
    return out, campaign.merge(SMALL, out)


def _results(doc):
    return json.dumps(campaign.results_of(doc), sort_keys=True)


def _shard_results(out):
    return [json.loads(campaign.shard_path(out, s).read_text())["result"]
            for s in campaign.plan(SMALL)]


def test_campaign_on_two_dask_workers_equals_one_process(dask_ex, serial_run, tmp_path):
    out, doc = serial_run
    info = campaign.run_campaign(SMALL, tmp_path, progress=False, executor=dask_ex)
    assert info["run"] == info["shards"] == len(campaign.plan(SMALL)) and info["pending"] == 0
    assert info["executor"] == "Dask LocalCluster of 2 worker processes"
    on_dask = campaign.merge(SMALL, tmp_path)
    assert _results(on_dask) == _results(doc)
    # every shard's own result too, not only the sums
    assert _shard_results(tmp_path) == _shard_results(out)
    assert on_dask["guarantees"]["ok"] and on_dask["totals"]["cases"] > 0


def test_interrupted_runs_resume_across_executors(dask_ex, serial_run, tmp_path):
    _, doc = serial_run
    shards = campaign.plan(SMALL)
    # 5 shards in this process, then 9 more on Dask (interrupted on purpose), then the rest
    first = campaign.run_campaign(SMALL, tmp_path, jobs=1, max_shards=5, progress=False)
    assert first["run"] == 5 and first["pending"] == len(shards) - 5
    kept = {p.name: p.stat().st_mtime_ns for p in tmp_path.glob("*.json")}
    assert len(kept) == 5
    second = campaign.run_campaign(SMALL, tmp_path, max_shards=9, progress=False,
                                   executor=dask_ex)
    assert (second["reused"], second["run"]) == (5, 9)
    assert second["pending"] == len(shards) - 14
    # the shard files already there were reused, not computed and written again
    assert {n: (tmp_path / n).stat().st_mtime_ns for n in kept} == kept
    with pytest.raises(ValueError, match="missing"):
        campaign.merge(SMALL, tmp_path)
    third = campaign.run_campaign(SMALL, tmp_path, progress=False, executor=dask_ex)
    assert (third["reused"], third["run"], third["pending"]) == (14, len(shards) - 14, 0)
    assert _results(campaign.merge(SMALL, tmp_path)) == _results(doc)


def test_cli_campaign_on_an_existing_scheduler(dask_ex, serial_run, tmp_path, capsys):
    _, doc = serial_run
    address = dask_ex.client.scheduler.address
    args = ["stress", "campaign", "--formats", "FP16/rtz,FP24/rne", "--rays-per-family",
            "16", "--shard-rays", "8", "--bundles", "8", "--shard-bundles", "4",
            "--seed", "5", "--shard-dir", str(tmp_path / "shards"), "--out",
            str(tmp_path), "--no-progress", "--scheduler", address]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert f"Dask cluster at {address} (2 worker threads)" in text
    merged = json.loads((tmp_path / "stress_campaign.json").read_text())
    assert merged["command"].endswith(f"--scheduler {address}")
    assert merged["run"]["executor"].startswith("Dask cluster at")
    assert _results(merged) == _results(doc)


def test_bench_slice_on_two_dask_workers_equals_one_process(dask_ex):
    from raplas_hdl.bench.plan import quick_spec
    from raplas_hdl.bench.sweep import results_of, run_sweep

    # two formats (two bounds, so two groups of one scene) and the capped probe point
    spec = quick_spec(formats=["FP16", "FP24"], scenes=["cornell"], size=(16, 16),
                      per_family=40)
    here = run_sweep(spec, progress=None, cost_thread=False)
    there = run_sweep(spec, progress=None, cost_thread=False, executor=dask_ex)
    assert there["executor"] == dask_ex.describe() and here["executor"] == "this process"
    assert [p["grid"] for p in here["points"]] == ["reference", "main", "reference", "main",
                                                   "cap"]
    assert here["points"][-1]["capped"]
    a, b = results_of(here), results_of(there)
    assert a["points"][1]["pairs_issued"] > 0 and "t_total" not in a["points"][1]
    assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)
    assert there["cpu_seconds"] > 0


def test_workers_with_other_versions_are_refused(dask_ex):
    mine = cluster.versions()
    assert mine["raplas-hdl"] and mine["numba"]
    dask_ex._check_versions()       # the real workers match
    with pytest.raises(ValueError, match=re.escape(f"other versions: numba {mine['numba']} "
                                                   "(here 0.0)")):
        dask_ex._check_versions({**mine, "numba": "0.0"})
    # the campaign's executor checks its shard format too, on the workers
    ours = campaign.worker_versions()
    assert ours == {**mine, "campaign_version": campaign.VERSION}
    dask_ex.worker_versions = campaign.worker_versions
    try:
        dask_ex._check_versions()
        with pytest.raises(ValueError, match=re.escape(
                f"campaign_version {campaign.VERSION} (here {campaign.VERSION + 1})")):
            dask_ex._check_versions({**ours, "campaign_version": campaign.VERSION + 1})
    finally:
        dask_ex.worker_versions = cluster.versions


def test_unreachable_scheduler_is_one_clear_error():
    ex = cluster.DaskExecutor(scheduler="tcp://127.0.0.1:1", timeout=1)
    with pytest.raises(ValueError, match="cannot reach the Dask scheduler at"):
        ex.connect()


CAMPAIGN = ["stress", "campaign", "--formats", "FP24/rtz", "--rays-per-family", "4",
            "--bundles", "0", "--no-progress"]
BENCH = ["bench", "--quick", "--quiet"]


@pytest.mark.parametrize("argv, option", [
    (CAMPAIGN + ["--dask-workers", "2"], "--dask-workers"),
    (CAMPAIGN + ["--scheduler", "tcp://127.0.0.1:8786"], "--scheduler"),
    (BENCH + ["--dask-workers", "2"], "--dask-workers"),
    (BENCH + ["--scheduler", "tcp://127.0.0.1:8786"], "--scheduler"),
])
def test_without_dask_the_options_say_how_to_install_it(argv, option, tmp_path, monkeypatch,
                                                        capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)     # import distributed fails
    assert main(argv + ["--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert err.endswith(f"{option} needs Dask distributed, which is not installed: "
                        "pip install 'raplas-hdl[cluster]'")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("extra, message", [
    (["--dask-workers", "2", "--jobs", "2"], "--jobs applies to the local process pool"),
    (["--scheduler", "tcp://"], "names no host"),
    (["--dask-workers", "0"], "--dask-workers: 0 is not in 1 to"),
    (["--dask-workers", "2", "--scheduler", "tcp://h:1"], "not allowed with argument"),
])
def test_bad_cluster_options(extra, message, tmp_path, capsys):
    assert main(CAMPAIGN + ["--out", str(tmp_path / "o")] + extra) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
    assert not (tmp_path / "o").exists()
