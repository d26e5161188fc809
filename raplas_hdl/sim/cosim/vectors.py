"""Vectors files of ``raplas-hdl cosim`` for the units past the FP ones: typed hex lines.

A file is plain text, one item per line, fields in hexadecimal separated by white space;
``#`` starts a comment. The first comment line that names a unit is the header::

    # plane-sphere e7m16-rtz rows=4 cols=4: P NX NY NZ P | S ID CX CY CZ R ROW_MASK COL_MASK

It names the unit, the format and the build parameters that change the expected results
(``rows``, ``cols``, ``mode``); a file whose header names another unit, format or
parameter value is refused (the message says which option to give). Each unit has one or
more line *kinds*: a kind with a tag starts with it (``P``, ``S``, ...), the untagged kind
(the ray-triangle unit's only one) has none. :func:`read_lines` checks the whole file
before anything runs: the kind, the number of fields, hex digits, and every value against
the width of its field. docs/cosim.md lists the kinds of every unit.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from raplas_hdl.fp import parse_format

__all__ = ["MAX_LINES", "UNIT_NAMES", "LineKind", "check_header", "columns_of", "hex_fields",
           "match_header", "read_lines", "text_lines", "write_lines"]

#: Most lines of one vectors file.
MAX_LINES = 10_000_000
#: The units whose name a header may give (longest first, for the pattern).
UNIT_NAMES = ("fp-add", "fp-mul", "plane-sphere-tester", "plane-sphere", "ray-triangle",
              "intersection-unit", "board-top")
_HEADER = re.compile(r"#\s*(" + "|".join(sorted(UNIT_NAMES, key=len, reverse=True))
                     + r")(?![\w-])(?:\s+([^\s:=]+))?((?:\s+[a-z_]+=[^\s:]+)*)\s*:")


@dataclass(frozen=True)
class LineKind:
    """One kind of line: its tag (None: untagged) and its fields ``(name, bits)``."""

    tag: str | None
    fields: tuple

    @property
    def names(self) -> str:
        return " ".join(n.upper() for n, _ in self.fields)


def text_lines(path) -> list[str]:
    """The lines of a text file; ValueError (one line) when it cannot be read or is not
    text."""
    try:
        fh = open(path, encoding="utf-8", errors="strict")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise ValueError(f"vectors file {str(path)!r} cannot be read "
                         f"({exc.strerror or exc})") from None
    with fh:
        try:
            return fh.readlines()
        except UnicodeDecodeError:
            raise ValueError(f"{path}: not a text file") from None


def match_header(text: str):
    """The header match of a (stripped) line, or None."""
    return _HEADER.match(text)


def check_header(path, lineno, m, unit, fmt=None, params=None) -> None:
    """Refuse a header (:func:`match_header`) naming another unit, format or parameter
    value than ``unit``, ``fmt`` and ``params`` (ValueError naming the option to give)."""
    params = params or {}
    if m.group(1) != unit:
        raise ValueError(f"{path}:{lineno}: the file holds {m.group(1)} vectors, not {unit}")
    if m.group(2) and fmt is not None:
        try:
            ffmt = parse_format(m.group(2))
        except ValueError:
            raise ValueError(f"{path}:{lineno}: the header names an unknown format "
                             f"{m.group(2)!r}") from None
        if ffmt != fmt:
            raise ValueError(f"{path}:{lineno}: the file holds {ffmt.name} vectors, not "
                             f"{fmt.name} (give --format {ffmt.name})")
    for item in m.group(3).split():
        key, _, value = item.partition("=")
        if key in params and str(params[key]) != value:
            raise ValueError(f"{path}:{lineno}: the file is for {key}={value}, not "
                             f"{key}={params[key]} (give --{key.replace('_', '-')} {value})")


def hex_fields(path, lineno, values, names) -> list[int]:
    """The hex numbers of one line (ValueError naming the line: not hex, or negative)."""
    try:
        ints = [int(v, 16) for v in values]
    except ValueError:
        raise ValueError(f"{path}:{lineno}: not a hex number in "
                         f"{' '.join(values)!r}") from None
    for name, v in zip(names, ints):
        if v < 0:
            raise ValueError(f"{path}:{lineno}: {name} is negative")
    return ints


def read_lines(path, unit: str, kinds, fmt=None, params=None) -> list:
    """Every item of a vectors file, checked: ``[(lineno, tag, [int, ...]), ...]``.

    Parameters
    ----------
    path : path
    unit : str
        The unit the file must be for (its header, when there is one).
    kinds : sequence of LineKind
    fmt : FPFormat, optional
        The format the header must name (when it names one).
    params : dict, optional
        Build parameters the header must agree with (those it names).

    Raises
    ------
    ValueError
        One line naming the file, the line and the problem.
    """
    params = params or {}
    by_tag = {k.tag: k for k in kinds}
    tags = [k.tag for k in kinds if k.tag is not None]
    items = []
    header_seen = False
    for lineno, line in enumerate(text_lines(path), 1):
        text = line.strip()
        if not header_seen:
            m = match_header(text)
            if m:
                header_seen = True
                check_header(path, lineno, m, unit, fmt, params)
                continue
        fields = text.split("#", 1)[0].split()
        if not fields:
            continue
        tag = fields[0].upper() if fields[0].upper() in by_tag else None
        if tag is None and None not in by_tag:
            raise ValueError(f"{path}:{lineno}: unknown line kind {fields[0]!r} for {unit} "
                             f"(lines start with {' or '.join(tags)})")
        kind = by_tag[tag]
        values = fields[1:] if tag is not None else fields
        if len(values) != len(kind.fields):
            what = f"{tag} line" if tag is not None else "line"
            raise ValueError(f"{path}:{lineno}: a {unit} {what} has {len(kind.fields)} hex "
                             f"fields ({kind.names}), not {len(values)}")
        ints = hex_fields(path, lineno, values, [n.upper() for n, _ in kind.fields])
        for (name, bits), v in zip(kind.fields, ints):
            if v >> bits:
                raise ValueError(f"{path}:{lineno}: {name.upper()} {v:#x} is wider than its "
                                 f"{bits} bits")
        items.append((lineno, tag, ints))
        if len(items) > MAX_LINES:
            raise ValueError(f"{path}: more than {MAX_LINES:,} lines")
    if not items:
        raise ValueError(f"{path}: no cases")
    return items


def columns_of(items, kind: LineKind) -> dict:
    """The values of the items of ``kind`` as ``{field: uint64 array}``."""
    rows = [v for _, t, v in items if t == kind.tag]
    arr = np.array(rows, dtype=np.uint64).reshape(len(rows), len(kind.fields))
    return {name: arr[:, k] for k, (name, _) in enumerate(kind.fields)}


def write_lines(path, unit: str, fmt, params: dict, kinds, blocks) -> None:
    """Write a vectors file: the header, then ``blocks``, each ``(kind, {field: array})``
    (the rows of one block are written together, in order)."""
    tag_text = " | ".join((f"{k.tag} " if k.tag else "") + k.names for k in kinds)
    extra = "".join(f" {k}={v}" for k, v in params.items())
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(f"# {unit} {fmt.name}{extra}: {tag_text} (hex)\n")
        for kind, cols in blocks:
            if not kind.fields:
                fh.write(f"{kind.tag}\n")
                continue
            arr = np.stack([np.asarray(cols[n], dtype=np.uint64) for n, _ in kind.fields],
                           axis=1)
            prefix = f"{kind.tag} " if kind.tag else ""
            fh.writelines(prefix + " ".join(f"{int(v):x}" for v in row) + "\n" for row in arr)
