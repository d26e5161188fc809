"""The records that cross the units' boundaries, each defined once; every view derives from it.

A :class:`Record` is an ordered list of :class:`Field` (name, width, meaning), packed from
the low bits up in that order, exactly as an ``amaranth.lib.data.StructLayout`` packs its
fields. A width is a number of bits or the name of a build parameter (``"W"``, the format
width; ``"ray_id_bits"``; ...), so one record describes every build.
:meth:`Record.bind` fixes the parameters (from a
:class:`~raplas_hdl.model.config.UnitConfig`, an
:class:`~raplas_hdl.fp.format.FPFormat` or keywords) and gives a :class:`Layout`: field
offsets, and the packers of the testbenches and drivers. The views:

- :meth:`Record.dtype`: the NumPy structured dtype (one element per record; a vector field
  such as a ray origin is a ``(3,)`` sub-array); ``RESULT.dtype()`` is
  :data:`raplas_hdl.model.intersection.RESULT_DTYPE`;
- :meth:`Layout.pack` / :meth:`Layout.unpack` (Python integers, one per record) and
  :meth:`Layout.pack_words` / :meth:`Layout.unpack_words` (``uint64`` words, the low word
  first), vectorised with NumPy over the records;
- :meth:`Record.markdown` and :meth:`Layout.markdown`: documentation tables;
- the RTL's ``StructLayout`` (:func:`raplas_hdl.rtl.records.struct_layout`; this module never
  imports Amaranth).

The records (the parameters of their widths in brackets; :func:`unit_params` gives them
for a unit build):

- :data:`CMD`: the intersection unit's ``cmd`` stream, one run (``sphere_id_bits``,
  ``run_count_bits``);
- :data:`RESULT`: one beat of the intersection unit's ``o`` stream (``ray_id_bits``,
  ``tri_id_bits``, ``W``);
- :data:`ANSWER`: one beat of the result stream of a unit built with the on-chip reduction
  (``UnitConfig.reduce``): one answer per ray (``ray_id_bits``, ``tri_id_bits``, ``W``);
- in ``certified`` mode each of ``RT_RESULT``, ``RESULT`` and ``ANSWER`` carries one more
  field on top, :data:`OUTCOME` (2 bits), and ``RT_RESULT`` and ``RESULT`` one more above
  it, :data:`TIGHT` (1 bit): :data:`RT_RESULT_CERTIFIED`,
  :data:`RESULT_CERTIFIED`, :data:`ANSWER_CERTIFIED`; :func:`rt_result_record`,
  :func:`result_record`, :func:`answer_record` and :func:`output_record` pick a build's;
- :data:`COUNTERS`: the intersection unit's ``counters`` port (32 bits each);
- :data:`PAIR`: the ray-triangle unit's input, a :data:`RAY` and a :data:`TRIANGLE` with
  their IDs (``ray_id_bits``, ``tri_id_bits``, ``W``); :data:`RT_RESULT`: its output;
- :data:`PLANE`: a plane word of the plane-sphere array (``W``); :data:`SPHERE`: the
  array's input (``id_bits``, ``W``); :data:`PS_RESULT`: its output (``id_bits``,
  ``rows``, ``cols``).

No Amaranth.
"""

from __future__ import annotations

import keyword
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from ..fp.format import FPFormat
from .config import COUNTER_NAMES, UnitConfig

__all__ = ["Field", "Record", "Layout", "Slot", "unit_params", "words_to_ints",
           "ints_to_words", "PARAMETERS", "EVENT_COUNT_BITS", "RAY", "TRIANGLE", "PAIR",
           "RT_RESULT", "RESULT", "ANSWER", "OUTCOME", "OUTCOME_MISS", "OUTCOME_HIT",
           "OUTCOME_UNCERTAIN", "TIGHT", "RT_RESULT_CERTIFIED", "RESULT_CERTIFIED",
           "ANSWER_CERTIFIED", "rt_result_record", "result_record", "answer_record",
           "output_record", "CMD", "COUNTERS", "PLANE", "SPHERE", "PS_RESULT", "RECORDS"]

