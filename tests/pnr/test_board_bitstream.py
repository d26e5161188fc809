"""``raplas-hdl bitstream --board ulx3s-85f``: the board design's clock, pins and bitstream.

In ``make test`` (seconds): the PLL's dividers (exact where 25 MHz times a ratio makes the
clock, within the ECP5's ranges everywhere), the UART divisor and its refusal, the board
design's ports each on the ULX3S pin amaranth-boards gives it (the oscillator G2, the FIRE 1
button R1, the FTDI's M1 / L4, LEDs B2 ... E2) in an ``.lpf`` that places them all, the one
EHXPLLL in the emitted Verilog with the chosen dividers, and bad input refused in one line
before any work. In ``make test-full`` (a whole synthesis, place and route and pack, about
an hour): the default build's bitstream, its report, and its clock met.
"""

import json

import pytest

from raplas_hdl.cli import main
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.pnr.bitstream import PREAMBLE, check_bitstream
from raplas_hdl.pnr.board import ULX3S_BOARD_PINS, check_lpf, lpf_text, ulx3s_pins
from raplas_hdl.pnr.board_bitstream import (BOARD_SEED, CLOCK_PORT, DEFAULT_CLOCK_MHZ,
                                            MAX_BAUD_ERROR, PNR_TARGET_MHZ, aim_lpf,
                                            board_clock, fastest_clock)
from raplas_hdl.rtl.ecp5_pll import OUT_MHZ, PFD_MHZ, VCO_MHZ, pll_settings

#: The board design's pins on the ULX3S (its schematic's sites).
SITES = {"clk_25mhz": "G2", "btn_fire": "R1", "uart_rx": "M1", "uart_tx": "L4",
         "led_heartbeat": "B2", "led_rx": "C2", "led_tx": "C1", "led_bus": "D2",
         "led_bus_error": "D1", "led_locked": "E2"}


@pytest.mark.parametrize("mhz,dividers,vco", [(75, (1, 3, 8), 600), (50, (1, 2, 12), 600),
                                              (100, (1, 4, 6), 600), (62.5, (2, 5, 10), 625),
                                              (25, (1, 1, 24), 600)])
def test_pll_makes_exact_clocks_exactly(mhz, dividers, vco):
    s = pll_settings(25.0, mhz)
    assert s.f_out == mhz and (s.clki_div, s.clkfb_div, s.clkop_div) == dividers
    assert s.f_vco == vco                      # ecppll's tie-break: the VCO nearest 600


def test_pll_stays_in_range_and_comes_near():
    for k in range(200):
        want = 4.0 + k * 0.98          # 4-199 MHz: the clocks a unit takes
        s = pll_settings(25.0, want)
        assert PFD_MHZ[0] <= s.f_pfd <= PFD_MHZ[1]
        assert VCO_MHZ[0] <= s.f_vco <= VCO_MHZ[1]
        assert OUT_MHZ[0] <= s.f_out <= OUT_MHZ[1]
        # 25 MHz over 1-8 times 1-80: a step of at most 25/8 MHz between outputs
        assert abs(s.f_out - want) <= 25.0 / 16 + 1e-9, (want, s)
    with pytest.raises(ValueError, match=r"^an ECP5 PLL output runs at 3.125-400 MHz, not 500$"):
        pll_settings(25.0, 500)


def test_uart_divisor_is_the_nearest_and_a_far_rate_is_refused():
    pll, divisor, baud = board_clock(75.0, 3_000_000)
    assert (pll.f_out, divisor, baud) == (75.0, 25, 3_000_000)
    pll, divisor, baud = board_clock(DEFAULT_CLOCK_MHZ, 3_000_000)      # 25 x 5 / 3
    assert (pll.clki_div, pll.clkfb_div, divisor, round(baud)) == (3, 5, 14, 2_976_190)
    pll, divisor, baud = board_clock(39.29, 3_000_000)      # 25 x 11 / 7
    assert (pll.clki_div, pll.clkfb_div, divisor, round(baud)) == (7, 11, 13, 3_021_978)
    pll, divisor, baud = board_clock(50.0, 3_000_000)     # 16.7 clocks per bit
    assert divisor == 17 and abs(baud / 3e6 - 1) < MAX_BAUD_ERROR
    with pytest.raises(ValueError, match=r"^at 10 MHz the UART makes 2,500,000 baud at best "
                                         r"\(divisor 4\), more than 2% off 3,000,000$"):
        board_clock(10.0, 3_000_000)


