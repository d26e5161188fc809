"""``raplas-hdl constraints``: UCF (XC4VSX35-10FF668) and XDC (7-series) of the board top.

Emits the board top's Verilog, reads its port names, and writes
``<dir>/raplas_board.ucf`` and ``<dir>/raplas_board.xdc`` (see
:mod:`raplas_hdl.rtl.constraints`); ``--check`` writes nothing and fails (exit 1) naming
every port that a committed file lacks or names in excess.
"""

from __future__ import annotations

import sys
from pathlib import Path

UNIT = "board-top"


def add_parser(subparsers):
    from ..rtl.constraints import PART, UCF_NAME, XDC_NAME
    from ..rtl.units import UNITS
    from .verilog import add_format_options

    p = subparsers.add_parser(
        "constraints", help="write (or --check) the board top's UCF and XDC",
        description=f"Write {UCF_NAME} (ISE, {PART}) and {XDC_NAME} (Vivado, 7-series) for "
                    "the board top, with port names read from its emitted Verilog. Pin "
                    "locations are board specific: placeholders unless --pins gives them.")
    p.add_argument("-o", "--output-dir", default="constraints",
                   help="directory of the two files (default: constraints)")
    p.add_argument("--check", action="store_true",
                   help="write nothing; fail if a file lacks a port of the emitted top or "
                        "names a port it does not have")
    p.add_argument("--freq", type=float, default=100.0, help="clock target in MHz (default 100)")
    p.add_argument("--in-delay", type=float, default=None,
                   help="input delay after the clock edge, ns (default 60%% of the period)")
    p.add_argument("--out-delay", type=float, default=None,
                   help="output delay budget before the next edge, ns (default 40%% of the "
                        "period)")
    p.add_argument("--ucf-iostandard", default="LVCMOS25", help="default LVCMOS25")
    p.add_argument("--xdc-iostandard", default="LVCMOS33", help="default LVCMOS33")
    p.add_argument("--pins", default=None,
                   help='JSON pin file {"clk": "AB12", "wb_adr[0]": "C3", ...}')
    p.add_argument("--verilog", default=None,
                   help="also write the emitted top's Verilog (and manifest) here")
    add_format_options(p)
    for opt, (typ, default, help_) in UNITS[UNIT].options.items():
        p.add_argument("--" + opt.replace("_", "-"), dest=opt, type=typ, default=None,
                       help=f"{help_} (default {default})")
    return p


def run(args) -> int:
    from ..rtl.constraints import (UCF_NAME, XDC_NAME, board_ports, check_files, load_pins,
                                   ucf_text, xdc_text)
    from ..rtl.emit import emit_verilog
    from ..rtl.units import UNITS, build_unit
    from .verilog import format_from_args

    fmt = format_from_args(args)
    options = {opt: getattr(args, opt) for opt in UNITS[UNIT].options}
    unit, comp, opts = build_unit(UNIT, fmt, **options)
    params = {"exp_bits": fmt.exp_bits, "man_bits": fmt.man_bits, "rounding": fmt.rounding,
              **opts}
    text, manifest = emit_verilog(comp, unit.module, params)
    ports = board_ports(text, unit.module)
    outdir = Path(args.output_dir)
    ucf, xdc = outdir / UCF_NAME, outdir / XDC_NAME
    if args.check:
        problems = check_files(ports, {ucf: "ucf", xdc: "xdc"})
        for line in problems:
            print(f"raplas-hdl constraints: {line}", file=sys.stderr)
        if problems:
            print("raplas-hdl constraints: the files do not match the emitted top; "
                  "regenerate them with `raplas-hdl constraints`", file=sys.stderr)
            return 1
        print(f"{ucf} and {xdc} match the {len(ports)} ports of {unit.module}",
              file=sys.stderr)
        return 0
    pins = load_pins(args.pins, ports) if args.pins else None
    common = {"freq_mhz": args.freq, "in_delay": args.in_delay, "out_delay": args.out_delay,
              "pins": pins}
    outdir.mkdir(parents=True, exist_ok=True)
    ucf.write_text(ucf_text(ports, iostandard=args.ucf_iostandard, **common))
    xdc.write_text(xdc_text(ports, iostandard=args.xdc_iostandard, **common))
    written = [ucf, xdc]
    if args.verilog:
        import json

        vpath = Path(args.verilog)
        vpath.parent.mkdir(parents=True, exist_ok=True)
        vpath.write_text(text)
        mpath = vpath.with_suffix(".json")
        mpath.write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
        written += [vpath, mpath]
    print("wrote " + ", ".join(map(str, written)), file=sys.stderr)
    return 0