#: Width parameters a field may name, and what they are.
PARAMETERS = {
    "W": "width of the format's bit patterns, 1 + exp_bits + man_bits",
    "ray_id_bits": "bits of a ray ID (the unit: ceil(log2(rows*cols)))",
    "tri_id_bits": "bits of a triangle ID (the unit: ceil(log2(max_triangles)))",
    "sphere_id_bits": "bits of a sphere ID (ceil(log2(max_spheres)))",
    "run_count_bits": "bits of a run's sphere count 0 .. max_spheres",
    "id_bits": "bits of the plane-sphere array's sphere ID",
    "rows": "row planes of the bundle",
    "cols": "column planes of the bundle",
}

#: Width of the ray-triangle unit's per-pair event counts (up to 34 operations per pair).
EVENT_COUNT_BITS = 6

_STORAGE = ("u1", "u2", "u4", "u8")


def _fits(dtype: np.dtype) -> int:
    return 8 * np.dtype(dtype).itemsize


@dataclass(frozen=True)
class Field:
    """One field of a record.

    Parameters
    ----------
    name : str
        A Python identifier (the struct member, the dtype field, the dict key).
    width : int or str
        Bits (of each element, for a vector field), or a key of :data:`PARAMETERS`.
    meaning : str
        One line for the documentation tables.
    parts : tuple of str
        For a vector field, the names of its elements, the first in the low bits (``"xyz"``
        gives ``("x", "y", "z")``); empty for a scalar field.
    dtype : str, optional
        NumPy storage of one element (``u1`` .. ``u8``). Default: the smallest that holds a
        fixed width; ``u4`` for a parametric width.
    """

    name: str
    width: int | str
    meaning: str = ""
    parts: tuple = ()
    dtype: str | None = None

    def __post_init__(self):
        if not self.name.isidentifier() or keyword.iskeyword(self.name):
            raise ValueError(f"field name {self.name!r} is not an identifier")
        if isinstance(self.width, str):
            if self.width not in PARAMETERS:
                raise ValueError(f"field {self.name}: width {self.width!r} is not a parameter "
                                 f"({', '.join(PARAMETERS)})")
        elif not isinstance(self.width, int) or isinstance(self.width, bool) or \
                not 1 <= self.width <= 64:
            raise ValueError(f"field {self.name}: width must be 1 to 64 bits or a parameter "
                             f"name, not {self.width!r}")
        object.__setattr__(self, "parts", tuple(self.parts))
        if self.dtype is not None and self.dtype not in _STORAGE:
            raise ValueError(f"field {self.name}: dtype must be one of {', '.join(_STORAGE)}")

    @property
    def storage(self) -> np.dtype:
        """NumPy dtype of one element."""
        if self.dtype is not None:
            return np.dtype(self.dtype)
        if isinstance(self.width, str):
            return np.dtype("u4")
        return np.dtype(next(s for s in _STORAGE if _fits(s) >= self.width))

    @property
    def width_text(self) -> str:
        """The width as the docs show it (``"W"``, ``"3 x W"``, ``"1"``)."""
        w = str(self.width)
        return f"{len(self.parts)} x {w}" if self.parts else w

    def with_(self, **changes) -> Field:
        """A copy with some attributes changed (``field.with_(dtype="u8")``)."""
        return replace(self, **changes)


def _vec(name, meaning, width="W", parts="xyz"):
    return Field(name, width, meaning, tuple(parts))


@dataclass(frozen=True)
class Slot:
    """A field of a bound :class:`Layout`: its offset and width in bits."""

    name: str
    offset: int
    width: int          # of each element for a vector field
    parts: tuple
    storage: np.dtype
    meaning: str

    @property
    def size(self) -> int:
        return self.width * max(1, len(self.parts))

    def leaves(self):
        """``(element index or None, offset, width)`` of each element."""
        if not self.parts:
            yield None, self.offset, self.width
        else:
            for k in range(len(self.parts)):
                yield k, self.offset + k * self.width, self.width


