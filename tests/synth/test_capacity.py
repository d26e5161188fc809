"""Capacity per configuration (issue 15, point 4): the composition, the limits, the block-RAM
model and the pairs per second, on hand-made rows (no Yosys run here; the real figures are
``benchmarks/bench_synth.py --capacity``'s)."""

import json

import pytest

from raplas_hdl.cli import main
from raplas_hdl.fp import FP24
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.synth.capacity import (DEVICES, Config, bram_blocks, build_capacity,
                                       capacity_row, compose, pairs_per_cycle, render_capacity,
                                       rest_of, unit_config)


def _row(dsp, slices, path=30, luts=None, ffs=None, bram=0):
    return {"dsp48": dsp, "slices_est": slices, "luts": luts or 2 * slices,
            "ffs": ffs or slices, "bram": bram, "path_cells": path, "path_levels": path // 2}


def test_bram_model_per_write_lane():
    # Triangle Memory: 12 lanes of 24 bits x 1024 -> 2 blocks each (1024 x 18 twice)
    b = bram_blocks(UnitConfig(fmt=FP24))
    assert b["tri"] == 24 and b["sphere"] == 4 and b["ray"] == 6
    assert b["total"] == sum(v for k, v in b.items() if k != "total")
    # K lanes read Triangle Memory, the triangle lists and Ray Memory through their own ports
    b2 = bram_blocks(UnitConfig(fmt=FP24), lanes=2)
    assert b2["tri"] == 48 and b2["ray"] == 12 and b2["tlist"] == 2 * b["tlist"]
    assert b2["sphere"] == b["sphere"]
    # the bunny's triangles do not fit any device's block RAM
    big = bram_blocks(unit_config(FP24, 69451))["total"]
    assert big > max(d["bram18"] for d in DEVICES.values())


def test_composition_round_trip():
    unit, array, rtu = _row(42, 14798), _row(24, 8488), _row(18, 6039)
    rest = rest_of(unit, array, rtu)
    assert rest["slices_est"] == 271 and rest["dsp48"] == 0
    assert compose(array, rtu, rest, 1)["slices_est"] == 14798
    assert compose(array, rtu, rest, 2)["slices_est"] == 14798 + 6039
    assert compose(array, rtu, rest, 3)["dsp48"] == 24 + 3 * 18


def test_units_are_the_minimum_over_the_resources():
    cfg = Config("XC4VSX35", "virtex4", 4, 2)
    need = {"dsp48": 132, "slices_est": 7000}
    row = capacity_row(cfg, need, {"1k": 90, "big": 500}, {"a": 0.9, "b": 1.7}, 35)
    assert row["limits"] == {"dsp48": 1, "slices": 2, "slices_x1.25": 1}
    assert row["bram_limits"] == {"1k": 2, "big": 0}
    assert row["units[1k]"] == 1 and row["units[big]"] == 0         # DSP48 binds, BRAM binds
    # pairs per second from the slowest scene, not K x clock
    assert row["pairs_per_s[1k]"] == pytest.approx(1 * 0.9 * 100e6)
    row = capacity_row(cfg, {"dsp48": 60, "slices_est": 7000}, {"1k": 40}, {"a": 1.5}, 35)
    assert (row["units[1k]"], row["units_x1.25[1k]"]) == (2, 1)
    assert row["pairs_per_s_x1.25[1k]"] == pytest.approx(150e6)


def test_pairs_per_cycle_selects_testers_and_lanes():
    rows = [{"scene": "a", "format": "FP24", "rows": 4, "cols": 4, "testers": 8, "lanes": 1,
             "pairs_per_cycle": 0.7},
            {"scene": "a", "format": "FP24", "rows": 4, "cols": 4, "testers": 8, "lanes": 2,
             "pairs_per_cycle": 1.2},
            {"scene": "b", "format": "FP24", "rows": 8, "cols": 8, "testers": 8, "lanes": 2,
             "pairs_per_cycle": 1.9}]
    assert pairs_per_cycle(rows, 8, 2) == {"a": 1.2}
    assert pairs_per_cycle(rows, 4, 1) == {}


def test_build_capacity_from_parts_and_validation():
    key = lambda u, o, f="xc4v": (u, tuple(sorted(o.items())), f)   # noqa: E731
    base = {"rows": 4, "cols": 4, "target": "generic", "adder": "generic"}
    v4 = {"target": "virtex4", "adder": "virtex4"}
    found = {
        key("intersection-unit", {**base, "testers": 8}): _row(42, 14798, 40, bram=46),
        key("plane-sphere", {**base, "testers": 8}): _row(24, 8488, 39),
        key("plane-sphere", {**base, "testers": 4}): _row(12, 4557, 38),
        key("ray-triangle", {"target": "generic", "adder": "generic", "mode": "paper"}):
            _row(18, 6039, 40),
        key("plane-sphere", {**base, **v4, "testers": 4}): _row(36, 3430, 33),
        key("ray-triangle", {**v4, "mode": "paper"}): _row(48, 5596, 35),
        key("intersection-unit", {**base, **v4, "testers": 4}): _row(84, 9400, 38, bram=46),
        key("intersection-unit", {**base, **v4, "testers": 4, "reduce": True}):
            _row(90, 9900, 38, bram=47),
    }
    tp = [{"scene": "s", "testers": t, "lanes": k, "pairs_per_cycle": 0.5 * k}
          for t in (8, 4) for k in (1, 2, 3)]
    cap = build_capacity(FP24, found, tp, {"1k": 1024})
    rows = {(r["target"], r["testers"], r["lanes"]): r for r in cap["table"] if not r["reduce"]}
    red = {(r["target"], r["testers"], r["lanes"]): r for r in cap["table"] if r["reduce"]}
    # the reduction's cost (the unit with it minus the unit without) on every xc4v row
    assert red["virtex4", 4, 2]["slices_est"] == rows["virtex4", 4, 2]["slices_est"] + 500
    assert red["generic", 8, 1]["dsp48"] == rows["generic", 8, 1]["dsp48"] + 6
    assert red["generic", 8, 1]["bram18"]["1k"] == 47
    assert not any(r["family"] == "xc7" for r in red.values())
    assert rows["generic", 8, 1]["slices_est"] == 14798            # its own rest: exact
    assert rows["virtex4", 4, 1]["slices_est"] == 3430 + 5596 + 271
    assert rows["virtex4", 4, 2]["dsp48"] == 36 + 2 * 48
    # the block RAM model is calibrated to Yosys's count at the synthesised size
    assert rows["generic", 8, 1]["bram18"]["1k"] == 46
    (val,) = cap["validation"]
    assert val["slices_est"]["predicted"] == 3430 + 5596 + 271
    assert val["slices_est"]["error"] == pytest.approx((9297 - 9400) / 9400)
    text = "\n".join(render_capacity(cap, worst_path=40))
    assert "| XC4VSX35 | virtex4 | 4 | 2 | off |" in text and "**XC4VSX35**" in text


def test_cli_capacity_errors(tmp_path, capsys):
    missing = tmp_path / "none.json"
    assert main(["synth", "capacity", "--throughput", str(missing)]) == 2
    assert "--throughput: no such file" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps([{"scene": "a", "testers": 8}]))
    assert main(["synth", "capacity", "--throughput", str(bad)]) == 2
    assert "lacks lanes, pairs_per_cycle" in capsys.readouterr().err
    assert main(["synth", "capacity", "--adder", "virtex4", "--throughput", str(bad)]) == 2
    assert "--adder does not apply to capacity" in capsys.readouterr().err
    assert main(["synth", "ray-triangle", "--adder", "virtex4", "--family", "xc7"]) == 2
    assert "takes the generic RTL only" in capsys.readouterr().err


