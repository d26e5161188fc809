"""``raplas-hdl pnr UNIT --bitstream`` and ``--copies N`` on the FP units (seconds each).

The bitstream: fp-add behind the serial wrapper, every port placed by the generated ``.lpf``
(checked against the emitted top's ports), routed in context and packed by yowasp-ecppack
into a real ECP5 bitstream (the preamble, the part's name). The copies: two fp-adds and two
fp-muls side by side take twice the flip-flops and multipliers of one. Bad inputs are one
line, and a design that cannot fit the device is refused before place and route.
"""

import json
from pathlib import Path

import pytest

from raplas_hdl.cli import main
from raplas_hdl.fp import FP24
from raplas_hdl.pnr.bitstream import PREAMBLE, check_bitstream
from raplas_hdl.pnr.board import check_lpf, lpf_text, ulx3s_pins
from raplas_hdl.pnr.ecp5 import synthesize_ecp5
from raplas_hdl.pnr.fit import DEVICE_CELLS, cells_needed, check_fit
from raplas_hdl.pnr.unit import pnr_unit, unit_verilog
from raplas_hdl.rtl.emit import verilog_ports

#: The serial wrapper's ports.
WRAPPER_PORTS = {"clk_25mhz", "rst", "sclk", "sdi", "load", "sdo"}


@pytest.fixture(scope="module")
def build(tmp_path_factory):
    """One build folder for the module: the single units' netlists are shared (the copies'
    fit check synthesises one unit first)."""
    return tmp_path_factory.mktemp("pnr-build")


