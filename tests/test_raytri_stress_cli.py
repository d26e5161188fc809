"""``raplas-hdl stress ray-triangle``: the fast subset through the command line."""

import json

import pytest

from raplas_hdl.cli import main
from raplas_hdl.fp import FP24
from raplas_hdl.verify import stress


def test_stress_cli_writes_the_table(tmp_path, capsys):
    out = tmp_path / "stress.json"
    code = main(["stress", "ray-triangle", "--format", "FP24/chop", "--per-family", "40",
                 "--seed", "3", "--json", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "FP24/chop paper" in text and "FP24/chop conservative" in text
    res = json.loads(out.read_text())
    assert [r["mode"] for r in res] == ["paper", "conservative"]
    assert set(res[0]["families"]) == set(stress.FAMILIES)
    assert res[1]["pooled"]["false_misses"] == 0 and res[1]["pooled"]["leaks"] == 0


def test_generator_is_seeded():
    a = stress.generate(FP24, 5, seed=9)
    b = stress.generate(FP24, 5, seed=9)
    c = stress.generate(FP24, 5, seed=10)
    assert (a.o == b.o).all() and (a.v2 == b.v2).all()
    assert not (a.o == c.o).all()


def test_unknown_family():
    with pytest.raises(ValueError, match="family"):
        stress.generate(FP24, 5, families=("random", "bogus"))
