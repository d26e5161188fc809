"""``raplas-hdl board-sim``: the board design simulated behind a pseudo-terminal.

Starts :class:`~raplas_hdl.sim.drive.serial_board_sim.SimulatedBoard` (the UARTBone bridge,
the board top and its unit under Verilator, the UART driven bit by bit from a
pseudo-terminal), prints the terminal's name and keeps it running until Ctrl-C, so that the
host side opens it as it would a board's serial port:
``raplas-hdl render --backend board --port PORT`` in another shell, or LiteX's
``litex_server --uart --uart-port PORT``.
"""

from __future__ import annotations

import contextlib
import time

from . import grammar as g
from .verilog import add_unit_options, unit_options

#: The board's build where the command line is silent: the render's default mode and bundle
#: lattice, answers (not pairs) on the link. ``raplas-hdl bitstream`` builds the same.
BOARD_DEFAULTS = {"rows": 8, "cols": 8, "mode": "certified", "reduce": True}


def board_config(args):
    """The :class:`~raplas_hdl.model.config.UnitConfig` of the unit options in ``args``
    (the board-top unit's), :data:`BOARD_DEFAULTS` where none is given."""
    from ..model.config import UnitConfig

    opts = {k: v for k, v in unit_options(args, "board-top").items() if v is not None}
    for k in ("target", "adder"):
        opts.pop(k, None)
    return UnitConfig(fmt=args.fmt, **{**BOARD_DEFAULTS, **opts})


def add_parser(subparsers):
    p = subparsers.add_parser(
        "board-sim", help="simulate the board behind a pseudo-terminal (a serial port)",
        description="Simulate the board design (UARTBone bridge, board top, unit) under "
                    "Verilator with its UART on a pseudo-terminal, print the terminal's name "
                    "and run until Ctrl-C: render through it with raplas-hdl render "
                    "--backend board --port PORT. The build: "
                    + ", ".join(f"{k} {v}" for k, v in BOARD_DEFAULTS.items())
                    + " unless the unit options say otherwise.")
    g.add_format_option(p, field_widths=True)
    add_unit_options(p, units=("board-top",), only=("rows", "cols", "testers",
                                                    "tris_per_sphere", "max_triangles",
                                                    "max_spheres", "fifo_depth", "mode",
                                                    "reduce"))
    p.add_argument("--divisor", type=g.int_range(4, 1 << 16), default=None, metavar="N",
                   help="the simulated UART's clocks per bit (default 4)")
    p.add_argument("--seconds", type=g.float_range(0.0, lo_open=True), default=None,
                   metavar="S", help="stop after S seconds (default: at Ctrl-C)")
    return p


def check(args) -> None:
    args.fmt = g.format_from_args(args)
    args.config = board_config(args)
    g.require_simulator("verilator")


def run(args) -> int:
    from ..sim.drive.serial_board_sim import SIM_BAUD, SIM_DIVISOR, SimulatedBoard

    cfg = args.config
    print(f"building the board ({cfg.fmt.name} {cfg.mode}{' reduce' if cfg.reduce else ''} "
          f"{cfg.rows}x{cfg.cols}, {cfg.max_triangles} triangles, {cfg.max_spheres} "
          "spheres); the first build takes minutes", flush=True)
    with SimulatedBoard(cfg, args.divisor or SIM_DIVISOR) as board:
        lattice = f"{cfg.rows}x{cfg.cols}"
        print(f"simulated board on {board.port} (Ctrl-C stops it)\n"
              f"  raplas-hdl render --backend board --port {board.port} --baud {SIM_BAUD} "
              f"--tile {lattice} --shadow {lattice} -o out.png", flush=True)
        t0 = time.monotonic()
        with contextlib.suppress(KeyboardInterrupt):      # Ctrl-C: stop the board
            while board.alive and (args.seconds is None
                                   or time.monotonic() - t0 < args.seconds):
                time.sleep(0.2)
        if not board.alive:
            raise RuntimeError("the simulated board stopped")
    return 0