class Record:
    """A record: named fields packed from the low bits up, in order.

    Parameters
    ----------
    name : str
    fields : sequence of Field
    doc : str
        One line: where the record travels.

    Raises
    ------
    ValueError
        On repeated field names.
    """

    def __init__(self, name: str, fields, doc: str = ""):
        self.name = name
        self.fields = tuple(fields)
        self.doc = doc
        names = [f.name for f in self.fields]
        if len(set(names)) != len(names):
            raise ValueError(f"record {name}: repeated field names in {names}")
        self.names = tuple(names)
        self.params = tuple(sorted({f.width for f in self.fields if isinstance(f.width, str)}))

    def __repr__(self):
        return f"Record({self.name!r}, {', '.join(self.names)})"

    def __iter__(self):
        return iter(self.fields)

    def __getitem__(self, name) -> Field:
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(f"record {self.name} has no field {name!r}")

    def dtype(self) -> np.dtype:
        """NumPy structured dtype: one element per record, the fields in order."""
        return np.dtype([(f.name, f.storage, (len(f.parts),)) if f.parts else
                         (f.name, f.storage) for f in self.fields])

    def bind(self, source=None, **params) -> Layout:
        """The layout of one build: every width resolved.

        Parameters
        ----------
        source : UnitConfig, FPFormat or mapping, optional
            A unit configuration (its :func:`unit_params`), a format (``W``), or a mapping
            of parameters.
        **params
            Parameters (override those of ``source``).

        Raises
        ------
        ValueError
            When a parameter the record needs is missing or a width is not positive. (A
            field wider than its NumPy storage is allowed here, for the RTL's layouts; the
            packers of such a layout raise.)
        """
        values = dict(_params_of(source))
        values.update(params)
        missing = [p for p in self.params if p not in values]
        if missing:
            raise ValueError(f"record {self.name} needs the parameter(s) {', '.join(missing)}")
        slots, offset = [], 0
        for f in self.fields:
            w = values[f.width] if isinstance(f.width, str) else f.width
            if not isinstance(w, (int, np.integer)) or isinstance(w, bool) or w < 1:
                raise ValueError(f"record {self.name}: field {f.name} width {w!r} (parameter "
                                 f"{f.width}) is not a positive integer")
            w = int(w)
            slot = Slot(f.name, offset, w, f.parts, f.storage, f.meaning)
            slots.append(slot)
            offset += slot.size
        return Layout(self, {p: int(values[p]) for p in self.params}, tuple(slots))

    def markdown(self) -> str:
        """Documentation table (Markdown) with symbolic widths."""
        lines = ["| Field | Width | Meaning |", "|---|---|---|"]
        for f in self.fields:
            parts = f" ({', '.join(f.parts)})" if f.parts else ""
            lines.append(f"| `{f.name}`{parts} | {f.width_text} | {f.meaning} |")
        return "\n".join(lines) + "\n"


def _params_of(source) -> dict:
    if source is None:
        return {}
    if isinstance(source, Mapping):
        return dict(source)
    if isinstance(source, UnitConfig):
        return unit_params(source)
    if isinstance(source, FPFormat):
        return {"W": source.width}
    raise ValueError(f"cannot take record parameters from {source!r}")


def unit_params(config) -> dict:
    """The width parameters of a :class:`~raplas_hdl.model.config.UnitConfig`."""
    return {"W": config.fmt.width, "ray_id_bits": config.ray_id_bits,
            "tri_id_bits": config.tri_id_bits, "sphere_id_bits": config.sphere_id_bits,
            "run_count_bits": config.run_count_bits, "rows": config.rows, "cols": config.cols}


_BYTE_ORDER = "little"