def test_fastest_clock_under_a_limit_is_one_the_pll_and_the_uart_take():
    """What a build that missed its clock suggests: under 44.9 MHz, 41.7 MHz (25 x 5 / 3,
    divisor 14, 0.8 % slow) is the fastest the PLL makes and the UART takes at 3 Mbaud
    (43.75 MHz, 25 x 7 / 4, misses 3 Mbaud by 2.8 %)."""
    assert fastest_clock(44.9, 3_000_000) == 41.6667
    assert fastest_clock(75.0, 3_000_000) == 75.0
    assert fastest_clock(45.0, 3_000_000) == 45.0
    assert fastest_clock(5.0, 3_000_000) is None            # 4 clocks per bit at the least
    for limit in (30.0, 44.9, 61.0, 99.0):
        f = fastest_clock(limit, 3_000_000)
        pll, _, baud = board_clock(f, 3_000_000)
        assert round(pll.f_out, 4) == f <= limit and abs(baud / 3e6 - 1) <= MAX_BAUD_ERROR


@pytest.fixture(scope="module")
def board_verilog():
    """The board design of a small unit, emitted (the pins do not depend on the unit)."""
    from raplas_hdl.fp import FP16
    from raplas_hdl.rtl.emit import emit_verilog
    from raplas_hdl.rtl.ulx3s_top import ULX3STop

    cfg = UnitConfig(fmt=FP16, rows=1, cols=2, tris_per_sphere=1, max_triangles=4,
                     max_spheres=2, fifo_depth=3)
    return emit_verilog(ULX3STop(cfg, pll_settings(25.0, 62.5), 21), "top", cfg.params())


def test_every_port_is_on_its_ulx3s_pin_and_the_pll_is_in_the_verilog(board_verilog):
    text, manifest = board_verilog
    ports = manifest["ports"]
    assert {p["name"] for p in ports} == set(ULX3S_BOARD_PINS) == set(SITES)
    assert all(p["width"] == 1 for p in ports)
    pins = ulx3s_pins("LFE5U-85F", {p["name"]: p["direction"] for p in ports},
                      places=ULX3S_BOARD_PINS)
    assert {k: v["site"] for k, v in pins.items()} == SITES
    lpf = lpf_text(ports, pins, "t")
    got = check_lpf(lpf, ports, CLOCK_PORT)
    assert got["locate"] == SITES and got["frequency"] == {CLOCK_PORT: 25.0}
    assert all("IO_TYPE=LVCMOS33" in a for a in got["iobuf"].values())
    assert "PULLMODE=DOWN" in got["iobuf"]["btn_fire"]      # released: no reset
    assert text.count("EHXPLLL #(") == 1
    assert text.count("DCCA dcca (") == 1          # the reset onto a global
    for param in (".CLKI_DIV(32'd2)", ".CLKFB_DIV(32'd5)", ".CLKOP_DIV(32'd10)",
                  '.FEEDBK_PATH("CLKOP")', '(* FREQUENCY_PIN_CLKOP = "62.5" *)',
                  '(* FREQUENCY_PIN_CLKI = "25" *)'):
        assert param in text, param
    with pytest.raises(ValueError, match="has no pin on the ULX3S"):
        lpf_text(ports + [{"name": "extra", "direction": "input", "width": 1}], pins, "t")
    # what nextpnr gets when it aims at 75 MHz with the PLL at 41.7: the oscillator at 45 MHz,
    # every pin as before
    aimed = check_lpf(aim_lpf(lpf, 75.0 / 41.666667), ports, CLOCK_PORT)
    assert aimed["locate"] == SITES and aimed["iobuf"] == got["iobuf"]
    assert aimed["frequency"] == {CLOCK_PORT: pytest.approx(45.0, abs=1e-5)}
    assert aim_lpf(lpf, 1.0) == lpf
    with pytest.raises(RuntimeError, match="does not give clk_25mhz one FREQUENCY"):
        aim_lpf(lpf.replace("25 MHZ", "12 MHZ"), 2.0)