def _pnr_run(copies, comb, mult, fmax=(92.0, 90.0, 95.0), **kw):
    util = {"TRELLIS_COMB": {"used": comb, "available": 83640},
            "TRELLIS_FF": {"used": comb // 2, "available": 83640},
            "MULT18X18D": {"used": mult, "available": 156},
            "DP16KD": {"used": 48, "available": 208}}
    return {"unit": "intersection-unit", "format": "e7m16-rtz", "options": {}, "speed": 6,
            "device": "LFE5U-85F", "copies": copies, "utilisation": util,
            "fmax": {"clk": {"median": fmax[0], "min": fmax[1], "max": fmax[2], "seeds": 3}},
            "command": "raplas-hdl pnr intersection-unit --copies 2", **kw}


def test_ecp5_row_not_measured_without_a_multi_copy_run():
    from raplas_hdl.synth.capacity_ecp5 import ecp5_rows, render_ecp5

    tp = [{"scene": "s", "testers": 8, "lanes": 1, "pairs_per_cycle": 0.9}]
    single = _pnr_run(1, 32000, 42)
    other = {**_pnr_run(2, 1000, 0), "unit": "fp-add"}
    for runs in (None, [], [single, other]):
        (row,) = ecp5_rows(runs, tp, FP24)
        assert row["measured"] is False and "units" not in row and "fmax" not in row
    text = "\n".join(render_ecp5([row], 100e6))
    assert "| LFE5U-85F | 6 | generic | 8 | 1 | off | **not measured**" in text
    assert "MHz" not in text.split("not measured")[1].split("\n")[0].replace("Fmax MHz", "")


def test_ecp5_row_from_placed_copies():
    from raplas_hdl.synth.capacity_ecp5 import ecp5_rows, render_ecp5

    tp = [{"scene": "a", "testers": 8, "lanes": 1, "pairs_per_cycle": 0.9},
          {"scene": "b", "testers": 8, "lanes": 1, "pairs_per_cycle": 0.99},
          {"scene": "a", "testers": 4, "lanes": 1, "pairs_per_cycle": 0.5}]
    (row,) = ecp5_rows([_pnr_run(2, 64240, 84), _pnr_run(1, 32000, 42)], tp, FP24)
    assert row["measured"] and row["copies"] == 2 and row["basis"].startswith("place and route")
    assert row["bound_by"] == "TRELLIS_COMB" and row["units"] == 2      # 76.8 % for two
    assert row["fmax"]["median"] == 92.0
    assert row["pairs_per_s_placed"] == pytest.approx(2 * 0.9 * 92e6)
    assert row["pairs_per_s"] == pytest.approx(2 * 0.9 * 92e6)
    (row,) = ecp5_rows([_pnr_run(2, 30000, 84)], tp, FP24)
    assert row["bound_by"] == "MULT18X18D" and row["units"] == 3        # 2 / (84 / 156)
    assert row["pairs_per_s"] == pytest.approx(3 * 0.9 * 92e6)
    line = render_ecp5([row], 100e6)[-1]
    assert "| 2 | 30,000 / 83,640 (35.9%) | 84 / 156 (53.8%) |" in line
    assert "**3** (MULT18X18D) | **92.0** (90.0-95.0, 3) | 0.900-0.990 | 166 M | 248 M | 2.48x" \
        in line


def test_capacity_table_says_estimate_and_carries_the_ecp5_rows():
    key = lambda u, o, f="xc4v": (u, tuple(sorted(o.items())), f)   # noqa: E731
    base = {"rows": 4, "cols": 4, "target": "generic", "adder": "generic"}
    found = {
        key("intersection-unit", {**base, "testers": 8}): _row(42, 14798, 40, bram=46),
        key("plane-sphere", {**base, "testers": 8}): _row(24, 8488, 39),
        key("ray-triangle", {"target": "generic", "adder": "generic", "mode": "paper"}):
            _row(18, 6039, 40),
    }
    tp = [{"scene": "s", "testers": 8, "lanes": k, "pairs_per_cycle": 0.9} for k in (1, 2, 3)]
    cap = build_capacity(FP24, found, tp, {"1k": 1024})
    assert [r["measured"] for r in cap["ecp5"]] == [False]
    text = "\n".join(render_capacity(cap))
    assert "Every figure of this table is a Yosys estimate" in text
    assert all(x.endswith("| Yosys estimate |") for x in text.splitlines()
               if x.startswith("| XC4VSX35 |"))
    assert "### ECP5: placed and routed" in text and "**not measured**" in text
    cap = build_capacity(FP24, found, tp, {"1k": 1024}, pnr_runs=[_pnr_run(2, 64240, 84)])
    assert cap["ecp5"][0]["units"] == 2
    assert "| place and route (nextpnr-ecp5) | 2 |" in "\n".join(render_capacity(cap))


def test_cli_capacity_pnr_file_errors(tmp_path, capsys):
    from pathlib import Path

    tp = str(Path(__file__).resolve().parents[2] / "docs" / "results" / "throughput.json")
    assert main(["synth", "capacity", "--throughput", tp, "--pnr",
                 str(tmp_path / "none.json")]) == 2
    assert "--pnr: no such file" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"rows": []}))
    assert main(["synth", "capacity", "--throughput", tp, "--pnr", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--pnr:" in err and "no \"runs\" list" in err
