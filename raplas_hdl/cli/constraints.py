"""``raplas-hdl constraints``: UCF (XC4VSX35-10FF668) and XDC (7-series) of the board top.

Emits the board top's Verilog, reads its port names, and writes
``<dir>/raplas_board.ucf`` and ``<dir>/raplas_board.xdc`` (see
:mod:`raplas_hdl.rtl.constraints`); ``--check`` writes nothing and fails (exit 1) naming
every port that a committed file lacks or names in excess.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from . import grammar as g
from .verilog import add_unit_options, unit_options

UNIT = "board-top"
MAX_FREQ_MHZ = 1000.0


def add_parser(subparsers):
    from ..rtl.constraints import PART, UCF_NAME, XDC_NAME

    p = subparsers.add_parser(
        "constraints", help="write (or --check) the board top's UCF and XDC",
        description=f"Write {UCF_NAME} (ISE, {PART}) and {XDC_NAME} (Vivado, 7-series) for "
                    "the board top, with port names read from its emitted Verilog. Pin "
                    "locations are board specific: placeholders unless --pins gives them.")
    p.add_argument("-o", "--output-dir", default="constraints", metavar="DIR",
                   help="directory of the two files (default: constraints)")
    p.add_argument("--check", action="store_true",
                   help="write nothing; fail if a file lacks a port of the emitted top or "
                        "names a port it does not have")
    p.add_argument("--freq", type=g.float_range(0.0, MAX_FREQ_MHZ, lo_open=True), default=100.0,
                   metavar="MHZ", help=f"clock target in MHz, above 0 and at most "
                                       f"{MAX_FREQ_MHZ:g} (default 100)")
    p.add_argument("--in-delay", type=g.float_range(0.0), default=None, metavar="NS",
                   help="input delay after the clock edge, ns, less than the period "
                        "(default 60%% of the period)")
    p.add_argument("--out-delay", type=g.float_range(0.0), default=None, metavar="NS",
                   help="output delay budget before the next edge, ns, less than the period "
                        "(default 40%% of the period)")
    p.add_argument("--ucf-iostandard", default="LVCMOS25", metavar="STD",
                   help="I/O standard of the UCF (default LVCMOS25)")
    p.add_argument("--xdc-iostandard", default="LVCMOS33", metavar="STD",
                   help="I/O standard of the XDC (default LVCMOS33)")
    p.add_argument("--pins", default=None, metavar="FILE.json",
                   help='JSON pin file {"clk": "AB12", "wb_adr[0]": "C3", ...}')
    p.add_argument("--verilog", default=None, metavar="FILE.v",
                   help="also write the emitted top's Verilog (and manifest .json) here")
    g.add_format_option(p, field_widths=True)
    add_unit_options(p, units=(UNIT,))
    return p


def check(args) -> None:
    args.fmt = g.format_from_args(args)
    args.options = unit_options(args, UNIT)
    period = 1000.0 / args.freq
    for opt, v in (("--in-delay", args.in_delay), ("--out-delay", args.out_delay)):
        if v is not None and not v < period:
            raise g.UsageError(f"{opt} {v:g} ns is not less than the period {period:.3f} ns")
    for opt, v in (("--ucf-iostandard", args.ucf_iostandard),
                   ("--xdc-iostandard", args.xdc_iostandard)):
        if not v or not v.replace("_", "").isalnum():
            raise g.UsageError(f"{opt} {v!r} is not an I/O standard name (such as LVCMOS25)")
    outdir = Path(args.output_dir)
    if args.check:
        g.reject(args, ("pins", "verilog"), "with --check (it writes nothing)")
        if not outdir.is_dir():
            raise g.UsageError(f"-o {args.output_dir!r} is not a directory (--check reads "
                               "the files there)")
        return
    g.check_output_dir(outdir, "-o")
    if args.pins:
        g.check_input_file(args.pins, "--pins", (".json",))
        try:
            pins = json.loads(Path(args.pins).read_text())
        except (ValueError, UnicodeDecodeError) as exc:
            raise ValueError(f"--pins {args.pins!r} is not JSON ({g.one_line(exc)})") from None
        if not isinstance(pins, dict):
            raise g.UsageError(f"--pins {args.pins!r}: a pin file is a JSON object of port "
                               "bit -> pin")
    if args.verilog:
        v = g.check_output_file(args.verilog, (".v", ".sv"), "--verilog")
        g.check_output_file(v.with_suffix(".json"), (".json",), "manifest")


def run(args) -> int:
    from ..rtl.constraints import (UCF_NAME, XDC_NAME, board_ports, check_files, load_pins,
                                   ucf_text, xdc_text)
    from ..rtl.emit import emit_verilog
    from ..rtl.units import build_unit

    fmt = args.fmt
    unit, comp, opts = build_unit(UNIT, fmt, **args.options)
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
    ucf_s = ucf_text(ports, iostandard=args.ucf_iostandard, **common)
    xdc_s = xdc_text(ports, iostandard=args.xdc_iostandard, **common)
    outdir.mkdir(parents=True, exist_ok=True)
    ucf.write_text(ucf_s)
    xdc.write_text(xdc_s)
    written = [ucf, xdc]
    if args.verilog:
        vpath = Path(args.verilog)
        vpath.write_text(text)
        mpath = vpath.with_suffix(".json")
        mpath.write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
        written += [vpath, mpath]
    print("wrote " + ", ".join(map(str, written)), file=sys.stderr)
    return 0