class Layout:
    """A :class:`Record` with its widths resolved: offsets and packers.

    Attributes
    ----------
    record : Record
    params : dict
        The parameters the record's widths needed.
    fields : tuple of Slot
        Name, offset, width (per element), parts, storage, meaning.
    size : int
        Bits of one packed record.
    n_words : int
        ``uint64`` words of one packed record.
    dtype : numpy.dtype
        ``record.dtype()``.
    """

    def __init__(self, record: Record, params: dict, fields: tuple):
        self.record = record
        self.params = params
        self.fields = fields
        self.size = sum(s.size for s in fields)
        self.n_words = max(1, -(-self.size // 64))
        self.dtype = record.dtype()
        self._too_wide = [f"{s.name} ({s.width} bits, stored as {s.storage})" for s in fields
                          if s.width > _fits(s.storage)]

    def _check_storage(self):
        if self._too_wide:
            raise ValueError(f"record {self.record.name}: field(s) wider than their NumPy "
                             f"storage: {', '.join(self._too_wide)}")

    def __repr__(self):
        return f"Layout({self.record.name!r}, {self.params}, {self.size} bits)"

    def __iter__(self):
        return iter(self.fields)

    def __getitem__(self, name) -> Slot:
        for s in self.fields:
            if s.name == name:
                return s
        raise KeyError(f"record {self.record.name} has no field {name!r}")

    def offsets(self) -> dict:
        """``{name: (offset, width)}`` of every element (``"o.x"`` for a vector field)."""
        out = {}
        for s in self.fields:
            for k, off, w in s.leaves():
                out[s.name if k is None else f"{s.name}.{s.parts[k]}"] = (off, w)
        return out

    # -- packing ------------------------------------------------------------------------------
    def _columns(self, values):
        """Per element ``(offset, width, uint64 column)`` and the batch shape."""
        self._check_storage()
        missing = []
        cols = []
        for s in self.fields:
            try:
                v = values[s.name]
            except (KeyError, ValueError, IndexError):
                missing.append(s.name)
                continue
            v = np.asarray(v)
            if v.dtype.kind == "b":
                v = v.astype(np.uint8)
            if v.dtype.kind not in "ui":
                raise ValueError(f"{self.record.name}.{s.name}: integer bit patterns expected, "
                                 f"not {v.dtype}")
            if s.parts:
                if v.ndim < 1 or v.shape[-1] != len(s.parts):
                    raise ValueError(f"{self.record.name}.{s.name}: last axis must have "
                                     f"{len(s.parts)} elements ({', '.join(s.parts)}), shape "
                                     f"{v.shape}")
            if v.size and v.dtype.kind == "i" and v.min() < 0:
                raise ValueError(f"{self.record.name}.{s.name}: negative value")
            cols.append((s, v))
        if missing:
            raise KeyError(f"record {self.record.name}: no value for {', '.join(missing)}")
        shape = np.broadcast_shapes(*[v.shape[:-1] if s.parts else v.shape for s, v in cols])
        n = int(np.prod(shape, dtype=np.int64))
        leaves = []
        for s, v in cols:
            full = np.broadcast_to(v, shape + ((len(s.parts),) if s.parts else ()))
            flat = full.reshape(n, -1).astype(np.uint64)
            for k, off, w in s.leaves():
                col = flat[:, 0 if k is None else k]
                if w < 64 and col.size and col.max() >> np.uint64(w):
                    raise ValueError(f"{self.record.name}.{s.name}: value does not fit in "
                                     f"{w} bits")
                leaves.append((off, w, col))
        return leaves, shape, n

    def pack_words(self, values) -> np.ndarray:
        """Records -> ``uint64`` words, shape ``batch + (n_words,)``, the low word first.

        ``values``: a structured array (of :attr:`dtype` or with its names), one element
        (``np.void``), or a mapping of field name to array; arrays broadcast together.
        Vector fields take their elements on the last axis.

        Raises
        ------
        KeyError
            When a field has no value.
        ValueError
            When a value is negative, not an integer, or wider than its field.
        """
        leaves, shape, n = self._columns(values)
        words = np.zeros((n, self.n_words), np.uint64)
        for off, w, col in leaves:
            k, s = divmod(off, 64)
            words[:, k] |= col << np.uint64(s)
            if s + w > 64:
                words[:, k + 1] |= col >> np.uint64(64 - s)
        return words.reshape(shape + (self.n_words,))

    def pack(self, values):
        """Records -> Python integers (a list; one integer for a single record)."""
        words = self.pack_words(values)
        ints = words_to_ints(words.reshape(-1, self.n_words))
        return ints[0] if words.ndim == 1 else ints

    def unpack_words(self, words) -> np.ndarray:
        """``uint64`` words (``batch + (n_words,)``) -> structured array of :attr:`dtype`."""
        self._check_storage()
        words = np.asarray(words)
        if words.ndim < 1 or words.shape[-1] != self.n_words:
            raise ValueError(f"record {self.record.name}: words must end in an axis of "
                             f"{self.n_words}, not shape {words.shape}")
        shape = words.shape[:-1]
        flat = words.reshape(-1, self.n_words).astype(np.uint64)
        out = np.zeros(flat.shape[0], self.dtype)
        for s in self.fields:
            for k, off, w in s.leaves():
                i, sh = divmod(off, 64)
                col = flat[:, i] >> np.uint64(sh)
                if sh + w > 64:
                    col |= flat[:, i + 1] << np.uint64(64 - sh)
                col &= np.uint64((1 << w) - 1)
                if k is None:
                    out[s.name] = col
                else:
                    out[s.name][:, k] = col
        return out.reshape(shape)

    def unpack(self, ints) -> np.ndarray:
        """Python integers (or one) -> structured array (0-d for one integer).

        Raises
        ------
        ValueError
            When an integer is negative or wider than :attr:`size` bits.
        """
        single = isinstance(ints, (int, np.integer))
        seq = [int(ints)] if single else [int(x) for x in ints]
        if any(x < 0 or x >> self.size for x in seq):
            raise ValueError(f"record {self.record.name}: value outside {self.size} bits")
        out = self.unpack_words(ints_to_words(seq, self.n_words))
        return out[0] if single else out

    def zeros(self, n: int) -> np.ndarray:
        return np.zeros(n, self.dtype)

    def markdown(self) -> str:
        """Documentation table (Markdown) with this build's bit positions."""
        lines = ["| Field | Bits | Width | Meaning |", "|---|---|---|---|"]
        for s in self.fields:
            parts = f" ({', '.join(s.parts)})" if s.parts else ""
            lo, hi = s.offset, s.offset + s.size - 1
            bits = f"{hi}:{lo}" if hi != lo else f"{lo}"
            width = f"{len(s.parts)} x {s.width}" if s.parts else f"{s.width}"
            lines.append(f"| `{s.name}`{parts} | {bits} | {width} | {s.meaning} |")
        return "\n".join(lines) + "\n"


def words_to_ints(words) -> list:
    """Rows of ``uint64`` words (the low word first) -> Python integers."""
    words = np.ascontiguousarray(np.asarray(words, np.uint64).astype("<u8"))
    if words.ndim == 1:
        words = words[:, None]
    nb = 8 * words.shape[1]
    raw = words.tobytes()
    return [int.from_bytes(raw[k * nb:(k + 1) * nb], _BYTE_ORDER)
            for k in range(words.shape[0])]


def ints_to_words(ints, n_words: int) -> np.ndarray:
    """Python integers -> ``uint64`` words, shape ``(n, n_words)``, the low word first."""
    nb = 8 * n_words
    ints = list(ints)
    try:
        raw = b"".join(int(x).to_bytes(nb, _BYTE_ORDER) for x in ints)
    except OverflowError:
        raise ValueError(f"an integer is negative or wider than {64 * n_words} bits") from None
    return np.frombuffer(raw, dtype="<u8").reshape(len(ints), n_words).astype(np.uint64)


# -- the records ----------------------------------------------------------------------------
#: A ray: Ray Memory's word (fields 0-5 of a ray in the write-port address map).
RAY = Record("ray", [
    _vec("o", "origin"),
    _vec("d", "direction (unit length)"),
], "a ray (Ray Memory word, ray-triangle input)")

#: A triangle: Triangle Memory's word (fields 0-11 of a triangle in the address map).
TRIANGLE = Record("triangle", [
    _vec("v0", "vertex V0"),
    _vec("e1", "edge E1 = V1 - V0"),
    _vec("e2", "edge E2 = V2 - V0"),
    _vec("n", "normal N = E1 x E2"),
], "a triangle (Triangle Memory word, ray-triangle input)")

_RT_IDS = (
    Field("ray_id", "ray_id_bits", "ray ID, carried through", dtype="u8"),
    Field("tri_id", "tri_id_bits", "triangle ID, carried through", dtype="u8"),
)

#: The ray-triangle unit's input: a (ray, triangle) pair with its IDs.
PAIR = Record("pair", _RT_IDS + RAY.fields + TRIANGLE.fields,
              "ray-triangle unit input stream (i)")

#: What the ray-triangle test decides about a pair (the prefix of both result records).
_OUTCOME = (
    Field("hit", 1, "the ray hits the triangle"),
    Field("t", "W", "t' = N.(V0 - O) (bit pattern)"),
    Field("u", "W", "u' = -(Q.E2)"),
    Field("v", "W", "v' = Q.E1"),
    Field("det", "W", "det = N.D"),
    Field("flags", 3, "OR of the pair's operation events: overflow 0, underflow 1, invalid 2"),
)

#: The ray-triangle unit's output.
RT_RESULT = Record("rt_result", _RT_IDS + _OUTCOME + tuple(
    Field(f"n_{ev}", EVENT_COUNT_BITS, f"operations of the pair that raised {ev}")
    for ev in ("overflow", "underflow", "invalid")), "ray-triangle unit output stream (o)")

#: One beat of the intersection unit's result stream.
RESULT = Record("result", (
    Field("ray_id", "ray_id_bits", "ray ID i*cols + j (0 on an empty beat)"),
    Field("tri_id", "tri_id_bits", "triangle ID"),
) + _OUTCOME + (
    Field("last", 1, "the run's last beat"),
    Field("empty", 1, "the run issued no pair: the only beat, every other field 0"),
), "intersection unit result stream (o)")

#: One beat of the reduced result stream (``UnitConfig.reduce``): the answer of one ray of
#: a run (:mod:`raplas_hdl.model.reduction`), the run's rays with an answer in ascending
#: order; a run without any answer gives one ``empty`` beat.
ANSWER = Record("answer", (
    Field("ray_id", "ray_id_bits", "ray ID i*cols + j (0 on an empty beat)"),
    Field("tri_id", "tri_id_bits", "the answer's triangle: the nearest accepted hit, or in an "
                                   "any-hit bundle the first accepted hit of the stream"),
    Field("t", "W", "its t' (bit pattern)"),
    Field("u", "W", "its u'"),
    Field("v", "W", "its v'"),
    Field("det", "W", "its det"),
    Field("flags", 3, "its pair's events (as RESULT's flags)"),
    Field("last", 1, "the run's last beat"),
    Field("empty", 1, "no ray of the run has an answer: the only beat, every other field 0"),
), "intersection unit result stream (o) with the on-chip reduction")

#: The certified mode's outcome of a pair (:mod:`raplas_hdl.model.certified`).
OUTCOME_MISS, OUTCOME_HIT, OUTCOME_UNCERTAIN = 0, 1, 2

#: The field a ``certified`` unit adds on top of its result records (``hit`` is then
#: ``outcome == 1``). In ``RT_RESULT`` and ``RESULT``: the pair's outcome; in ``ANSWER``:
#: what the beat is (1 a ray's answer, a certain hit; 2 an uncertain pair sent on to the host;
#: 0 the ``empty`` beat).
OUTCOME = Field("outcome", 2, "certified mode: 0 miss, 1 certain hit, 2 uncertain "
                              "(hit = outcome == 1)")


#: The field a certified pair carries above its outcome
#: (:mod:`raplas_hdl.model.ordering`): a certain hit whose ``t'`` and ``det`` are within a
#: relative ``2**-tight_bits(fmt)`` of R's, so that the reducer may order it.
TIGHT = Field("tight", 1, "certified mode: a certain hit whose t' and det are within "
                          "2**-tight_bits of R's (model/ordering.py); 0 otherwise")


def _with_outcome(record: Record, name: str, meaning: str, tight: bool = False) -> Record:
    return Record(name, record.fields + (OUTCOME.with_(meaning=meaning),)
                  + ((TIGHT,) if tight else ()), record.doc + ", certified mode")


#: The certified ray-triangle unit's output (``RayTriangleUnit(mode="certified")``).
RT_RESULT_CERTIFIED = _with_outcome(RT_RESULT, "rt_result_certified", OUTCOME.meaning, True)
#: One beat of a certified intersection unit's result stream.
RESULT_CERTIFIED = _with_outcome(RESULT, "result_certified", OUTCOME.meaning, True)
#: One beat of a certified unit's reduced stream: a run's uncertain pairs (``outcome`` 2, in
#: stream order), then its answers (``outcome`` 1, ascending rays), or, when it has no
#: answer, one ``empty`` beat (``outcome`` 0) after its uncertain pairs
#: (:mod:`raplas_hdl.model.reduction`).
ANSWER_CERTIFIED = _with_outcome(ANSWER, "answer_certified",
                                 "1: the ray's answer (a certain hit); 2: an uncertain pair "
                                 "for the host (before the run's answers); 0: empty beat")


def _certified(config) -> bool:
    return getattr(config, "mode", "paper") == "certified"


def rt_result_record(config) -> Record:
    """The ray-triangle unit's output record in ``config``'s mode."""
    return RT_RESULT_CERTIFIED if _certified(config) else RT_RESULT


def result_record(config) -> Record:
    """The unreduced result stream's record in ``config``'s mode."""
    return RESULT_CERTIFIED if _certified(config) else RESULT


def answer_record(config) -> Record:
    """The reduced stream's record in ``config``'s mode."""
    return ANSWER_CERTIFIED if _certified(config) else ANSWER


def output_record(config) -> Record:
    """The record of the intersection unit's ``o`` stream: :func:`answer_record` for a unit
    built with the on-chip reduction (``config.reduce``), else :func:`result_record` (each
    with :data:`OUTCOME` in ``certified`` mode)."""
    return answer_record(config) if getattr(config, "reduce", False) else \
        result_record(config)


#: The intersection unit's run command.
CMD = Record("cmd", [
    Field("first", "sphere_id_bits", "first sphere ID, or run-list position when indirect"),
    Field("count", "run_count_bits", "spheres in the run (0 allowed)"),
    Field("bank", 1, "bundle bank (Plane Memory, Ray Memory, run list)"),
    Field("indirect", 1, "the spheres come from the bank's run list"),
    Field("keep_all", 1, "no culling: every sphere of the run passes the plane test (row and "
                         "column masks all ones), for a bundle over the culling budget"),
], "intersection unit command stream (cmd)")

_COUNTER_MEANINGS = {
    "cycles": "cycles while a run is outstanding",
    "spheres": "spheres tested",
    "plane_tests": "plane-sphere tests (rows + cols per sphere)",
    "pairs_issued": "pairs sent to the ray-triangle unit",
    "pairs_skipped": "pairs not issued (disabled rays)",
    "hits": "hits",
    "overflow": "operations that raised overflow, over the issued pairs",
    "underflow": "operations that raised underflow, over the issued pairs",
    "invalid": "operations that raised invalid, over the issued pairs",
}


def _counters():
    names = ("cycles",) + tuple(COUNTER_NAMES)
    return Record("counters", [Field(n, 32, _COUNTER_MEANINGS[n]) for n in names],
                  "intersection unit counters (32 bits each, wrap around)")


#: The intersection unit's counters: ``cycles`` and
#: :data:`~raplas_hdl.model.config.COUNTER_NAMES`.
COUNTERS = _counters()

#: A plane: the plane-sphere array's plane word (``n.x + p = 0``), and Plane Memory's.
PLANE = Record("plane", [
    Field("nx", "W", "normal x"), Field("ny", "W", "normal y"), Field("nz", "W", "normal z"),
    Field("p", "W", "offset p"),
], "plane-sphere array plane word (pw_data)")

#: The plane-sphere array's input.
SPHERE = Record("sphere", [
    Field("id", "id_bits", "sphere ID, carried through", dtype="u8"),
    _vec("c", "centre"),
    Field("r", "W", "inflated radius r'"),
], "plane-sphere array input stream (i)")

#: The plane-sphere array's output.
PS_RESULT = Record("ps_result", [
    Field("id", "id_bits", "sphere ID", dtype="u8"),
    Field("row_mask", "rows", "bit i: row plane i keeps the sphere", dtype="u8"),
    Field("col_mask", "cols", "bit j: column plane j keeps the sphere", dtype="u8"),
], "plane-sphere array output stream (o)")

#: Every record, by name.
RECORDS = {r.name: r for r in (CMD, RESULT, ANSWER, COUNTERS, PAIR, RT_RESULT, RAY, TRIANGLE,
                               PLANE, SPHERE, PS_RESULT, RT_RESULT_CERTIFIED, RESULT_CERTIFIED,
                               ANSWER_CERTIFIED)}
