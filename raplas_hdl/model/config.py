"""The intersection unit's build parameters (:class:`UnitConfig`) and the names of its
counters: what every layer that builds, drives or models the unit agrees on first (the
memory image, the records, the reduction, the RTL and the host all start from here).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fp.format import FP24, FPFormat, check_format
from .certified import check_certified_format
from .modes import check_mode

__all__ = ["UnitConfig", "COUNTER_NAMES", "ADDRESS_INDEX_BITS", "check_int"]

#: Bits of the index field of the write port's address map (:mod:`.memory_image`): a
#: region holds at most ``2**ADDRESS_INDEX_BITS`` records, which bounds
#: ``max_spheres * tris_per_sphere`` (the triangle lists).
ADDRESS_INDEX_BITS = 23

#: Counters kept by the unit and by the model, in the order of the RTL's ``counters`` port.
#: ``cycles`` exists only in the RTL (the model has no clock).
COUNTER_NAMES = ("spheres", "plane_tests", "pairs_issued", "pairs_skipped", "hits",
                 "overflow", "underflow", "invalid")


def _bits_for(n: int) -> int:
    """Bits of an unsigned field holding the values 0 .. n-1 (at least 1)."""
    return max(1, (int(n) - 1).bit_length())


def check_int(name, value, lo, hi=None):
    """Raise ``ValueError`` naming ``name`` unless ``value`` is an integer in ``lo .. hi``."""
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool):
        raise ValueError(f"{name} must be an integer, not {value!r}")
    if value < lo or (hi is not None and value > hi):
        rng = f"at least {lo}" if hi is None else f"between {lo} and {hi}"
        raise ValueError(f"{name} must be {rng}, not {value}")


@dataclass(frozen=True)
class UnitConfig:
    """Build parameters of the intersection unit (and of its model).

    Parameters
    ----------
    fmt : FPFormat
        Arithmetic format of every unit and memory.
    rows, cols : int
        Bundle lattice, 1 to 64 each.
    testers : int or None
        Plane-sphere testers in the array (``None``: ``rows + cols``, one per plane).
    tris_per_sphere : int
        Largest triangle list of a sphere (1 to 4096).
    max_triangles, max_spheres : int
        Depths of Triangle Memory and Sphere Memory (1 to 2**20).
    mode : str
        Ray-triangle mode, ``"paper"``, ``"conservative"`` or ``"certified"`` (the result
        records carry the pair's ``outcome``, :data:`raplas_hdl.model.records.OUTCOME`;
        ``exp_bits <= 9``, ``margin_scale`` 1).
    margin_scale : int
        Scale of the conservative margin (the ray-triangle unit's parameter).
    fifo_depth : int
        Depth of the pair FIFO in front of the ray-triangle unit (3 to 1024: the record
        fetch holds one credit per entry, and a 2-entry buffered FIFO cannot take a write
        while its stored entry moves to its output register). Below 8 the credits' round
        trip limits the fetch to ``fifo_depth`` pairs per 8 cycles.
    lanes : int
        Ray-triangle units fed by the one plane-sphere array (1 to 8): pairs are dealt to
        them round-robin and their results merged back in the same order, so the result
        stream does not depend on it (``docs/intersection-unit.md``). In :meth:`params`
        only when not 1.
    reduce : bool
        On-chip reduction (:mod:`raplas_hdl.model.reduction`): the result stream carries
        one answer per ray (the nearest accepted hit, or the first blocking hit of an
        any-hit bundle) instead of one beat per pair. In :meth:`params` only when set.

    Raises
    ------
    ValueError
        Naming the parameter that is out of range.
    """

    fmt: FPFormat = FP24
    rows: int = 4
    cols: int = 4
    testers: int | None = None
    tris_per_sphere: int = 8
    max_triangles: int = 1024
    max_spheres: int = 256
    mode: str = "paper"
    margin_scale: int = 1
    fifo_depth: int = 16
    lanes: int = 1
    reduce: bool = False

    def __post_init__(self):
        check_format(self.fmt)
        check_int("rows", self.rows, 1, 64)
        check_int("cols", self.cols, 1, 64)
        if self.testers is not None:
            check_int("testers", self.testers, 1, 128)
        check_int("tris_per_sphere", self.tris_per_sphere, 1, 4096)
        check_int("max_triangles", self.max_triangles, 1, 1 << 20)
        check_int("max_spheres", self.max_spheres, 1, 1 << 20)
        check_mode(self.mode)
        check_int("margin_scale", self.margin_scale, 1)
        if self.mode == "certified":
            check_certified_format(self.fmt)
            if self.margin_scale != 1:
                raise ValueError(f"the certified unit takes margin_scale 1 only, not "
                                 f"{self.margin_scale}")
        check_int("fifo_depth", self.fifo_depth, 3, 1024)
        check_int("lanes", self.lanes, 1, 8)
        if not isinstance(self.reduce, (bool, np.bool_)):
            raise ValueError(f"reduce must be True or False, not {self.reduce!r}")
        if self.max_spheres * self.tris_per_sphere > 1 << ADDRESS_INDEX_BITS:
            raise ValueError("max_spheres * tris_per_sphere exceeds the address map "
                             f"({1 << ADDRESS_INDEX_BITS} list entries)")

    # -- derived ----------------------------------------------------------------------
    @property
    def n_testers(self) -> int:
        return self.rows + self.cols if self.testers is None else self.testers

    @property
    def n_planes(self) -> int:
        return self.rows + self.cols

    @property
    def n_rays(self) -> int:
        return self.rows * self.cols

    @property
    def ray_id_bits(self) -> int:
        return _bits_for(self.n_rays)

    @property
    def tri_id_bits(self) -> int:
        return _bits_for(self.max_triangles)

    @property
    def sphere_id_bits(self) -> int:
        return _bits_for(self.max_spheres)

    @property
    def count_bits(self) -> int:
        """Bits of a triangle count 0 .. tris_per_sphere."""
        return _bits_for(self.tris_per_sphere + 1)

    @property
    def run_count_bits(self) -> int:
        """Bits of a run's sphere count 0 .. max_spheres."""
        return _bits_for(self.max_spheres + 1)

    @classmethod
    def from_params(cls, params: dict) -> UnitConfig:
        """The configuration of :meth:`params` ``params`` (``testers`` as given there)."""
        p = dict(params)
        fmt = FPFormat(p.pop("exp_bits"), p.pop("man_bits"), p.pop("rounding"))
        return cls(fmt=fmt, **p)

    def params(self) -> dict:
        """JSON-serialisable parameters (for headers, manifests and reports)."""
        return {"exp_bits": self.fmt.exp_bits, "man_bits": self.fmt.man_bits,
                "rounding": self.fmt.rounding, "rows": self.rows, "cols": self.cols,
                "testers": self.n_testers, "tris_per_sphere": self.tris_per_sphere,
                "max_triangles": self.max_triangles, "max_spheres": self.max_spheres,
                "mode": self.mode, "margin_scale": self.margin_scale,
                "fifo_depth": self.fifo_depth,
                **({"lanes": self.lanes} if self.lanes != 1 else {}),
                **({"reduce": True} if self.reduce else {})}