@pytest.mark.parametrize("args,message", [
    ([], "the following arguments are required: --board"),
    (["--board", "ulx3s-12f"], "board must be one of ulx3s-85f, ulx3s-45f, ulx3s-25f"),
    (["--board", "ulx3s-85f", "--clock", "10"], "at 10 MHz the UART makes 2,500,000 baud"),
    (["--board", "ulx3s-85f", "--clock", "500"], "--clock"),
    (["--board", "ulx3s-85f", "--rows", "65"], "rows"),
    (["--board", "ulx3s-85f", "--baud", "300"], "--baud"),
    (["--board", "ulx3s-85f", "--seed", "0"], "--seed"),
    (["--board", "ulx3s-85f", "--target", "30"], "--target 30: place and route must aim at "
                                                 "least at the clock, 41.6667 MHz"),
    (["--board", "ulx3s-85f", "--mode", "certified", "--format", "e10m13"], "certified"),
])
def test_bad_input_is_one_line_before_any_work(args, message, capsys, tmp_path):
    assert main(["bitstream", *args, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert err.startswith("raplas-hdl bitstream: error: ") or "usage" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.full
def test_default_board_bitstream(tmp_path, capsys):
    """The default build (8x8 certified with the on-chip reduction) from the command line:
    a bitstream and an SVF, every port placed, the PLL's clock met (a whole place and
    route; cached under build/pnr/ when run before)."""
    out = tmp_path / "out"
    assert main(["bitstream", "--board", "ulx3s-85f", "-o", str(out)]) == 0
    cap = capsys.readouterr()
    assert "openFPGALoader -b ulx3s " in cap.out
    rec = json.loads((out / "board-top-ulx3s.json").read_text())
    b = rec["bitstream"]
    bit = out / "board-top-ulx3s.bit"
    data = bit.read_bytes()
    assert check_bitstream(bit) == len(data) == b["bytes"] > 100_000
    assert PREAMBLE in data[:4096] and b"LFE5U-85F" in data[:64]
    assert (out / "board-top-ulx3s.svf").stat().st_size == b["svf_bytes"] > len(data)
    assert {k: v["site"] for k, v in b["pins"].items()} == SITES
    assert rec["utilisation"]["TRELLIS_IO"]["used"] == len(SITES)
    assert rec["utilisation"]["EHXPLLL"]["used"] == 1
    assert rec["utilisation"]["DCCA"]["used"] == 2          # the PLL's clock and the reset
    opts = rec["options"]
    assert (opts["rows"], opts["cols"], opts["mode"], opts["reduce"]) == (8, 8, "certified",
                                                                         True)
    pll, divisor, _ = board_clock(DEFAULT_CLOCK_MHZ, 3_000_000)
    assert b["pll"]["f_out_mhz"] == round(pll.f_out, 6) and b["divisor"] == divisor == 14
    assert b["target_mhz"] == rec["freq_target"] == PNR_TARGET_MHZ
    assert b["seed"] == BOARD_SEED
    assert b["timing_met"] and rec["fmax"][b["clock"]]["median"] >= pll.f_out
    lpf = (out / "board-top-ulx3s.lpf").read_text()    # the user's: the true oscillator
    assert check_lpf(lpf, [{"name": k} for k in SITES], CLOCK_PORT)["frequency"] == {
        CLOCK_PORT: 25.0}
