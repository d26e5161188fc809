"""``raplas-hdl verilog UNIT``: write a unit's Verilog and its JSON manifest."""

from __future__ import annotations

import sys

from ..model.modes import RTL_MODES
from . import grammar as g

#: The units and their options as the command line states them: option -> (argparse
#: type, metavar, help without the default). Per-unit defaults and ranges come from
#: UNIT_LIMITS; the builders in raplas_hdl.rtl.units check the same ranges again.
UNIT_NAMES = ("fp-add", "fp-mul", "fp-le", "fp-lt", "fp-neg", "plane-sphere-tester",
              "plane-sphere", "ray-triangle", "intersection-unit", "board-top")

#: option -> {unit: (lo, hi, default)} for the integer options; choices for the others.
UNIT_LIMITS = {
    # the defaults of raplas_hdl.rtl.step_delays.DEFAULT_STAGES, kept here as text so that
    # the command line does not load the RTL (a test compares them)
    "stages": {"fp-add": (1, 9, "rtz 6, rne 7, chop 5"),
               "fp-mul": (1, 5, "rtz 4, rne 5, chop 4")},
    # the reducer alone: a unit of `raplas-hdl cosim` only
    "rows": {u: (1, g.MAX_LATTICE, 4) for u in ("plane-sphere", "intersection-unit",
                                                 "board-top", "reducer")},
    "cols": {u: (1, g.MAX_LATTICE, 4) for u in ("plane-sphere", "intersection-unit",
                                                 "board-top", "reducer")},
    "testers": {u: (1, 2 * g.MAX_LATTICE, None) for u in ("plane-sphere",
                                                           "intersection-unit", "board-top")},
    "tris_per_sphere": {u: (1, 4096, 8) for u in ("intersection-unit", "board-top")},
    "max_triangles": {"board-top": (1, 65536, 1024)},
    "max_spheres": {"board-top": (1, 16384, 256)},
    "fifo_depth": {"board-top": (3, 1024, 16)},
    "lanes": {"intersection-unit": (1, 8, 1)},
}
CHOICE_OPTIONS = {
    "mode": (RTL_MODES, "paper",
             ("ray-triangle", "intersection-unit", "board-top")),
    "target": (("generic", "virtex4"), "generic",
               ("fp-add", "fp-mul", "plane-sphere-tester", "plane-sphere", "ray-triangle",
                "intersection-unit", "board-top")),
    "adder": (("generic", "virtex4"), "generic",
              ("plane-sphere-tester", "plane-sphere", "ray-triangle", "intersection-unit",
               "board-top")),
}
#: flags (given or not): option -> the units that take them.
FLAG_OPTIONS = {"reduce": ("intersection-unit", "board-top")}
_HELP = {
    "stages": "pipeline stages",
    "rows": "bundle rows",
    "cols": "bundle columns",
    "testers": "plane-sphere testers, at most rows+cols",
    "tris_per_sphere": "triangles per bounding sphere",
    "max_triangles": "Triangle Memory depth (larger units take minutes to emit)",
    "max_spheres": "Sphere Memory depth",
    "fifo_depth": "pair FIFO depth",
    "lanes": "ray-triangle lanes behind the one culling array (results in the same order)",
    "reduce": "on-chip reduction: one ANSWER beat per ray (the nearest hit, or any hit "
              "for shadow rays) leaves the unit, not one result beat per pair",
    "mode": "ray-triangle mode",
    "target": "multiplier target: inferred multiplies (generic) or Virtex-4 DSP48 "
              "primitives (virtex4); fp-add: its shifts and add in two DSP48",
    "adder": "FP adder target of the unit's adders: fabric (generic) or two Virtex-4 DSP48 "
             "each (virtex4, latency 7)",
}


def _units_text(units) -> str:
    units = list(units)
    return "all units" if len(units) == len(UNIT_NAMES) else ", ".join(units)


def unit_takes(unit: str) -> set:
    """The unit options that ``unit`` takes."""
    return ({o for o, pu in UNIT_LIMITS.items() if unit in pu}
            | {o for o, (_, _, t) in CHOICE_OPTIONS.items() if unit in t}
            | {o for o, t in FLAG_OPTIONS.items() if unit in t})


def add_unit_options(p, units=UNIT_NAMES, only=None):
    """The unit options of ``units`` (help: range, default and which units take them);
    ``only`` restricts them to those names."""
    grp = p.add_argument_group("unit options (each applies to the units named)")
    for opt, per_unit in UNIT_LIMITS.items():
        if only is not None and opt not in only:
            continue
        per_unit = {u: v for u, v in per_unit.items() if u in units}
        if not per_unit:
            continue
        lo = min(v[0] for v in per_unit.values())
        hi = max(v[1] for v in per_unit.values())
        ranges = {(v[0], v[1], v[2]) for v in per_unit.values()}
        if len(ranges) == 1:
            a, b, d = ranges.pop()
            default = "rows+cols" if d is None else d
            text = f"{_HELP[opt]}, {a} to {b} (default {default}); {_units_text(per_unit)}"
        else:
            text = _HELP[opt] + ": " + ", ".join(
                f"{u} {a} to {b} (default {d})" for u, (a, b, d) in per_unit.items())
        grp.add_argument("--" + opt.replace("_", "-"), dest=opt, default=None, metavar="N",
                         type=int_option(opt, lo, hi), help=text)
    for opt, (choices, default, takers) in CHOICE_OPTIONS.items():
        if only is not None and opt not in only:
            continue
        takers = [u for u in takers if u in units]
        if not takers:
            continue
        grp.add_argument("--" + opt, dest=opt, default=None, metavar="{" + ",".join(choices) + "}",
                         type=g.choice(*choices, what=opt),
                         help=f"{_HELP[opt]} (default {default}); {_units_text(takers)}")
    for opt, takers in FLAG_OPTIONS.items():
        takers = [u for u in takers if u in units]
        if (only is not None and opt not in only) or not takers:
            continue
        grp.add_argument("--" + opt, dest=opt, default=None, action="store_const", const=True,
                         help=f"{_HELP[opt]}; {_units_text(takers)}")


