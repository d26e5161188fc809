"""The one grammar of the ``raplas-hdl`` command line: shared options and checks.

Every subcommand builds its parser with the helpers here, so that the same thing is
spelled the same way everywhere and every bad value is found before any work:

- :func:`add_format_option`: ``--format FMT`` (``FP24``, ``FP24/rtz``, ``e7m16``,
  ``e7m16-rne``) and ``--rounding``; one format, or (``multiple=True``, the sweeps) a
  repeatable ``--format`` that also takes comma-separated lists.
  :func:`format_from_args` / :func:`formats_from_args` turn them into formats.
- :func:`int_range`, :func:`float_range`, :func:`choice`, :func:`size`, :func:`lattice`:
  argument types with stated limits (``MAX_IMAGE``, ``MAX_LATTICE``), checked while parsing.
- :func:`check_output_file`, :func:`check_output_dir`, :func:`check_input_file`: an output's
  directory exists and is writable, it is not an existing directory, its extension is the
  right one; an input exists and is a readable file.
- :func:`add_waves_option` / :func:`waves`: FST waveforms of every simulation of a command.
- :func:`add_out_option`: ``--out DIR`` for commands that write reports (default under
  ``build/``).
- :func:`reject`: an option given where it does not apply.

Errors are :class:`UsageError` (or ``ValueError``/``OSError`` from a check); ``main`` prints
them as one line ``raplas-hdl <command>: error: <message>`` and exits with 2. A command
module may define ``check(args)``: ``main`` calls it after parsing and before ``run``; it
validates everything and must not write anything.

To add an option to a command, add it in that command's ``add_parser`` with a type from
here (the limit then shows in ``--help`` and is enforced while parsing), and check
anything that depends on other options in its ``check``.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import sys
import tempfile
import time
from pathlib import Path

__all__ = [
    "MAX_IMAGE", "MAX_LATTICE", "UsageError", "Parser", "int_range", "float_range",
    "choice", "size", "lattice", "lattice_list", "add_format_option", "format_from_args",
    "formats_from_args", "format_names", "canonical_format", "roundings_of", "add_out_option",
    "add_waves_option", "waves", "fst_libs_missing", "check_output_file", "check_output_dir",
    "check_input_file", "check_distinct", "reject", "given", "one_line", "jsonable",
    "require_simulator", "plain",
]

#: Largest image side (``--size``, ``--mesh-size``): 8192 pixels.
MAX_IMAGE = 8192
#: Largest bundle or light lattice side (``--tile``, ``--shadow``, ``--bundles``, rows and
#: columns of the units): 64, the unit's own limit.
MAX_LATTICE = 64


class UsageError(Exception):
    """A bad command line or input: printed as one line, exit code 2."""

    def __init__(self, message: str, prog: str | None = None):
        super().__init__(message)
        self.prog = prog


def plain(text: str | None) -> str | None:
    """Help text without reStructuredText markup (double backticks, ``:mod:`` roles)."""
    if text is None:
        return None
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"\1", text)
    return text.replace("``", "")


class _Formatter(argparse.HelpFormatter):
    """Paragraphs are wrapped, indented lines (lists) kept; no breaks after hyphens
    (``fp-mul`` stays whole)."""

    def __init__(self, prog):
        super().__init__(prog, max_help_position=30)

    def _split_lines(self, text, width):
        import textwrap

        return textwrap.wrap(" ".join(text.split()), width, break_on_hyphens=False)

    def _fill_text(self, text, width, indent):
        import textwrap

        out = []
        for para in text.strip("\n").split("\n\n"):
            lines = para.split("\n")
            if any(ln.startswith(" ") for ln in lines):
                out.append("\n".join(indent + ln for ln in lines))
            else:
                out.append(textwrap.fill(" ".join(para.split()), width, initial_indent=indent,
                                         subsequent_indent=indent, break_on_hyphens=False))
        return "\n\n".join(out)


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are :class:`UsageError` (one line, exit 2) and
    that takes option names only in full (no abbreviations: ``--format`` never means
    ``--formats``)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        kwargs.setdefault("formatter_class", _Formatter)
        for key in ("description", "epilog"):
            if kwargs.get(key):
                kwargs[key] = plain(kwargs[key])
        super().__init__(*args, **kwargs)
        self.set_defaults(_prog=self.prog)

    def add_argument(self, *args, **kwargs):
        if "help" in kwargs and kwargs["help"] is not argparse.SUPPRESS:
            kwargs["help"] = plain(kwargs["help"])
        return super().add_argument(*args, **kwargs)

    def error(self, message):
        raise UsageError(message, self.prog)


def one_line(message) -> str:
    """``message`` as one line (line breaks become ``; ``)."""
    parts = [p.strip() for p in str(message).strip().splitlines() if p.strip()]
    return "; ".join(parts)


# -- argument types ---------------------------------------------------------------------

def int_range(lo: int | None = None, hi: int | None = None, name: str = "an integer"):
    """An ``int`` argument type accepting ``lo`` to ``hi`` (either may be None)."""

    def convert(text):
        try:
            value = int(str(text).strip(), 0)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            if hi is None:
                raise argparse.ArgumentTypeError(f"must be at least {lo}, not {value}")
            if lo is None:
                raise argparse.ArgumentTypeError(f"must be at most {hi}, not {value}")
            raise argparse.ArgumentTypeError(f"must be {lo} to {hi}, not {value}")
        return value

    convert.__name__ = name
    return convert


def float_range(lo: float | None = None, hi: float | None = None, lo_open: bool = False,
                hi_open: bool = False):
    """A finite ``float`` argument type in ``[lo, hi]`` (``(`` / ``)`` when open)."""

    def convert(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        bad = not math.isfinite(value)
        bad |= lo is not None and (value < lo or (lo_open and value == lo))
        bad |= hi is not None and (value > hi or (hi_open and value == hi))
        if bad:
            left = "any" if lo is None else f"{'(' if lo_open else '['}{lo:g}"
            right = "" if hi is None else f"{hi:g}{')' if hi_open else ']'}"
            where = f"in {left}, {right}" if hi is not None else (
                f"{'above' if lo_open else 'at least'} {lo:g}" if lo is not None else "finite")
            raise argparse.ArgumentTypeError(f"must be {where}, not {text}")
        return value

    convert.__name__ = "number"
    return convert


def choice(*choices, what: str = "value"):
    """A string argument type accepting one of ``choices``, with a message that names
    them (``target must be one of generic, virtex4, not 'xc7'``)."""

    def convert(text):
        if text not in choices:
            raise argparse.ArgumentTypeError(
                f"{what} must be one of {', '.join(choices)}, not {text!r}")
        return text

    convert.__name__ = what
    return convert


def _label(name, text) -> str:
    return f"{name} {text!r}" if name else repr(text)


def size(text: str, name: str | None = "size", limit: int = MAX_IMAGE) -> tuple[int, int]:
    """``WxH`` with 1 <= W, H <= ``limit``."""
    try:
        w, h = (int(x) for x in str(text).lower().split("x"))
    except ValueError:
        raise ValueError(f"{_label(name, text)} is not WxH (for example 128x96)") from None
    if not (1 <= w <= limit and 1 <= h <= limit):
        raise ValueError(f"{_label(name, text)}: width and height must be 1 to {limit}")
    return w, h


def lattice(text: str, name: str | None, allow_zero: bool = True,
            limit: int = MAX_LATTICE) -> tuple[int, int]:
    """``RxC`` with 1 <= R, C <= ``limit``; ``0``/``off``/``none`` give ``(0, 0)`` when
    ``allow_zero``."""
    if str(text).strip().lower() in ("0", "off", "none", "0x0"):
        if allow_zero:
            return 0, 0
        raise ValueError(f"{name or 'the lattice'} cannot be 0")
    try:
        r, c = (int(x) for x in str(text).lower().split("x"))
    except ValueError:
        raise ValueError(f"{_label(name, text)} is not RxC (for example 4x4)") from None
    if r < 1 or c < 1 or r > limit or c > limit:
        raise ValueError(f"{_label(name, text)}: rows and cols must be 1 to {limit}")
    return r, c


def lattice_list(text: str, name: str) -> list[tuple[int, int]]:
    """A comma-separated list of ``RxC`` (none of them 0)."""
    items = [x.strip() for x in str(text).split(",") if x.strip()]
    if not items:
        raise ValueError(f"{name} is empty")
    return [lattice(x, name, allow_zero=False) for x in items]


def _type(convert):
    """An argparse ``type`` from a function raising ValueError."""

    def wrapped(text):
        try:
            return convert(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    wrapped.__name__ = getattr(convert, "__name__", "value")
    return wrapped


def size_type(name: str = "--size"):
    """``WxH`` as an argparse type (argparse names the option in the message)."""
    return _type(lambda t: size(t, None))


def lattice_type(name: str, allow_zero: bool = True):
    """``RxC`` (or 0 when ``allow_zero``) as an argparse type."""
    return _type(lambda t: lattice(t, None, allow_zero))


# -- the format ---------------------------------------------------------------------------

_FORMAT_HELP = ("FP16, FP20, FP24, FP32 or eXmY (X exponent bits 2-11, Y fraction bits, "
                "1+X+Y at most 32), optionally with a rounding: FP24/rne, e7m16-chop")
_ROUNDINGS = ("rtz", "rne", "chop")


def _check_format_text(text: str, allow_all: bool = False) -> str:
    from ..fp import parse_format

    if allow_all and text.lower() == "all":
        return "all"
    parse_format(text)          # raises ValueError naming the text
    return text


class _OneFormat(argparse.Action):
    """``--format FMT``, at most once."""

    def __call__(self, parser, namespace, value, option_string=None):
        if getattr(namespace, self.dest, None) is not None:
            parser.error(f"{option_string} given twice: this command takes one format "
                         "(a sweep such as stress or bench takes several)")
        try:
            _check_format_text(value)
        except ValueError as exc:
            parser.error(f"argument {option_string}: {exc}")
        setattr(namespace, self.dest, value)


class _ListOption(argparse.Action):
    """A repeatable option whose values may also be comma-separated lists (``extend``)."""

    def __init__(self, *args, check=None, **kwargs):
        self.check = check
        super().__init__(*args, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        items = []
        for v in (values if isinstance(values, list) else [values]):
            items += [x.strip() for x in str(v).split(",") if x.strip()]
        if not items:
            parser.error(f"argument {option_string}: empty list")
        for item in items:
            if self.check is not None:
                try:
                    self.check(item)
                except ValueError as exc:
                    parser.error(f"argument {option_string}: {exc}")
        current = list(getattr(namespace, self.dest, None) or [])
        setattr(namespace, self.dest, current + items)


class _Reject(argparse.Action):
    """A hidden option that exists only to say what to write instead."""

    def __init__(self, *args, message="", **kwargs):
        self.message = message
        kwargs.setdefault("nargs", "?")
        kwargs["help"] = argparse.SUPPRESS
        super().__init__(*args, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        parser.error(f"{option_string}: {self.message}")


def _check_rounding(text: str) -> str:
    if text not in _ROUNDINGS and text != "all":
        raise ValueError(f"rounding must be one of {', '.join(_ROUNDINGS)}, not {text!r}")
    return text


def add_format_option(p, multiple: bool = False, default: str = "FP24/rtz",
                      field_widths: bool = False, plural: bool = False,
                      allow_all: bool = False, rounding_default: str = "rtz"):
    """Add ``--format`` and ``--rounding`` (the same on every command).

    Parameters
    ----------
    multiple : bool
        A sweep: ``--format`` is repeatable and takes comma lists (``--format FP16
        --format FP24/rne`` = ``--format FP16,FP24/rne``), and so is ``--rounding``
        (the roundings of formats given without one).
    default : str
        What the help states as the default.
    field_widths : bool
        Also accept the format as ``--exp-bits``/``--man-bits`` (instead of ``--format``).
    plural : bool
        Also accept ``--formats LIST`` and ``--roundings LIST`` (the spelling of the
        committed campaign and bench commands); otherwise ``--formats`` is an error that
        says what to write.
    allow_all : bool
        ``all`` stands for every preset (and every rounding).
    """
    g = p.add_argument_group("format")
    if multiple:
        g.add_argument("--format", dest="format", action=_ListOption, nargs="+",
                       default=None, metavar="FMT",
                       check=lambda t: _check_format_text(t, allow_all),
                       help=f"number format(s) to sweep: {_FORMAT_HELP}"
                            + ("; or all" if allow_all else "")
                            + f"; repeatable, or comma-separated (default {default})")
        g.add_argument("--rounding", dest="rounding", action=_ListOption, nargs="+",
                       default=None, metavar="R", check=_check_rounding,
                       help="roundings of the formats given without one: rtz, rne, chop"
                            + (" or all" if allow_all else "")
                            + f"; repeatable, or comma-separated (default {rounding_default})")
        if plural:
            g.add_argument("--formats", dest="format", action=_ListOption, metavar="LIST",
                           check=lambda t: _check_format_text(t, allow_all),
                           help="the same as --format with a comma-separated list")
            g.add_argument("--roundings", dest="rounding", action=_ListOption,
                           metavar="LIST", check=_check_rounding,
                           help="the same as --rounding with a comma-separated list")
        else:
            g.add_argument("--formats", action=_Reject,
                           message="not an option here; give the formats with --format FMT "
                                   "(repeatable, or a comma-separated list)")
    else:
        g.add_argument("--format", dest="format", action=_OneFormat, default=None,
                       metavar="FMT", help=f"number format: {_FORMAT_HELP} (default {default})")
        g.add_argument("--rounding", type=choice(*_ROUNDINGS, what="rounding"), default=None,
                       metavar="{rtz,rne,chop}",
                       help="rounding of a --format given without one (default rtz)")
        g.add_argument("--formats", action=_Reject,
                       message="this command takes one format: use --format FMT")
        if field_widths:
            g.add_argument("--exp-bits", type=int_range(name="exp-bits"), default=None,
                           metavar="E", help="the format as field widths instead of --format:"
                                             " exponent bits E, 2-11 (default 7)")
            g.add_argument("--man-bits", type=int_range(name="man-bits"), default=None,
                           metavar="M", help="fraction bits M, at least 1, 1+E+M at most 32 "
                                             "(default 16)")


def format_from_args(args):
    """The one :class:`~raplas_hdl.fp.FPFormat` of a command (``--format`` or the field
    widths, and ``--rounding``)."""
    from ..fp import FPFormat, parse_format

    text = getattr(args, "format", None)
    e, m = getattr(args, "exp_bits", None), getattr(args, "man_bits", None)
    if text is not None and (e is not None or m is not None):
        raise UsageError("give the format either as --format or as --exp-bits/--man-bits, "
                         "not both")
    if text is not None:
        return parse_format(text, args.rounding)
    try:
        return FPFormat(7 if e is None else e, 16 if m is None else m, args.rounding or "rtz")
    except ValueError as exc:
        raise UsageError(f"--exp-bits/--man-bits: {exc}") from None


_HAS_ROUNDING = re.compile(r"[/-](rtz|rne|chop)\s*$", re.I)


def canonical_format(name: str) -> str:
    """``name`` as ``FP24`` (no rounding) or ``FP24/rne`` (with one), ``E6M17`` for
    non-presets: the spelling the sweeps' specs expect (a rounding only after ``/``)."""
    from ..fp import parse_format

    fmt = parse_format(name)
    text = str(fmt)
    return text if _HAS_ROUNDING.search(name.strip()) else text.rsplit("/", 1)[0]


