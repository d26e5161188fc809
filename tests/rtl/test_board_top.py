"""The board-level top: register map, host driver in co-simulation, constraints.

- the register table of ``docs/board-top.md`` equals :data:`REGISTER_MAP`, which the RTL
  and the driver both use;
- the host driver (:class:`~raplas_hdl.link.driver.BoardDriver`) runs a FP24 scene
  of 30 triangles through ``board_top``'s Verilog over Wishbone, under Icarus and
  Verilator: seven runs (range and list runs, an early-out rewrite of the enable bits, an
  empty run, a keep-all run (``CMD_START.keep_all``), an all-disabled run, the first
  bundle's planes again), random idle cycles on the bus;
  every run's stream and counters equal the golden model's bit for bit. The same
  simulation checks the bus protocol (``wb_err``, the memory window, a refused command);
- the driver imports neither Amaranth nor cocotb;
- ``raplas-hdl constraints --check`` passes on the committed files and names a port that
  a file lacks or has in excess.
"""

import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.model.board_map import REGISTER_MAP, parse_markdown_table
from raplas_hdl.model.config import UnitConfig
from tests.support.unit_scenes import assert_keep_all, check_against_model, scene_and_runs

ROOT = Path(__file__).resolve().parents[2]
CFG = UnitConfig(fmt=FP24, rows=4, cols=4, testers=4, tris_per_sphere=4, max_triangles=256,
                 max_spheres=128, fifo_depth=8)


def test_board_doc_table_matches_register_map():
    doc = (ROOT / "docs" / "board-top.md").read_text()
    assert parse_markdown_table(doc) == REGISTER_MAP


