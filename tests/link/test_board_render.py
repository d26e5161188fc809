"""The simulated board end to end: the whole board design under Verilator, the host on its
serial port.

:class:`~raplas_hdl.sim.drive.serial_board_sim.SimulatedBoard` runs the serial board
(UARTBone bridge, board top, the certified 8x8 unit with the on-chip reduction: the board's
default build, ``raplas_hdl.cli.board_sim.BOARD_DEFAULTS``) with its UART pins driven bit by
bit from a pseudo-terminal at 4 clocks per bit (``SIM_DIVISOR``; a board's is its clock over
the baud rate). Checked:

- ``raplas-hdl render --backend board --port PORT`` renders cornell at 8x8 (8x8 primary and
  shadow bundles) in the default (certified) mode through it: the image, every pixel's
  nearest triangle, ``t`` and visibility equal the model's with the reduction, and so do the
  answers that crossed the link and the counters the any-hit early-out does not change
  (spheres, plane tests, skipped pairs; issued pairs at most the model's); the link's CRC
  was compared after the scene load and after every round;
- a render the build cannot do is refused before any work, in one line: another lattice,
  another mode, more triangles than Triangle Memory holds;
- (``make test-full``) teapot, 6,328 triangles, on a build with Triangle Memory 8,192 and
  Sphere Memory 1,024, equal to the model in the same way;
- LiteX's ``litex_server --uart`` and ``RemoteClient`` read the board's ID, its register-map
  version and configuration, write and read back a register, and read the counters (those
  the project's driver then reads) through the same terminal: the link speaks UARTBone,
  not merely itself.
"""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from raplas_hdl.cli import main
from raplas_hdl.cli.board_sim import BOARD_DEFAULTS
from raplas_hdl.fp import FP24
from raplas_hdl.host.backends import BackendUnavailable, make_backend
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene
from raplas_hdl.model.board_map import BOARD_ID, COUNTER_REGS, MAP_VERSION, REGISTERS
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.sim.drive.serial_board_sim import SIM_BAUD, SimulatedBoard

CFG = UnitConfig(fmt=FP24, **BOARD_DEFAULTS)
EXACT = ("spheres", "plane_tests", "pairs_skipped")


def test_the_simulated_board_end_to_end(tmp_path, capsys):
    """One test, so that one worker builds and starts the simulated board (pytest-xdist
    would start a module fixture's on every worker that drew one of its tests)."""
    with SimulatedBoard(CFG) as board:
        render_through_the_simulated_board_equals_the_model(board, tmp_path, capsys)
        render_the_board_cannot_do_is_refused_before_any_work(board)
        litex_tools_read_the_board_registers(board)


@pytest.mark.full
def test_a_mesh_of_thousands_of_triangles_on_a_bigger_board(tmp_path, capsys):
    """teapot (6,328 triangles, 791 leaf spheres of 8) on the build with Triangle Memory
    8,192 and Sphere Memory 1,024: about 4 minutes, 2 of them the scene's 160 k words over
    the simulated link."""
    with SimulatedBoard(replace(CFG, max_triangles=8192, max_spheres=1024)) as board:
        render_through_the_simulated_board_equals_the_model(board, tmp_path, capsys, "teapot")


def _settings(**kw):
    return RenderSettings(8, 8, progress=False, **{"rows": 8, "cols": 8, "shadow_rows": 8,
                                                   "shadow_cols": 8, **kw})


def _render_cli(tmp_path, name, scene, *backend):
    out = tmp_path / name
    assert main(["render", "--scene", scene, "--size", "8x8", "--shadow", "8x8",
                 *backend, "--no-progress", "-o", f"{out}.png", "--ids", f"{out}.npz",
                 "--json", f"{out}.json"]) == 0
    return np.load(f"{out}.npz"), json.loads(Path(f"{out}.json").read_text())["stats"]


def render_through_the_simulated_board_equals_the_model(board, tmp_path, capsys,
                                                        scene="cornell"):
    ids, stats = _render_cli(tmp_path, "board", scene, "--backend", "board", "--port",
                             board.port, "--baud", str(SIM_BAUD))
    assert "board (" in capsys.readouterr().out
    ref_ids, ref = _render_cli(tmp_path, "model", scene, "--backend", "model", "--reduce")
    assert (ref_ids["tri_id"] >= 0).any()
    assert (np.nan_to_num(ref_ids["visibility"], nan=1.0) < 1).any()
    assert sorted(ids.files) == sorted(ref_ids.files)
    for name in ref_ids.files:
        want = ref_ids[name]
        assert np.array_equal(ids[name], want, equal_nan=want.dtype.kind == "f"), name
    assert Path(tmp_path / "board.png").read_bytes() == Path(tmp_path / "model.png").read_bytes()
    unit, want = stats["unit"], ref["unit"]
    assert {k: unit[k] for k in EXACT} == {k: want[k] for k in EXACT}
    assert 0 < unit["pairs_issued"] <= want["pairs_issued"]    # the any-hit early-out
    assert stats["output_beats"]["answer"] == ref["output_beats"]["answer"] > 0
    link = stats["link"]
    assert link["rounds"] > 1 and link["words_written"] > 1000
    assert link["round_trips"] < link["words_read"]       # the result window in bursts


def render_the_board_cannot_do_is_refused_before_any_work(board):
    be = make_backend("board", FP24, mode="certified", port=board.port, baudrate=SIM_BAUD)
    try:
        writes = be.bus.words_written
        with pytest.raises(ValueError, match=r"takes 8x8 bundles, not 3x3 \(--shadow\): use "
                                             r"--shadow 8x8, or --shadow 0x0"):
            render(get_scene("cornell"), be, _settings(shadow_rows=3, shadow_cols=3))
        with pytest.raises(ValueError, match="Triangle Memory holds 1,024"):
            render(get_scene("stanford-bunny"), be, _settings())
        assert be.bus.words_written == writes      # nothing was loaded
    finally:
        be.close()
    with pytest.raises(BackendUnavailable, match="its unit is 'certified', --mode paper"):
        make_backend("board", FP24, mode="paper", port=board.port, baudrate=SIM_BAUD)


def litex_tools_read_the_board_registers(board):
    from tests.support.litex_server import litex_client

    with litex_client(board.port) as wb:
        assert wb.read(4 * REGISTERS["ID"]) == BOARD_ID
        assert wb.read(4 * REGISTERS["VERSION"]) == MAP_VERSION[0] << 16 | MAP_VERSION[1]
        lattice = wb.read(4 * REGISTERS["CFG_LATTICE"])
        assert (lattice & 0xFF, lattice >> 8 & 0xFF) == (CFG.rows, CFG.cols)
        wb.write(4 * REGISTERS["CMD_FIRST"], 0x1234)
        assert wb.read(4 * REGISTERS["CMD_FIRST"]) == 0x1234
        first = REGISTERS[next(iter(COUNTER_REGS.values()))]
        counters = wb.read(4 * first, length=len(COUNTER_REGS))
    # the same counters through the project's own driver
    from raplas_hdl.link.driver import BoardDriver
    from raplas_hdl.link.serial_bus import SerialBus

    with SerialBus(board.port, SIM_BAUD) as bus:
        assert list(BoardDriver(bus, CFG).read_counters().values()) == counters