def test_fp_add_bitstream_every_port_placed(build, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("RAPLAS_BUILD", str(build))
    out = tmp_path / "out"
    assert main(["pnr", "fp-add", "--bitstream", "--seeds", "1", "-o", str(out)]) == 0
    cap = capsys.readouterr()
    line = cap.out.strip().splitlines()[-1]
    assert line.startswith("fp-add e7m16-rtz on the ULX3S (LFE5U-85F speed 6, serial wrapper)")
    assert "I/O 6 (all placed by the .lpf)" in line and "fp-add-ulx3s.bit" in line
    bit = out / "fp-add-ulx3s.bit"
    data = bit.read_bytes()
    assert check_bitstream(bit) == len(data) > 100_000
    assert PREAMBLE in data[:4096] and b"LFE5U-85F" in data[:64]
    rec = json.loads((out / "fp-add-ulx3s.json").read_text())
    assert rec["out_of_context"] is False and rec["copies"] == 1
    b = rec["bitstream"]
    assert b["bytes"] == len(data) and b["path"] == str(bit) and b["seed"] == 1
    assert set(b["pins"]) == WRAPPER_PORTS
    assert b["pins"]["clk_25mhz"]["site"] == "G2"          # the ULX3S's 25 MHz oscillator
    assert b["wrapper"]["in_bits"] == 51 and b["wrapper"]["out_bits"] == 28
    u = rec["utilisation"]
    assert u["TRELLIS_IO"]["used"] == len(WRAPPER_PORTS)
    assert u["TRELLIS_FF"]["used"] > rec["synth"]["ff"] // 2 > 0
    assert 0 < rec["lut4_fraction"] < 0.02
    f = rec["fmax"][b["clock"]]
    assert "clk_25mhz" in b["clock"] and f["median"] > rec["freq_target"] == 25.0
    # every port of the placed top is in the .lpf, and nothing else
    top = Path(rec["work"]) / "top.v"
    ports = verilog_ports(top.read_text(), rec["module"])
    assert {p["name"] for p in ports} == WRAPPER_PORTS
    placed = check_lpf((out / "fp-add-ulx3s.lpf").read_text(), ports, "clk_25mhz")
    assert set(placed["locate"]) == WRAPPER_PORTS and placed["frequency"] == {"clk_25mhz": 25}
    md = (out / "fp-add-ulx3s.md").read_text()
    assert "Bitstream: `" in md and "| clk_25mhz | G2 | clk25 0 |" in md


def test_lpf_is_checked_against_the_ports():
    ports = [{"name": n, "direction": "output" if n == "sdo" else "input", "width": 1}
             for n in sorted(WRAPPER_PORTS)]
    pins = ulx3s_pins()
    text = lpf_text(ports, pins, "t")
    check_lpf(text, ports, "clk_25mhz")
    with pytest.raises(ValueError, match="no LOCATE COMP line for port.* extra"):
        check_lpf(text, ports + [{"name": "extra", "direction": "input", "width": 1}],
                  "clk_25mhz")
    with pytest.raises(ValueError, match="names port.* the design lacks: sdo"):
        check_lpf(text, [p for p in ports if p["name"] != "sdo"], "clk_25mhz")
    with pytest.raises(ValueError, match="no pin on the ULX3S"):
        lpf_text(ports + [{"name": "led", "direction": "output", "width": 1}], pins, "t")
    with pytest.raises(ValueError, match="8 bits wide"):
        lpf_text([{"name": "sdi", "direction": "input", "width": 8}], pins, "t")
    no_freq = "\n".join(x for x in text.splitlines() if not x.startswith("FREQUENCY"))
    with pytest.raises(ValueError, match="no FREQUENCY"):
        check_lpf(no_freq, ports, "clk_25mhz")


def test_two_copies_scale_flip_flops_and_multipliers(build, tmp_path, capsys, monkeypatch):
    one = pnr_unit("fp-add", FP24, {}, seeds=(1,), base=build)
    two = pnr_unit("fp-add", FP24, {}, seeds=(1,), base=build, copies=2)
    assert (one["copies"], two["copies"]) == (1, 2) and two["module"] == "fp_add_x2"
    assert two["synth"]["ff"] == 2 * one["synth"]["ff"]
    assert two["utilisation"]["TRELLIS_FF"]["used"] == 2 * one["utilisation"]["TRELLIS_FF"]["used"]
    comb1, comb2 = (r["utilisation"]["TRELLIS_COMB"]["used"] for r in (one, two))
    assert 1.8 * comb1 <= comb2 <= 2.2 * comb1
    assert two["lut4_fraction"] == pytest.approx(comb2 / 83640, abs=1e-5)
    assert "2 copies placed" in two["summary"] and two["fmax"]["clk"]["median"] >= 100.0
    # fp-mul: one MULT18X18D per copy, through the command line
    monkeypatch.setenv("RAPLAS_BUILD", str(build))
    out = tmp_path / "o"
    assert main(["pnr", "fp-mul", "--copies", "2", "--seeds", "1", "-o", str(out)]) == 0
    assert "fp-mul e7m16-rtz x2: LFE5U-85F" in capsys.readouterr().out
    rec = json.loads((out / "fp-mul-x2.json").read_text())
    assert rec["synth"]["mult18"] == rec["utilisation"]["MULT18X18D"]["used"] == 2
    text, module, _ = unit_verilog("fp-mul", FP24, {})
    single = synthesize_ecp5(text, module, base=build / "pnr")     # the fit check's, cached
    assert single.cached and rec["synth"]["ff"] == 2 * single.counts["ff"]
    assert rec["command"].endswith("--seeds 1 --copies 2")
    assert "2 copies side by side" in (out / "fp-mul-x2.md").read_text()


def test_fit_check_is_a_lower_bound():
    counts = {"lut4": 100, "carry": 10, "dram": 2, "ff": 50, "mult18": 28, "alu54": 0,
              "ebr": 1}
    need = cells_needed(counts, io=6)
    assert need["TRELLIS_COMB"] == 124 and need["TRELLIS_RAMW"] == 2
    assert check_fit(counts, "LFE5U-25F", "x") == cells_needed(counts)
    with pytest.raises(ValueError, match=r"^x does not fit: it needs at least 29 MULT18X18D "
                                         r"\(the LFE5U-25F has 28\)$"):
        check_fit({**counts, "mult18": 29}, "LFE5U-25F", "x")
    assert set(DEVICE_CELLS) == {"LFE5U-25F", "LFE5U-45F", "LFE5U-85F"}


@pytest.mark.parametrize("args,message", [
    (["fp-add", "--copies", "0"], "--copies"),
    (["fp-add", "--copies", "257"], "--copies"),
    (["board-top", "--bitstream"], "--bitstream: board-top has its own clock and reset"),
    (["fp-add", "--bitstream", "--freq", "50"], "--freq does not apply with --bitstream"),
    (["fp-add", "--bitstream", "--target", "virtex4"], "--target virtex4 instantiates Xilinx"),
])
def test_bad_input_is_one_line(args, message, capsys, tmp_path):
    assert main(["pnr", *args, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("bitstream", [True, False])
def test_a_design_that_cannot_fit_is_refused_before_place_and_route(
        bitstream, build, tmp_path, capsys, monkeypatch):
    """29 fp-muls need 29 multipliers, the LFE5U-25F has 28: refused from one fp-mul's
    synthesis (cached), with or without the serial wrapper."""
    monkeypatch.setenv("RAPLAS_BUILD", str(build))
    args = ["pnr", "fp-mul", "--copies", "29", "--device", "LFE5U-25F", "-o",
            str(tmp_path / "o")] + (["--bitstream"] if bitstream else [])
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == ("raplas-hdl pnr: error: fp-mul x29"
                       + (" behind the serial wrapper" if bitstream else "")
                       + " does not fit: it needs at least 29 MULT18X18D (the LFE5U-25F "
                         "has 28)")
    assert not any("Traceback" in x or "place and route" in x for x in err)
    assert not (tmp_path / "o").exists()


def test_bench_keeps_copies_apart_and_renders_them():
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    import bench_pnr

    runs = [r for r in json.loads(bench_pnr.RESULTS.read_text())["runs"]
            if r.get("copies", 1) == 1]
    one = next(r for r in runs if r["unit"] == "fp-add" and r["speed"] == 6
               and r["rounding"] == "rtz")
    util = {k: {**v, "used": 2 * v["used"]} for k, v in one["utilisation"].items()}
    two = {**one, "copies": 2, "utilisation": util}
    assert bench_pnr._key(one) != bench_pnr._key(two) == bench_pnr._key({**two})
    assert bench_pnr._key(one) == bench_pnr._key({**one, "copies": 1})
    text = bench_pnr.render(runs + [two])
    assert "## Copies side by side" in text
    row = next(x for x in text.splitlines() if x.startswith("| fp-add | e7m16-rtz | - | 6 | 2 |"))
    assert f"| {one['fmax']['clk']['median']:.1f} |" in row
    assert "## Copies side by side" not in bench_pnr.render(runs)