def test_board_driver_imports_no_amaranth_or_cocotb():
    code = ("import sys, raplas_hdl.link.driver; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('amaranth', 'cocotb')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


@pytest.fixture(scope="module")
def scene_runs():
    return scene_and_runs(CFG, 30, seed=7)


# the board's default build (certified, answers on the bus) and a certified build without
# the reduction (each pair's outcome and tight bit in RES_INFO) besides the paper mode's
@pytest.mark.parametrize("simulator, mode, reduce", [
    ("icarus", "paper", False), ("verilator", "paper", False),
    ("verilator", "certified", True),
    pytest.param("icarus", "certified", False, marks=pytest.mark.full)],
    ids=["icarus", "verilator", "verilator-certified-reduce", "icarus-certified"])
def test_board_cosim_matches_model(simulator, mode, reduce, scene_runs):
    from raplas_hdl.sim.drive.board_sim import run_board

    cfg = replace(CFG, mode=mode, reduce=reduce)
    scene, runs = scene_runs
    t0 = time.monotonic()
    results, stats = run_board(simulator, cfg, scene, runs, seed=7, gap_density=0.3,
                               build_key="board-test")
    ref = check_against_model(cfg, scene, runs, results)
    assert_keep_all(cfg, scene, runs, ref)
    print(f"{simulator}: {time.monotonic() - t0:.1f} s, {stats}")
    assert sum(r[1]["pairs_issued"] for r in ref) > 50
    assert sum(r[1]["hits"] for r in ref) > 0
    assert sum(r[1]["pairs_skipped"] for r in ref) > 0
    assert any(r[0]["empty"][0] for r in ref)
    if mode == "certified":
        outcomes = np.concatenate([r[0]["outcome"] for r in ref])
        assert 1 in outcomes.tolist()     # certain hits (answers, with the reduction)


# -- constraints ----------------------------------------------------------------------------
# The port names do not depend on the build parameters: a small build keeps emission short.
SMALL = ["--format", "FP16", "--rows", "2", "--cols", "2", "--tris-per-sphere", "2",
         "--max-triangles", "16", "--max-spheres", "8", "--fifo-depth", "3"]


@pytest.fixture(scope="module")
def small_ports():
    from raplas_hdl.fp import FP16
    from raplas_hdl.rtl.constraints import board_ports
    from raplas_hdl.sim.drive.board_sim import board_verilog   # emitted once for every xdist worker

    cfg = UnitConfig(fmt=FP16, rows=2, cols=2, tris_per_sphere=2, max_triangles=16,
                     max_spheres=8, fifo_depth=3)
    return board_ports(board_verilog(cfg))


def test_constraints_check_passes_on_committed_files(capsys):
    from raplas_hdl.cli import main

    assert main(["constraints", "--check", "-o", str(ROOT / "constraints"), *SMALL]) == 0
    assert "match the 11 ports of board_top" in capsys.readouterr().err


def test_constraints_check_names_missing_and_extra_ports(tmp_path, small_ports):
    from raplas_hdl.rtl.constraints import check_files

    ucf = (ROOT / "constraints" / "raplas_board.ucf").read_text()
    xdc = (ROOT / "constraints" / "raplas_board.xdc").read_text()
    (tmp_path / "a.ucf").write_text(
        "\n".join(line for line in ucf.splitlines() if '"wb_we"' not in line)
        + '\nNET "wb_irq" IOSTANDARD = LVCMOS25;\n')
    (tmp_path / "a.xdc").write_text(xdc.replace(" wb_we}", "}").replace("wb_adr[*]",
                                                                          "wb_addr[*]")
                                    + "# set_property PACKAGE_PIN <pin> [get_ports {wb_adr[8]}]\n")
    problems = check_files(small_ports, {tmp_path / "a.ucf": "ucf", tmp_path / "a.xdc": "xdc"})
    text = "\n".join(problems)
    assert "a.ucf: port(s) of board_top not constrained: wb_we" in text
    assert "a.ucf: port(s) not in board_top's Verilog: wb_irq" in text
    assert "a.ucf: no pin line for wb_we" in text
    assert "a.xdc: port(s) of board_top not constrained: wb_adr, wb_we" in text
    assert "a.xdc: port(s) not in board_top's Verilog: wb_addr" in text
    assert "a.xdc: pin line(s) for port bit(s) not in board_top: wb_adr[8]" in text
    assert len(problems) == 6
    assert check_files(small_ports, {tmp_path / "missing.xdc": "xdc"})[0].endswith(
        "missing (write it with `raplas-hdl constraints`)")


def test_constraints_pins_and_timing(tmp_path, small_ports):
    from raplas_hdl.rtl.constraints import check_files, load_pins, ucf_text, xdc_text

    (tmp_path / "pins.json").write_text('{"clk": "AB12", "wb_adr[3]": "C3"}')
    pins = load_pins(tmp_path / "pins.json", small_ports)
    ucf = ucf_text(small_ports, freq_mhz=125.0, pins=pins)
    xdc = xdc_text(small_ports, freq_mhz=125.0, pins=pins)
    assert 'NET "clk" LOC = "AB12";' in ucf and 'NET "wb_adr<3>" LOC = "C3";' in ucf
    assert "set_property PACKAGE_PIN C3 [get_ports {wb_adr[3]}]" in xdc
    assert 'PERIOD "TN_clk" 8.000 ns' in ucf and "create_clock -period 8.000" in xdc
    assert 'OFFSET = IN 3.200 ns VALID 3.200 ns BEFORE "clk"' in ucf
    assert "set_input_delay -clock clk -max 4.800" in xdc
    assert 'NET "rst" TIG;' in ucf and "set_false_path -from [get_ports rst]" in xdc
    (tmp_path / "p.ucf").write_text(ucf)
    (tmp_path / "p.xdc").write_text(xdc)
    assert check_files(small_ports, {tmp_path / "p.ucf": "ucf", tmp_path / "p.xdc": "xdc"}) == []
    (tmp_path / "bad.json").write_text('{"wb_adr[8]": "C4"}')
    with pytest.raises(ValueError, match=r"wb_adr\[8\]"):
        load_pins(tmp_path / "bad.json", small_ports)


def test_board_doc_ports_match_verilog(small_ports):
    import re

    doc = (ROOT / "docs" / "board-top.md").read_text()
    section = doc.split("## Ports", 1)[1].split("\n## ", 1)[0]
    named = {n for row in section.splitlines() if row.startswith("| `")
             for n in re.findall(r"`([a-z_]+)`", row.split("|")[1])}
    assert named == {p["name"] for p in small_ports}


def test_board_top_is_registered():
    from raplas_hdl.rtl.units import UNITS

    assert UNITS["board-top"].module == "board_top"


class _ConfigBus:
    """Answers the identification registers of a build (no unit behind it)."""

    def __init__(self, config, ident=None):
        from raplas_hdl.model.board_map import BOARD_ID, REGISTERS, config_words

        self.regs = {REGISTERS[k]: v for k, v in config_words(config.params()).items()}
        self.regs[REGISTERS["ID"]] = BOARD_ID if ident is None else ident
        self.regs[REGISTERS["VERSION"]] = 1 << 16

    def read(self, addr):
        return self.regs.get(addr, 0)

    def write(self, addr, value):
        raise AssertionError("the identification makes no write")


def test_board_driver_checks_the_build():
    from raplas_hdl.link.driver import BoardDriver, BoardMismatch

    drv = BoardDriver(_ConfigBus(CFG))
    assert drv.config == CFG                     # taken from the board
    assert BoardDriver(_ConfigBus(CFG), CFG).reads == 8
    other = replace(CFG, rows=2, mode="conservative")
    with pytest.raises(BoardMismatch, match="rows: board 4, expected 2; mode: board 'paper'"):
        BoardDriver(_ConfigBus(CFG), other)
    with pytest.raises(BoardMismatch, match="ID register reads 0x00000000"):
        BoardDriver(_ConfigBus(CFG, ident=0), CFG)
