"""The ``raplas-hdl`` command line.

Each subcommand lives in its own module of this package with ``add_parser(subparsers)``
and ``run(args) -> int``. Modules import their heavy dependencies (Amaranth, cocotb,
numba) inside ``run`` so that ``raplas-hdl --help`` stays fast and a user of the model or
the renderer never needs a simulator.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .. import __version__

#: Subcommand modules, in the order ``--help`` lists them.
SUBCOMMANDS = ("demo", "verilog", "cosim", "render", "bench", "stress", "synth",
               "constraints")


def _load(name):
    try:
        return importlib.import_module(f"{__name__}.{name}")
    except ModuleNotFoundError as exc:
        if exc.name == f"{__name__}.{name}":
            return None
        raise


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="raplas-hdl",
        description="RAPLAS ray-tracing intersection accelerator: Verilog generation, "
                    "bit-exact golden model, co-simulation and rendering.")
    parser.add_argument("--version", action="version", version=f"raplas-hdl {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in SUBCOMMANDS:
        module = _load(name)
        if module is not None:
            p = module.add_parser(sub)
            p.set_defaults(_run=module.run)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except (ValueError, FileNotFoundError) as exc:
        print(f"raplas-hdl {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