def int_option(opt, lo, hi):
    conv = g.int_range(lo, hi)

    def convert(text):
        return conv(text)

    convert.__name__ = opt
    return convert


def unit_options(args, unit: str) -> dict:
    """The unit options given on the command line for ``unit`` (None: the unit's default).

    Raises UsageError for an option that ``unit`` does not take or a value outside the
    unit's own range."""
    opts = {}
    for opt, per_unit in UNIT_LIMITS.items():
        v = getattr(args, opt, None)
        if unit in per_unit:
            lo, hi, _ = per_unit[unit]
            if v is not None and not lo <= v <= hi:
                raise g.UsageError(f"--{opt.replace('_', '-')} of {unit} must be {lo} to "
                                   f"{hi}, not {v}")
            opts[opt] = v
        elif v is not None:
            raise g.UsageError(f"--{opt.replace('_', '-')} does not apply to unit {unit}"
                               + _takes(unit))
    for opt, (_, _, takers) in CHOICE_OPTIONS.items():
        v = getattr(args, opt, None)
        if unit in takers:
            opts[opt] = v
        elif v is not None:
            raise g.UsageError(f"--{opt} does not apply to unit {unit}" + _takes(unit))
    for opt, takers in FLAG_OPTIONS.items():
        v = getattr(args, opt, None)
        if unit in takers:
            opts[opt] = v
        elif v is not None:
            raise g.UsageError(f"--{opt} does not apply to unit {unit}" + _takes(unit))
    if opts.get("mode") == "certified" and getattr(args, "fmt", None) is not None:
        from ..model.certified import check_certified_format

        try:
            check_certified_format(args.fmt)
        except ValueError as exc:
            raise g.UsageError(f"--mode certified: {exc}") from None
    if opts.get("reduce") and getattr(args, "fmt", None) is not None:
        from ..model.reduction import check_reduce_format

        try:
            check_reduce_format(args.fmt)
        except ValueError as exc:
            raise g.UsageError(f"--reduce: {exc}") from None
    if opts.get("testers") is not None:
        rows = opts.get("rows") or UNIT_LIMITS["rows"][unit][2]
        cols = opts.get("cols") or UNIT_LIMITS["cols"][unit][2]
        if opts["testers"] > rows + cols:
            raise g.UsageError(f"--testers {opts['testers']} is more than rows+cols = "
                               f"{rows + cols} (one tester per plane at most)")
    if unit == "board-top":
        spheres = opts.get("max_spheres") or UNIT_LIMITS["max_spheres"][unit][2]
        per = opts.get("tris_per_sphere") or UNIT_LIMITS["tris_per_sphere"][unit][2]
        if spheres * per > 1 << 20:
            raise g.UsageError(f"--max-spheres x --tris-per-sphere = {spheres * per} exceeds "
                               f"the address map ({1 << 20} list entries)")
    return opts


def _takes(unit: str) -> str:
    own = [o for o, pu in UNIT_LIMITS.items() if unit in pu]
    own += [o for o, (_, _, t) in CHOICE_OPTIONS.items() if unit in t]
    own += [o for o, t in FLAG_OPTIONS.items() if unit in t]
    if not own:
        return " (it takes no unit options)"
    return " (its options: " + ", ".join("--" + o.replace("_", "-") for o in own) + ")"


# compatibility: other modules and scripts imported these from here
def add_format_options(parser):
    g.add_format_option(parser, field_widths=True)


format_from_args = g.format_from_args


def add_parser(subparsers):
    from ..rtl.units import UNITS

    p = subparsers.add_parser(
        "verilog", help="emit a unit's Verilog (and a JSON manifest beside it)",
        description="Emit deterministic Verilog for one unit, and its JSON manifest (ports, "
                    "widths, latency, parameters) beside it with the extension .json.\n\n"
                    "Units:\n" + "\n".join(f"  {u.name:20s} {u.summary}"
                                          for u in UNITS.values()))
    p.add_argument("unit", type=g.choice(*UNITS, what="unit"), metavar="UNIT",
                   help=" | ".join(UNITS))
    g.add_format_option(p, field_widths=True)
    add_unit_options(p)
    p.add_argument("-o", "--output", required=True, metavar="FILE.v",
                   help="Verilog file to write (.v); the manifest goes beside it (.json)")
    return p


def check(args) -> None:
    args.fmt = g.format_from_args(args)
    args.options = unit_options(args, args.unit)
    out = g.check_output_file(args.output, (".v", ".sv"), "-o")
    g.check_output_file(out.with_suffix(".json"), (".json",), "manifest")


def run(args) -> int:
    from ..rtl.emit import write_unit
    from ..rtl.units import UNITS, build_unit

    fmt = args.fmt
    unit, comp, opts = build_unit(args.unit, fmt, **args.options)
    params = {"exp_bits": fmt.exp_bits, "man_bits": fmt.man_bits, "rounding": fmt.rounding,
              **opts}
    for opt in ("target", "adder"):   # the manifest always says which targets were built
        if opt in unit.options:
            params.setdefault(opt, UNITS[args.unit].options[opt][1])
    vpath, mpath = write_unit(comp, unit.module, params, args.output)
    print(f"wrote {vpath} ({unit.module}, latency {getattr(comp, 'latency', 'n/a')}) "
          f"and {mpath}", file=sys.stderr)
    return 0
