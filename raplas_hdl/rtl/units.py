"""Registry of the units that ``raplas-hdl verilog`` can emit.

Each entry builds a component from keyword parameters; the format arrives as an
:class:`~raplas_hdl.fp.FPFormat`. Builders import their unit lazily, so emitting one unit
never needs the others' modules.

The option ``target`` (``generic`` or ``virtex4``, every unit with an FP multiplier, and
``fp-add``) reaches the builder as its ``multiplier`` keyword: ``virtex4`` builds the
significand multiplies from Virtex-4 ``DSP48`` primitives (:mod:`raplas_hdl.rtl.dsp48`); for
``fp-add`` it is the adder's own target (:class:`~.fp_add.FPAdd` takes ``multiplier=`` as
another name for ``target``): two ``DSP48`` per adder (:mod:`raplas_hdl.rtl.fp_add_dsp48`).
The option ``adder`` (``generic`` or ``virtex4``, every unit built from FP adders and
multipliers) chooses the same for all of the unit's :class:`~.fp_add.FPAdd`, independently
of ``target``: ``--target virtex4 --adder virtex4`` puts both kinds of operation in DSP48.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path

from ..fp import FP24, FPFormat
from .emit import write_unit

__all__ = ["Unit", "UNITS", "build_unit", "emit_all", "TARGET_OPTION", "ADDER_OPTION"]

#: The ``target`` option of the units with FP multipliers (``--target`` on the CLI).
TARGET_OPTION = {"target": (str, "generic", "multiplier target: generic | virtex4 "
                                            "(DSP48 primitives)")}

#: The ``adder`` option of the units built from FP adders and multipliers (``--adder``).
ADDER_OPTION = {"adder": (str, "generic", "FP adder target: generic | virtex4 "
                                          "(two DSP48 per adder)")}

#: Values of the ``target`` option (the ``multiplier`` of :class:`~.fp_mul.FPMul`).
TARGETS = ("generic", "virtex4")

#: Options whose builder keyword has another name.
_KEYWORDS = {"target": "multiplier"}


@dataclass(frozen=True)
class Unit:
    name: str
    module: str         # Verilog module name
    summary: str
    builder: str        # "python.module:callable", called as callable(fmt, **options)
    options: dict = field(default_factory=dict)   # option -> (type, default, help)

    def build(self, fmt: FPFormat, **options):
        modname, _, attr = self.builder.partition(":")
        factory = getattr(importlib.import_module(modname), attr)
        return factory(fmt, **{_KEYWORDS.get(k, k): v for k, v in options.items()})


UNITS = {u.name: u for u in [
    Unit("fp-add", "fp_add", "pipelined FP adder/subtractor",
         "raplas_hdl.rtl.fp_add:FPAdd", {"stages": (int, None, "pipeline stages (default: "
                                                    "6, 7 in rne, 5 in chop)"),
                                         "target": (str, "generic", "adder target: generic "
                                                    "| virtex4 (two DSP48)")}),
    Unit("fp-mul", "fp_mul", "pipelined FP multiplier (one (M+1)x(M+1) multiply)",
         "raplas_hdl.rtl.fp_mul:FPMul", {"stages": (int, None, "pipeline stages (default: "
                                                    "4, 5 in rne)"),
                                         **TARGET_OPTION}),
    Unit("fp-le", "fp_le", "the contract's ordered a <= b, registered",
         "raplas_hdl.rtl.fp_compare:build_fp_le"),
    Unit("fp-lt", "fp_lt", "the contract's ordered a < b, registered",
         "raplas_hdl.rtl.fp_compare:build_fp_lt"),
    Unit("fp-neg", "fp_neg", "the contract's neg(a), registered",
         "raplas_hdl.rtl.fp_compare:FPNeg"),
    Unit("plane-sphere-tester", "plane_sphere_tester", "one plane-sphere tester",
         "raplas_hdl.rtl.plane_sphere:PlaneSphereTester", {**TARGET_OPTION, **ADDER_OPTION}),
    Unit("plane-sphere", "plane_sphere", "plane-sphere tester array with decoder",
         "raplas_hdl.rtl.plane_sphere:build_plane_sphere",
         {"rows": (int, 4, "bundle rows"), "cols": (int, 4, "bundle columns"),
          "testers": (int, None, "testers in the array (default rows+cols)"),
          **TARGET_OPTION, **ADDER_OPTION}),
    Unit("ray-triangle", "ray_triangle", "division-free Moller-Trumbore unit",
         "raplas_hdl.rtl.ray_triangle:RayTriangleUnit",
         {"mode": (str, "paper", "paper | conservative | certified"), **TARGET_OPTION,
          **ADDER_OPTION}),
    Unit("intersection-unit", "intersection_unit", "the whole intersection unit",
         "raplas_hdl.rtl.intersection:build_intersection_unit",
         {"rows": (int, 4, "bundle rows"), "cols": (int, 4, "bundle columns"),
          "testers": (int, None, "plane-sphere testers (default rows+cols)"),
          "tris_per_sphere": (int, 8, "triangles per bounding sphere"),
          "mode": (str, "paper", "paper | conservative"),
          "lanes": (int, 1, "ray-triangle lanes behind the culling array"),
          "reduce": (bool, False, "on-chip reduction: one answer per ray leaves the unit"),
          **TARGET_OPTION, **ADDER_OPTION}),
    Unit("board-top", "board_top", "the intersection unit behind a 32-bit Wishbone slave",
         "raplas_hdl.rtl.board_top:build_board_top",
         {"rows": (int, 4, "bundle rows"), "cols": (int, 4, "bundle columns"),
          "testers": (int, None, "plane-sphere testers (default rows+cols)"),
          "tris_per_sphere": (int, 8, "triangles per bounding sphere"),
          "max_triangles": (int, 1024, "Triangle Memory depth"),
          "max_spheres": (int, 256, "Sphere Memory depth"),
          "fifo_depth": (int, 16, "pair FIFO depth"),
          "mode": (str, "paper", "paper | conservative | certified"),
          "reduce": (bool, False, "on-chip reduction: the result window holds answers"),
          **TARGET_OPTION, **ADDER_OPTION}),
]}


def build_unit(name: str, fmt: FPFormat = FP24, **options):
    """Build unit ``name``; options left at ``None`` take the unit's default.

    Returns ``(unit, component, options)``, ``options`` being the ones given (``None``
    dropped).
    """
    try:
        unit = UNITS[name]
    except KeyError:
        raise ValueError(f"unknown unit {name!r}; known units: {', '.join(UNITS)}") from None
    unknown = set(options) - set(unit.options)
    if unknown:
        raise ValueError(f"unit {name} takes no option(s) {', '.join(sorted(unknown))}")
    opts = {k: v for k, v in options.items() if v is not None}
    for opt in ("target", "adder"):
        if opt in opts and opts[opt] not in TARGETS:
            raise ValueError(f"{opt} must be one of {', '.join(TARGETS)}, not {opts[opt]!r}")
    return unit, unit.build(fmt, **opts), opts


def emit_all(outdir, fmt: FPFormat = FP24, names=None) -> list[Path]:
    """Emit every registered unit (or ``names``) at their defaults into ``outdir``."""
    written = []
    for name in names or UNITS:
        unit, comp, opts = build_unit(name, fmt)
        params = {"exp_bits": fmt.exp_bits, "man_bits": fmt.man_bits,
                  "rounding": fmt.rounding, **opts}
        path, _ = write_unit(comp, unit.module, params, Path(outdir) / f"{unit.module}.v")
        written.append(path)
    return written
