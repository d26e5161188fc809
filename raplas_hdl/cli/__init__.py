"""The ``raplas-hdl`` command line.

Each subcommand lives in its own module of this package (``board-sim`` in ``board_sim``)
with ``add_parser(subparsers)``, an optional ``check(args)`` and ``run(args) -> int``. The shared options and checks (the
format, output paths, size limits, ``--waves``, ``--debug``) are in :mod:`.grammar`.

``main`` parses, calls ``check`` (which validates every value, path and size and writes
nothing), then ``run``. A bad command line or input, an ``OSError`` or a ``ValueError`` is
printed as one line ``raplas-hdl <command>: error: <message>`` with exit code 2; any other
failure as one line with exit code 1. ``--debug`` adds the traceback.

Modules import their heavy dependencies (Amaranth, cocotb, numba) inside ``run`` so that
``raplas-hdl --help`` stays fast and a user of the model or the renderer never needs a
simulator.
"""

from __future__ import annotations

import importlib
import sys
import traceback

from .. import __version__
from .grammar import Parser, UsageError, add_debug_option, one_line

#: Subcommand modules, in the order ``--help`` lists them.
SUBCOMMANDS = ("demo", "verilog", "cosim", "render", "bench", "stress", "synth",
               "constraints", "fusesoc", "pnr", "bitstream", "prove", "board-sim")


def _load(name):
    module = f"{__name__}.{name.replace('-', '_')}"     # board-sim: cli/board_sim.py
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name == module:
            return None
        raise


def build_parser() -> Parser:
    parser = Parser(
        prog="raplas-hdl",
        description="RAPLAS ray-tracing intersection accelerator: Verilog generation, "
                    "bit-exact golden model, co-simulation, rendering, place and route "
                    "and proofs.",
        epilog="Every command takes the format as --format FMT (FP24, FP24/rtz, e7m16, "
               "e7m16-rne); sweeps take several. Errors are one line with exit code 2; "
               "--debug shows the traceback.")
    parser.add_argument("--version", action="version", version=f"raplas-hdl {__version__}")
    add_debug_option(parser, top=True)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in SUBCOMMANDS:
        module = _load(name)
        if module is not None:
            p = module.add_parser(sub)
            p.set_defaults(_run=module.run, _check=getattr(module, "check", None))
            _add_debug_everywhere(p)
    return parser


def _add_debug_everywhere(p) -> None:
    """``--debug`` on ``p`` and on every parser nested under it (``stress campaign``)."""
    import argparse

    add_debug_option(p)
    for action in p._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in dict.fromkeys(action.choices.values()):
                _add_debug_everywhere(child)


def _message(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror and exc.filename is not None:
        target = exc.filename if exc.filename2 is None else f"{exc.filename} -> {exc.filename2}"
        return f"{target}: {exc.strerror}"
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return one_line(exc) or type(exc).__name__


def main(argv=None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    prog = "raplas-hdl"
    try:
        parser = build_parser()
        args, extra = parser.parse_known_args(argv)
        prog = getattr(args, "_prog", prog)
        debug = bool(getattr(args, "debug", debug))
        if extra:
            raise UsageError(f"unrecognized argument(s): {' '.join(extra)} "
                             f"(see {prog} --help)", prog)
        if args._check is not None:
            args._check(args)
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        if debug:
            traceback.print_exc()
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 (the one place that turns errors into a line)
        if debug:
            traceback.print_exc()
        if isinstance(exc, (UsageError, ValueError, OSError)) or type(exc).__name__ in (
                "SimulatorNotFound", "BackendUnavailable"):
            where = getattr(exc, "prog", None) or prog
            print(f"{where}: error: {_message(exc)}", file=sys.stderr)
            return 2
        # a failure, not a bad input: the first line (it names the log to read)
        kind = "" if isinstance(exc, (RuntimeError, AssertionError)) else \
            f"{type(exc).__name__}: "
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"{prog}: failed: {kind}{first}"
              + ("" if debug else " (--debug shows the traceback)"), file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