def format_names(args, default) -> list[str]:
    """The ``--format`` values of a sweep (``default`` when none), ``all`` expanded, in
    :func:`canonical_format` spelling."""
    from ..fp import PRESETS

    names = list(getattr(args, "format", None) or default)
    out = []
    for n in names:
        out += list(PRESETS) if n.lower() == "all" else [canonical_format(n)]
    return list(dict.fromkeys(out))


def roundings_of(args, default) -> list[str]:
    rs = list(getattr(args, "rounding", None) or default)
    out = []
    for r in rs:
        out += list(_ROUNDINGS) if r == "all" else [r]
    return list(dict.fromkeys(out))


def formats_from_args(args, default=("FP24",), default_roundings=("rtz",)):
    """The formats of a sweep: each ``--format`` with its own rounding, or with every
    ``--rounding`` when it names none."""
    from ..fp import parse_format

    out = []
    for name in format_names(args, default):
        if _HAS_ROUNDING.search(name):
            out.append(parse_format(name))
        else:
            out += [parse_format(name, r) for r in roundings_of(args, default_roundings)]
    return list(dict.fromkeys(out))


# -- outputs and inputs -------------------------------------------------------------------

def _probe_dir(d: Path, what: str) -> None:
    """Raise ValueError unless a file can be created in directory ``d``."""
    if not os.access(d, os.W_OK | os.X_OK):
        raise ValueError(f"{what}: cannot write to directory {str(d)!r} (permission denied)")
    try:
        fd, tmp = tempfile.mkstemp(prefix=".raplas-probe-", dir=d)
    except OSError as exc:
        raise ValueError(f"{what}: cannot write to directory {str(d)!r} "
                         f"({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(tmp)


def _existing_ancestor(p: Path, what: str) -> Path:
    """The nearest existing ancestor of ``p`` (which must be a directory)."""
    q = p
    while not q.exists():
        if q.parent == q:
            break
        q = q.parent
    if not q.is_dir():
        raise ValueError(f"{what}: {str(q)!r} is a file, not a directory")
    return q


def check_output_file(path, exts=(), what: str = "output", must_exist_dir: bool = True
                      ) -> Path:
    """Check that ``path`` can be written: the extension is one of ``exts`` (when given),
    it is not a directory, its directory exists (or, with ``must_exist_dir=False``, can be
    created) and is writable, an existing file there can be replaced. Writes nothing.

    Raises
    ------
    ValueError
        One line naming ``what``, the path and the problem.
    """
    if path is None or not str(path).strip():
        raise ValueError(f"{what}: empty file name")
    p = Path(path)
    label = f"{what} {str(path)!r}"
    if p.is_dir():
        raise ValueError(f"{label} is a directory")
    if exts and p.suffix.lower() not in exts:
        raise ValueError(f"{label}: the file name must end in {' or '.join(exts)}")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        anc = _existing_ancestor(parent, label)
        if must_exist_dir:
            raise ValueError(f"{label}: directory {str(parent)!r} does not exist")
        parent = anc
    _probe_dir(parent, label)
    if p.exists() and not os.access(p, os.W_OK):
        raise ValueError(f"{label}: the file exists and cannot be overwritten "
                         "(permission denied)")
    return p


def check_output_dir(path, what: str = "output directory") -> Path:
    """Check that directory ``path`` exists and is writable, or can be created (its
    nearest existing ancestor is a writable directory). Writes nothing."""
    if path is None or not str(path).strip():
        raise ValueError(f"{what}: empty directory name")
    p = Path(path)
    label = f"{what} {str(path)!r}"
    if p.exists():
        if not p.is_dir():
            raise ValueError(f"{label} is a file, not a directory")
        _probe_dir(p, label)
    else:
        _probe_dir(_existing_ancestor(p, label), label)
    return p


def check_input_file(path, what: str = "input", exts=()) -> Path:
    """Check that ``path`` is an existing, readable file (with one of ``exts``)."""
    p = Path(path)
    label = f"{what} {str(path)!r}"
    if not p.exists():
        raise ValueError(f"{label} does not exist")
    if p.is_dir():
        raise ValueError(f"{label} is a directory, not a file")
    if exts and p.suffix.lower() not in exts:
        raise ValueError(f"{label}: the file name must end in {' or '.join(exts)}")
    try:
        with open(p, "rb") as fh:
            fh.read(1)
    except OSError as exc:
        raise ValueError(f"{label} cannot be read ({exc.strerror or exc})") from None
    return p


def check_distinct(**paths) -> None:
    """No two of the named outputs are the same file."""
    seen = {}
    for opt, path in paths.items():
        if path is None:
            continue
        key = os.path.abspath(os.fspath(path))
        if key in seen:
            raise ValueError(f"{seen[key]} and {opt} name the same file {str(path)!r}")
        seen[key] = opt


# -- options that apply or not -------------------------------------------------------------

def given(args, *dests) -> list[str]:
    """The options among ``dests`` that were given (not None / False / empty)."""
    out = []
    for d in dests:
        v = getattr(args, d, None)
        if v is not None and v is not False and v != []:
            out.append("--" + d.replace("_", "-"))
    return out


def reject(args, dests, why: str) -> None:
    """Raise UsageError when any option of ``dests`` was given: ``--x does not apply
    <why>``."""
    opts = given(args, *dests)
    if opts:
        verb = "does" if len(opts) == 1 else "do"
        raise UsageError(f"{', '.join(opts)} {verb} not apply {why}")


# -- --out, --debug, --waves ------------------------------------------------------------

def add_out_option(p, default: str, what: str, aliases=()):
    """``--out DIR`` (default ``default``, under ``build/``)."""
    p.add_argument("--out", *aliases, dest="out", default=None, metavar="DIR",
                   help=f"{what} (default {default})")


def add_debug_option(p, top: bool = False):
    """``--debug``: show the traceback of an error (accepted before and after the
    command)."""
    p.add_argument("--debug", action="store_true",
                   default=False if top else argparse.SUPPRESS,
                   help="print the Python traceback of an error (default: one line)")


def add_waves_option(p, what: str = "every simulation"):
    """``--waves`` and ``--waves-dir``: record FST waveforms of the simulations."""
    g = p.add_argument_group("waveforms")
    g.add_argument("--waves", action="store_true",
                   help=f"record an FST waveform of {what} and print its path")
    g.add_argument("--waves-dir", default=None, metavar="DIR",
                   help="directory of the FST files (default build/waves/<command>; "
                        "needs --waves)")


def check_waves(args, simulator: str | None, applies: bool = True, why: str = "") -> None:
    """Check the waveform options: ``--waves-dir`` needs ``--waves``; ``--waves`` needs a
    simulation (``applies``) and, under Verilator, the lz4 library that FST needs."""
    if getattr(args, "waves_dir", None) is not None and not args.waves:
        raise UsageError("--waves-dir needs --waves")
    if not getattr(args, "waves", False):
        return
    if not applies:
        raise UsageError(f"--waves does not apply {why}")
    args.waves_dir = str(check_output_dir(
        args.waves_dir or os.path.join("build", "waves", args.command), "--waves-dir"))
    if simulator == "verilator":
        missing = fst_libs_missing()
        if missing:
            raise UsageError(f"--waves under Verilator writes FST, which needs {missing}: "
                             "install it with `apt-get install liblz4-dev`, or use "
                             "--sim icarus")


def fst_libs_missing() -> str | None:
    """What Verilator's FST writer lacks to compile and link (lz4), or None."""
    import shutil
    import subprocess

    cxx = shutil.which("g++") or shutil.which("c++")
    if cxx is None:
        return "a C++ compiler (g++)"
    try:
        hdr = subprocess.run([cxx, "-E", "-x", "c++", "-"], input="#include <lz4.h>\n",
                             capture_output=True, text=True, timeout=30)
        lib = subprocess.run([cxx, "-print-file-name=liblz4.so"], capture_output=True,
                             text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    if hdr.returncode != 0:
        return "the lz4 header lz4.h"
    if not os.path.isabs(lib.stdout.strip()):
        return "the lz4 library liblz4.so"
    return None


@contextlib.contextmanager
def waves(args):
    """Around a command's simulations: with ``--waves``, ask the simulation runner
    (:mod:`raplas_hdl.sim.build.runner`) for FST waveforms in ``args.waves_dir`` and print the
    path of every file written."""
    if not getattr(args, "waves", False):
        yield
        return
    d = Path(args.waves_dir)
    d.mkdir(parents=True, exist_ok=True)
    saved = {k: os.environ.get(k) for k in ("WAVES", "RAPLAS_WAVES_DIR")}
    os.environ["WAVES"] = "1"
    os.environ["RAPLAS_WAVES_DIR"] = str(d.resolve())
    t0 = time.time() - 1.0
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        files = sorted(f for f in d.glob("*.fst") if f.stat().st_mtime >= t0)
        if files:
            for f in files:
                print(f"waveform: {f}", file=sys.stderr)
        else:
            print(f"waveform: none written to {d}", file=sys.stderr)


# -- simulators -----------------------------------------------------------------------

def require_simulator(name: str) -> None:
    """UsageError (naming what to install) unless simulator ``name`` is installed."""
    from ..sim.build.runner import SimulatorNotFound
    from ..sim.build.runner import require_simulator as req

    try:
        req(name)
    except SimulatorNotFound as exc:
        raise UsageError(str(exc)) from None


# -- JSON --------------------------------------------------------------------------------

def jsonable(x):
    """``x`` with NumPy scalars as Python numbers and non-finite floats as strings."""
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    if hasattr(x, "item"):
        return jsonable(x.item())
    return x
