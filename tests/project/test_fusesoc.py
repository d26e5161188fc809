"""``raplas-hdl fusesoc``: the core parses with FuseSoC's own library and names files that
exist, the top is the emitted module, the board top's constraints are its UCF/xdc files,
the filelist compiles, and FuseSoC runs the core's lint target."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest
from fusesoc.capi2.coreparser import Core2Parser
from fusesoc.core import Core

from raplas_hdl.cli import main

BOARD = ["--rows", "1", "--cols", "1", "--tris-per-sphere", "2", "--max-triangles", "8",
         "--max-spheres", "4", "--fifo-depth", "3"]


def _core(path):
    return Core(Core2Parser(), str(path))


def _flags(target):
    return {"target": target, "is_toplevel": True}


@pytest.fixture(scope="module")
def fp_add(tmp_path_factory):
    out = tmp_path_factory.mktemp("fusesoc") / "fp_add_core"
    assert main(["fusesoc", "fp-add", "--format", "e5m10", "--stages", "2", "-o", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def board(tmp_path_factory):
    out = tmp_path_factory.mktemp("fusesoc") / "board"
    assert main(["fusesoc", "board-top", *BOARD, "-o", str(out)]) == 0
    return out


def test_core_parses_and_names_the_emitted_top(fp_add):
    core = _core(fp_add / "fp_add.core")
    manifest = json.loads((fp_add / "fp_add.json").read_text())
    assert str(core.name) == "raplas:hdl:fp_add:0.1.0"
    assert core.get_toplevel(_flags("default")) == manifest["module"] == "fp_add"
    files = core.get_files(_flags("default"))
    assert files == [{"name": "fp_add.v", "file_type": "verilogSource"}]
    text = (fp_add / files[0]["name"]).read_text()
    assert "\nmodule fp_add(" in text or "\nmodule fp_add (" in text
    desc = core.get_description()
    for key, value in manifest["parameters"].items():
        assert f"{key}={value}" in desc
    assert "exp_bits=5" in desc and "man_bits=10" in desc and "stages=2" in desc
    assert f"latency: {manifest['latency']} cycles" in desc
    assert core.get_toplevel(_flags("lint")) == "fp_add"
    assert core.get_target(_flags("lint")).default_tool == "verilator"
    assert core.get_target(_flags("synth_ise")) is None   # not a board top: no constraints


def test_verilog_is_the_verilog_command_s(fp_add, tmp_path):
    ref = tmp_path / "ref.v"
    assert main(["verilog", "fp-add", "--format", "e5m10", "--stages", "2", "-o", str(ref)]) == 0
    assert (fp_add / "fp_add.v").read_bytes() == ref.read_bytes()


def test_board_top_core_carries_ucf_and_xdc(board):
    from raplas_hdl.rtl.constraints import board_ports, check_files

    core = _core(board / "board_top.core")
    assert str(core.name) == "raplas:hdl:board_top:0.1.0"
    seen = {}
    for target, tool in (("synth_ise", "ise"), ("synth_vivado", "vivado")):
        assert core.get_toplevel(_flags(target)) == "board_top"
        assert core.get_target(_flags(target)).default_tool == tool
        files = core.get_files(_flags(target))
        assert files[0] == {"name": "board_top.v", "file_type": "verilogSource"}
        for f in files:
            assert (board / f["name"]).is_file(), f
            seen[f["file_type"]] = f["name"]
    assert seen == {"verilogSource": "board_top.v", "UCF": "raplas_board.ucf",
                    "xdc": "raplas_board.xdc"}
    assert dict(core.get_target(_flags("synth_ise")).tools)["ise"]["device"] == "xc4vsx35"
    ports = board_ports((board / "board_top.v").read_text())
    assert check_files(ports, {board / "raplas_board.ucf": "ucf",
                               board / "raplas_board.xdc": "xdc"}) == []
    assert "rows=1" in core.get_description() and "max_triangles=8" in core.get_description()


def test_filelist_compiles_with_icarus(fp_add, tmp_path):
    iverilog = shutil.which("iverilog")
    assert iverilog, "iverilog is installed by tools/bootstrap.py"
    assert (fp_add / "fp_add.f").read_text() == "fp_add.v\n"
    out = tmp_path / "a.vvp"
    res = subprocess.run([iverilog, "-g2012", "-s", "fp_add", "-o", str(out), "-c", "fp_add.f"],
                         cwd=fp_add, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert out.stat().st_size > 0


def _lint(core_dir, vlnv, cwd):
    from raplas_hdl.sim.build.runner import simulator_env

    res = subprocess.run([sys.executable, "-m", "fusesoc.main", "--cores-root", str(core_dir),
                          "run", "--target", "lint", vlnv], cwd=cwd,
                         env=simulator_env("verilator"), capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    assert (cwd / "build" / vlnv.replace(":", "_") / "lint-verilator").is_dir()


def test_fusesoc_runs_the_lint_target(fp_add, tmp_path):
    """FuseSoC (edalize) runs Verilator --lint-only on the core, found by its VLNV in a
    library folder."""
    _lint(fp_add, "raplas:hdl:fp_add:0.1.0", tmp_path)


def test_virtex4_core_lints_with_the_dsp48_model(tmp_path):
    """With DSP48 primitives the lint target adds Yosys's DSP48 model (without it Verilator
    fails on the unknown module); the .f lists it for simulators."""
    out = tmp_path / "mul"
    assert main(["fusesoc", "fp-mul", "--target", "virtex4", "-o", str(out)]) == 0
    core = _core(out / "fp_mul.core")
    assert "target=virtex4" in core.get_description()
    assert [f["name"] for f in core.get_files(_flags("lint"))] == ["fp_mul.v", "dsp48_sim.v"]
    assert [f["name"] for f in core.get_files(_flags("default"))] == ["fp_mul.v"]
    assert "\nmodule DSP48 (" in (out / "dsp48_sim.v").read_text()
    assert (out / "fp_mul.f").read_text() == "fp_mul.v\ndsp48_sim.v\n"
    _lint(out, "raplas:hdl:fp_mul:0.1.0", tmp_path)


def test_core_name_option(tmp_path):
    out = tmp_path / "c"
    assert main(["fusesoc", "fp-mul", "--core-name", "me:ip:mul24:1.2", "-o", str(out)]) == 0
    core = _core(out / "fp_mul.core")
    assert str(core.name) == "me:ip:mul24:1.2"
    assert core.get_toplevel(_flags("default")) == "fp_mul"


@pytest.mark.parametrize("argv, message", [
    (["fusesoc", "fp-add", "--rows", "2", "-o", "x"], "--rows does not apply to unit fp-add"),
    (["fusesoc", "fp-add", "--core-name", "a b", "-o", "x"], "is not a VLNV"),
    (["fusesoc", "nope", "-o", "x"], "unit must be one of fp-add"),
])
def test_bad_input_is_one_line(argv, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("raplas-hdl fusesoc: error:"), err
    assert message in err[0]
    assert not (tmp_path / "x").exists()


def test_help_is_plain_and_reads_the_format(capsys):
    from raplas_hdl.cli import build_parser
    from raplas_hdl.cli import grammar as g
    from raplas_hdl.fp import FP24

    with pytest.raises(SystemExit) as exc:
        main(["fusesoc", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "``" not in text and ":mod:" not in text and "(default None)" not in text
    assert "--core-name VLNV" in text and "--target {generic,virtex4}" in text
    args = build_parser().parse_args(["fusesoc", "fp-add", "-o", "d", "--format", "e7m16-rne"])
    assert g.format_from_args(args) == FP24.with_rounding("rne")
