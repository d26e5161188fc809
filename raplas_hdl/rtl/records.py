"""Amaranth views of the records of :mod:`raplas_hdl.model.records`.

:func:`struct_layout` turns a record (bound to a build's parameters) into the
``amaranth.lib.data.StructLayout`` of the ports that carry it: the same fields, in the same
order, from the low bits up, so the RTL, the NumPy dtypes and the testbenches' packers
cannot drift apart. A vector field (``parts``) becomes a nested layout of its elements.
"""

from __future__ import annotations

from amaranth.lib import data

from ..model.records import Layout, Record

__all__ = ["struct_layout"]


def struct_layout(record: Record | Layout, source=None, **params) -> data.StructLayout:
    """The ``StructLayout`` of ``record`` for a build.

    Parameters
    ----------
    record : Record or Layout
        A record (bound here with ``source`` and ``params``, see :meth:`Record.bind`) or an
        already bound layout.
    source : UnitConfig, FPFormat or mapping, optional
    **params
        Width parameters.

    Raises
    ------
    ValueError
        When a parameter is missing (see :meth:`Record.bind`).
    """
    if isinstance(record, Record):
        layout = record.bind(source, **params)
    elif isinstance(record, Layout):
        if source is not None or params:
            raise ValueError("a bound Layout takes no further parameters")
        layout = record
    else:
        raise ValueError(f"record must be a Record or a Layout, not {record!r}")
    members = {}
    for s in layout.fields:
        members[s.name] = (data.StructLayout({p: s.width for p in s.parts}) if s.parts
                           else s.width)
    out = data.StructLayout(members)
    assert out.size == layout.size
    return out
