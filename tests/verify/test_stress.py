"""``raplas-hdl stress ray-triangle``: the fast subset through the command line."""

import json

from raplas_hdl.cli import main
from raplas_hdl.model.stress_cases import FAMILIES


def test_stress_cli_writes_the_table(tmp_path, capsys):
    out = tmp_path / "stress.json"
    code = main(["stress", "ray-triangle", "--format", "FP24/chop", "--per-family", "40",
                 "--seed", "3", "--json", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "FP24/chop paper" in text and "FP24/chop conservative" in text
    assert "FP24/chop certified" in text
    res = json.loads(out.read_text())
    assert [r["mode"] for r in res] == ["paper", "conservative", "certified"]
    assert set(res[0]["families"]) == set(FAMILIES)
    assert res[1]["pooled"]["false_misses"] == 0 and res[1]["pooled"]["leaks"] == 0
    cert = res[2]["pooled"]
    assert cert["false_hits"] == 0 and cert["false_misses"] == 0 and cert["leaks"] == 0
    assert 0 < cert["uncertain"] < cert["pairs"]


def test_stress_cli_certified_bisect(capsys):
    code = main(["stress", "ray-triangle", "--format", "FP24/rtz", "--mode", "certified",
                 "--families", "random,grazing", "--per-family", "60", "--bisect"])
    assert code == 0
    assert "negative control: bounds x" in capsys.readouterr().out


def test_stress_cli_certified_below_the_bound_fails(capsys):
    code = main(["stress", "ray-triangle", "--format", "FP24/rtz", "--mode", "certified",
                 "--families", "grazing", "--per-family", "60", "--margin-scale", "0.01"])
    assert code == 1
    assert "MIS-CERTIFIED" in capsys.readouterr().out
