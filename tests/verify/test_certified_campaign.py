"""The certified mode in the stress campaign, and its negative control: bisect the factor on
every bound at which the campaign's own pairs get mis-certified, then show that the campaign
fails there and passes just above (docs/certified-mode.md, "Verification")."""

from __future__ import annotations

import pytest

from raplas_hdl.cli import main
from raplas_hdl.fp.format import parse_format
from raplas_hdl.model import stress_cases
from raplas_hdl.verify import campaign, stress
from raplas_hdl.verify.campaign import CampaignParams

#: One format, one family of near-edge rays, one shard, no culling task.
PARAMS = CampaignParams(formats=("FP24/rtz",), families=("grazing",), rays_per_family=300,
                        shard_rays=300, bundles=0, seed=13)


@pytest.fixture(scope="module")
def control():
    """The negative control on exactly the pairs of the campaign's one shard."""
    (shard,) = campaign.plan(PARAMS)
    fmt = parse_format(shard.fmt)
    cases = stress_cases.generate(fmt, shard.count, shard.derived_seed(), (shard.group,))
    return stress.bisect_certified(cases, stress.reference(cases, fmt))


def _run(tmp_path, scale):
    params = CampaignParams(**{**PARAMS.__dict__, "certified_scale": scale})
    campaign.run_campaign(params, tmp_path, jobs=1, progress=False)
    return campaign.merge(params, tmp_path)


def test_bounds_have_little_slack(control):
    # some factor below 1 mis-certifies a pair: the bounds are not vacuous, and the factor
    # says how much slack they have
    assert control["s_fail"] is not None
    assert 0.05 < control["s_fail"] < 1 and control["s_pass"] <= 1
    assert control["wrong_at_fail"] > 0


def test_campaign_passes_at_one_and_fails_below_the_factor(control, tmp_path):
    doc = _run(tmp_path / "one", 1.0)
    g = doc["guarantees"]
    assert g["certified_mis_certified"] == 0 and g["certified_leaks"] == 0 and g["ok"]
    row = next(r for r in doc["ray_triangle"] if r["mode"] == "certified")
    assert 0 < row["uncertain"] < row["in_domain"]
    assert "certified mode (bounds x1)" in campaign.markdown(doc)
    bad = _run(tmp_path / "fail", control["s_fail"])
    assert bad["guarantees"]["certified_mis_certified"] == control["wrong_at_fail"]
    assert not bad["guarantees"]["ok"]
    assert _run(tmp_path / "pass", control["s_pass"])["guarantees"]["ok"]


def test_cli_negative_control(tmp_path, capsys):
    args = ["stress", "campaign", "--format", "FP24/rtz", "--families", "grazing",
            "--rays-per-family", "300", "--shard-rays", "300", "--bundles", "0", "--seed", "13",
            "--shard-dir", str(tmp_path / "s"), "--out", str(tmp_path / "o"), "--jobs", "1",
            "--no-progress", "--certified-scale", "0.01"]
    assert main(args) == 1
    assert "GUARANTEE VIOLATED" in capsys.readouterr().out
    assert main(args[:-2] + ["--certified-scale", "0"]) == 2
    assert "--certified-scale" in capsys.readouterr().err
