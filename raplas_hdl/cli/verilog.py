"""``raplas-hdl verilog UNIT``: write a unit's Verilog and its JSON manifest."""

from __future__ import annotations

import sys


def add_format_options(parser):
    """Format options shared by every command that builds or models a unit."""
    from ..fp import FP24, ROUNDINGS

    parser.add_argument("--format", default=None,
                        help="FP16, FP20, FP24, FP32 or eXmY (overrides --exp-bits/--man-bits)")
    parser.add_argument("--exp-bits", type=int, default=FP24.exp_bits,
                        help="exponent bits E (default 7)")
    parser.add_argument("--man-bits", type=int, default=FP24.man_bits,
                        help="fraction bits M (default 16)")
    parser.add_argument("--rounding", choices=ROUNDINGS, default=None,
                        help="rounding (default rtz, or the one --format names)")


def format_from_args(args):
    from ..fp import FPFormat, parse_format

    if args.format:
        return parse_format(args.format, args.rounding)
    return FPFormat(args.exp_bits, args.man_bits, args.rounding or "rtz")


def add_parser(subparsers):
    from ..rtl.units import UNITS

    p = subparsers.add_parser(
        "verilog", help="emit a unit's Verilog (and a JSON manifest beside it)",
        description="Emit deterministic Verilog for one unit. Units: "
                    + "; ".join(f"{u.name} ({u.summary})" for u in UNITS.values()))
    p.add_argument("unit", choices=list(UNITS), metavar="UNIT",
                   help=" | ".join(UNITS))
    add_format_options(p)
    seen = set()
    for unit in UNITS.values():
        for opt, (typ, default, help_) in unit.options.items():
            if opt in seen:
                continue
            seen.add(opt)
            p.add_argument("--" + opt.replace("_", "-"), dest=opt, type=typ, default=None,
                           help=f"{help_} (default {default})")
    p.add_argument("-o", "--output", required=True, help="Verilog file to write")
    return p


def run(args) -> int:
    from ..rtl.emit import write_unit
    from ..rtl.units import UNITS, build_unit

    fmt = format_from_args(args)
    unit = UNITS[args.unit]
    options = {opt: getattr(args, opt) for opt in unit.options}
    for opt in {o for u in UNITS.values() for o in u.options} - set(unit.options):
        if getattr(args, opt, None) is not None:
            raise ValueError(f"--{opt.replace('_', '-')} does not apply to unit {args.unit}")
    unit, comp, opts = build_unit(args.unit, fmt, **options)
    params = {"exp_bits": fmt.exp_bits, "man_bits": fmt.man_bits, "rounding": fmt.rounding,
              **opts}
    if "target" in unit.options:   # the manifest always says which multiplier was built
        params.setdefault("target", unit.options["target"][1])
    vpath, mpath = write_unit(comp, unit.module, params, args.output)
    print(f"wrote {vpath} ({unit.module}, latency {getattr(comp, 'latency', 'n/a')}) "
          f"and {mpath}", file=sys.stderr)
    return 0
