"""Register map of the board-level top (:class:`raplas_hdl.rtl.board_top.BoardTop`).

One source for the RTL, the host driver (:mod:`raplas_hdl.link.driver`) and the
documentation (``docs/board-top.md``, whose table a test compares with
:data:`REGISTER_MAP`). No Amaranth.

The top is a 32-bit Wishbone B4 classic slave with 32-bit granularity: ``wb_adr`` is a
*word* address (byte address = 4 x ``wb_adr``), ``wb_sel`` is accepted and ignored (every
access is a whole word). The registers:

- **identification and configuration** (read only): :data:`BOARD_ID`, the map's version,
  and the build parameters (format, lattice, testers, depths), so that a driver can check
  it talks to the build it expects (:func:`config_words`, :func:`config_from_words`);
- **memory window**: ``MEM_ADDR`` holds an address of the unit's write port (the map of
  :mod:`raplas_hdl.model.memory_image`); each write to ``MEM_DATA`` writes that word into
  the unit and adds 1 to ``MEM_ADDR``, so a record's consecutive fields need one
  ``MEM_ADDR`` write;
- **command**: ``CMD_FIRST`` then ``CMD_START`` (:func:`cmd_start_word`: count, bank,
  indirect and keep_all, the record :data:`CMD_START_WORD`) queue a run in a one-deep
  slot; a ``CMD_START`` write while the slot is full is refused (``wb_err``, sticky
  ``cmd_overrun``), so a driver waits for ``STATUS.cmd_full`` = 0;
- **status and control**: ``STATUS`` (:data:`STATUS_BITS`) and ``CONTROL``
  (:data:`CONTROL_BITS`);
- **result window**: a read of ``RES_INFO`` pops the head beat of the unit's result stream
  into a latch and returns its flags with ``valid`` = 1, or returns 0 (nothing popped)
  when no beat is waiting; ``RES_IDS``, ``RES_T``, ``RES_U``, ``RES_V``, ``RES_DET`` then
  read the latched beat (words: the records :data:`RES_INFO_WORD`, :data:`RES_IDS_WORD`;
  :func:`result_beats` turns them into result beats). The unit stalls while the host does
  not pop (its stream's back-pressure), so nothing is dropped however slow the host is;
- **counters**: the unit's nine 32-bit counters, one word each (wrap around, zeroed by
  ``CONTROL.clear_counters``).

Unmapped addresses answer ``wb_err``; writes to read-only registers are acknowledged and
ignored; reads of write-only registers return 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .records import COUNTERS, RESULT, RESULT_CERTIFIED, Field, Record, output_record

__all__ = ["Register", "REGISTER_MAP", "REGISTERS", "ADDR_BITS", "BOARD_ID", "MAP_VERSION",
           "STATUS_BITS", "CONTROL_BITS", "RES_INFO_BITS", "RESULT_REGS", "COUNTER_REGS",
           "ROUNDING_CODES", "MODE_CODES", "config_words", "config_from_words",
           "cmd_start_word", "decode_cmd_start", "res_info_word", "res_ids_word",
           "decode_result_words", "result_beats", "markdown_table", "parse_markdown_table",
           "CMD_START_WORD", "RES_INFO_WORD", "RES_IDS_WORD", "CMD_KEEP_ALL_BIT"]

#: Width of ``wb_adr`` (word address).
ADDR_BITS = 8
#: Value of the ``ID`` register: ASCII "RPLS".
BOARD_ID = 0x52504C53
#: Register-map version (major, minor), read as ``major << 16 | minor``. 1.1 added the
#: ``keep_all`` bit of ``CMD_START``; 1.2 the certified mode (``outcome`` and ``tight`` in
#: ``RES_INFO``), the on-chip reduction (``reduce`` in ``CFG_FORMAT``: the result window then
#: holds answers) and ``lanes`` in ``CFG_LATTICE``.
MAP_VERSION = (1, 2)

ROUNDING_CODES = {"rtz": 0, "rne": 1, "chop": 2}
MODE_CODES = {"paper": 0, "conservative": 1, "certified": 2}

#: Bits of ``STATUS``.
STATUS_BITS = {"busy": 0, "result_valid": 1, "fifo_overflow": 2, "cmd_full": 3,
               "cmd_overrun": 4}
#: Bits of ``CONTROL`` (write 1 to act; writes of 0 do nothing).
CONTROL_BITS = {"clear_counters": 0, "clear_overrun": 1}

# -- the words of the command and result registers (records: fields from bit 0 up) ----------
#: ``CMD_START``: the fields of the unit's run command but ``first`` (``CMD_FIRST``).
CMD_START_WORD = Record("cmd_start", [
    Field("count", 24, "spheres in the run"),
    Field("bank", 1, "bundle bank"),
    Field("indirect", 1, "the spheres come from the bank's run list"),
    Field("keep_all", 1, "cull nothing (the command's keep_all bit)"),
], "CMD_START register")
#: ``RES_INFO``: the narrow fields of a popped result beat (:data:`RESULT`'s, and the
#: certified mode's ``outcome`` and ``tight``, 0 in the other modes; ``hit`` 0 and ``flags``
#: the answer's with the on-chip reduction, whose beats are
#: :data:`~raplas_hdl.model.records.ANSWER`'s).
RES_INFO_WORD = Record("res_info", [Field("valid", 1, "a beat was popped")] + [
    RESULT[name] for name in ("last", "empty", "hit", "flags")] + [
    RESULT_CERTIFIED[name] for name in ("outcome", "tight")], "RES_INFO register")
#: ``RES_IDS``: the IDs of a popped result beat.
RES_IDS_WORD = Record("res_ids", [RESULT["tri_id"].with_(width=20),
                                  RESULT["ray_id"].with_(width=12)], "RES_IDS register")

_CMD_START = CMD_START_WORD.bind()
_RES_INFO = RES_INFO_WORD.bind()
_RES_IDS = RES_IDS_WORD.bind()
#: Bits of ``RES_INFO`` (the low bit of ``flags``, 3 bits).
RES_INFO_BITS = {f.name: f.offset for f in _RES_INFO}
#: ``RES_IDS``: tri_id in bits 19:0, ray_id in bits 31:20.
RES_TRI_BITS = _RES_IDS["tri_id"].width
RES_RAY_SHIFT = _RES_IDS["ray_id"].offset
#: ``CMD_START``: count in bits 23:0, bank bit 24, indirect bit 25, keep_all bit 26.
CMD_COUNT_BITS = _CMD_START["count"].width
CMD_BANK_BIT = _CMD_START["bank"].offset
CMD_INDIRECT_BIT = _CMD_START["indirect"].offset
CMD_KEEP_ALL_BIT = _CMD_START["keep_all"].offset


def _bits(layout) -> str:
    """``"31:0"``: the bits a register word uses."""
    return f"{layout.size - 1}:0"


def _fields_text(layout) -> str:
    """``"count 23:0, bank 24, indirect 25"``: where a word's fields are."""
    def span(f):
        return f"{f.offset + f.size - 1}:{f.offset}" if f.size > 1 else f"{f.offset}"
    return ", ".join(f"{f.name} {span(f)}" for f in layout)


@dataclass(frozen=True)
class Register:
    """One row of the register map."""

    offset: int      # word address
    name: str
    access: str      # "R", "W", "RW", or "R*" (a read has a side effect)
    bits: str        # "31:0", "25:0", ...
    meaning: str


_COUNTERS = COUNTERS.names

#: The register map, in address order.
REGISTER_MAP: tuple[Register, ...] = (
    Register(0x00, "ID", "R", "31:0", "0x52504C53 (ASCII RPLS)"),
    Register(0x01, "VERSION", "R", "31:0", "register-map version: major 31:16, minor 15:0"),
    Register(0x02, "CFG_FORMAT", "R", "24:0",
             "exp_bits 7:0, man_bits 15:8, rounding 17:16 (0 rtz, 1 rne, 2 chop), "
             "mode 25:24 (0 paper, 1 conservative, 2 certified), reduce 26 (the result "
             "window holds answers)"),
    Register(0x03, "CFG_LATTICE", "R", "31:0",
             "rows 7:0, cols 15:8, testers 23:16, lanes 31:24"),
    Register(0x04, "CFG_DEPTHS", "R", "31:0", "tris_per_sphere 15:0, fifo_depth 31:16"),
    Register(0x05, "CFG_MAX_TRIANGLES", "R", "31:0", "Triangle Memory depth"),
    Register(0x06, "CFG_MAX_SPHERES", "R", "31:0", "Sphere Memory depth"),
    Register(0x07, "CFG_MARGIN_SCALE", "R", "31:0", "conservative-margin scale"),
    Register(0x08, "STATUS", "R", "4:0",
             "busy 0 (a run is queued or going), result_valid 1 (a result beat waits), "
             "fifo_overflow 2 (sticky, pair FIFO), cmd_full 3 (command slot taken), "
             "cmd_overrun 4 (sticky, a CMD_START was refused)"),
    Register(0x09, "CONTROL", "W", "1:0",
             "write 1: clear_counters 0 (zero every counter), clear_overrun 1"),
    Register(0x0A, "MEM_ADDR", "RW", "31:0",
             "address on the unit's write port (memory_image map); +1 after each MEM_DATA"),
    Register(0x0B, "MEM_DATA", "W", "31:0", "write this word at MEM_ADDR, then MEM_ADDR += 1"),
    Register(0x0C, "CMD_FIRST", "RW", "31:0",
             "first sphere ID, or run-list position when indirect"),
    Register(0x0D, "CMD_START", "W", _bits(_CMD_START),
             f"{_fields_text(_CMD_START)}; queues the run with CMD_FIRST "
             "(wb_err and cmd_overrun if the slot is full)"),
    Register(0x10, "RES_INFO", "R*", _bits(_RES_INFO),
             f"pops a beat: {_fields_text(_RES_INFO)} "
             "(overflow, underflow, invalid); 0 when no beat waits"),
    Register(0x11, "RES_IDS", "R", _bits(_RES_IDS), f"popped beat: {_fields_text(_RES_IDS)}"),
    Register(0x12, "RES_T", "R", "31:0", "popped beat: t' (format bit pattern)"),
    Register(0x13, "RES_U", "R", "31:0", "popped beat: u'"),
    Register(0x14, "RES_V", "R", "31:0", "popped beat: v'"),
    Register(0x15, "RES_DET", "R", "31:0", "popped beat: det"),
) + tuple(Register(0x20 + k, f"CTR_{f.name.upper()}", "R", f"{f.width - 1}:0",
                   f"counter: {f.meaning}") for k, f in enumerate(COUNTERS))

#: Name -> word address.
REGISTERS = {r.name: r.offset for r in REGISTER_MAP}
#: Result-window registers after ``RES_INFO``, in read order.
RESULT_REGS = ("RES_IDS", "RES_T", "RES_U", "RES_V", "RES_DET")
#: Counter name (``cycles`` and :data:`~raplas_hdl.model.config.COUNTER_NAMES`) ->
#: register name.
COUNTER_REGS = {name: f"CTR_{name.upper()}" for name in _COUNTERS}


def _check_map():
    offsets = [r.offset for r in REGISTER_MAP]
    assert offsets == sorted(set(offsets)), "register offsets must be unique and ascending"
    assert max(offsets) < (1 << ADDR_BITS)


_check_map()


# -- configuration words ------------------------------------------------------------------
def config_words(params: dict) -> dict:
    """Values of the ``CFG_*`` registers for :meth:`UnitConfig.params` ``params``."""
    return {
        "CFG_FORMAT": (params["exp_bits"] | params["man_bits"] << 8
                       | ROUNDING_CODES[params["rounding"]] << 16
                       | MODE_CODES[params["mode"]] << 24
                       | int(params.get("reduce", False)) << 26),
        "CFG_LATTICE": (params["rows"] | params["cols"] << 8 | params["testers"] << 16
                        | params.get("lanes", 1) << 24),
        "CFG_DEPTHS": params["tris_per_sphere"] | params["fifo_depth"] << 16,
        "CFG_MAX_TRIANGLES": params["max_triangles"],
        "CFG_MAX_SPHERES": params["max_spheres"],
        "CFG_MARGIN_SCALE": params["margin_scale"] & 0xFFFFFFFF,
    }


def config_from_words(words: dict) -> dict:
    """Inverse of :func:`config_words`: the parameters a board reports (``lanes`` and
    ``reduce`` only when not the default, as :meth:`UnitConfig.params` gives them)."""
    fmt, lat, dep = words["CFG_FORMAT"], words["CFG_LATTICE"], words["CFG_DEPTHS"]
    rounding = {v: k for k, v in ROUNDING_CODES.items()}.get((fmt >> 16) & 3, "?")
    mode = {v: k for k, v in MODE_CODES.items()}.get((fmt >> 24) & 3, "?")
    lanes, reduce = lat >> 24, bool(fmt >> 26 & 1)
    return {"exp_bits": fmt & 0xFF, "man_bits": (fmt >> 8) & 0xFF, "rounding": rounding,
            "rows": lat & 0xFF, "cols": (lat >> 8) & 0xFF, "testers": (lat >> 16) & 0xFF,
            "tris_per_sphere": dep & 0xFFFF, "max_triangles": words["CFG_MAX_TRIANGLES"],
            "max_spheres": words["CFG_MAX_SPHERES"], "mode": mode,
            "margin_scale": words["CFG_MARGIN_SCALE"], "fifo_depth": dep >> 16,
            **({"lanes": lanes} if lanes != 1 else {}),
            **({"reduce": True} if reduce else {})}


# -- command and result words ---------------------------------------------------------------
def cmd_start_word(count: int, bank: int, indirect: bool, keep_all: bool = False) -> int:
    """The ``CMD_START`` word of a run of ``count`` spheres on ``bank`` (``keep_all``: cull
    nothing)."""
    if not 0 <= int(count) < (1 << CMD_COUNT_BITS):
        raise ValueError(f"count must be 0 .. {(1 << CMD_COUNT_BITS) - 1}, not {count}")
    if bank not in (0, 1):
        raise ValueError(f"bank must be 0 or 1, not {bank!r}")
    return _CMD_START.pack({"count": int(count), "bank": int(bank),
                            "indirect": int(bool(indirect)), "keep_all": int(bool(keep_all))})


def decode_cmd_start(word: int) -> tuple[int, int, int, int]:
    """(count, bank, indirect, keep_all) of a ``CMD_START`` word."""
    w = _CMD_START.unpack(int(word) & ((1 << _CMD_START.size) - 1))
    return tuple(int(w[name]) for name in CMD_START_WORD.names)


def res_info_word(last, empty, hit, flags, outcome=0, tight=0) -> int:
    """``RES_INFO`` of a popped beat (``valid`` set)."""
    return _RES_INFO.pack({"valid": 1, "last": int(last), "empty": int(empty), "hit": int(hit),
                           "flags": int(flags) & 7, "outcome": int(outcome) & 3,
                           "tight": int(tight) & 1})


def res_ids_word(ray_id, tri_id) -> int:
    return _RES_IDS.pack({"ray_id": int(ray_id), "tri_id": int(tri_id)})


def result_beats(info, ids, t, u, v, det, config=None) -> np.ndarray:
    """Beats of the unit's output stream from the six words read per beat (arrays, one
    element per beat): :data:`~raplas_hdl.model.intersection.RESULT_DTYPE`, or for
    ``config`` the dtype of its stream (:func:`~raplas_hdl.model.records.output_record`:
    with ``outcome`` and ``tight`` in certified mode, answers with ``reduce``)."""
    info = _RES_INFO.unpack_words(np.asarray(info, np.uint64).reshape(-1, 1))
    idw = _RES_IDS.unpack_words(np.asarray(ids, np.uint64).reshape(-1, 1))
    dtype = RESULT.dtype() if config is None else output_record(config).dtype()
    out = np.zeros(len(info), dtype)
    for name in ("last", "empty", "hit", "flags", "outcome", "tight"):
        if name in dtype.names:
            out[name] = info[name]
    for name in ("ray_id", "tri_id"):
        out[name] = idw[name]
    for name, word in (("t", t), ("u", u), ("v", v), ("det", det)):
        out[name] = np.asarray(word, np.uint64).reshape(-1)
    return out


def decode_result_words(info: int, ids: int, t: int, u: int, v: int, det: int,
                        config=None) -> dict:
    """Fields of one beat (as :func:`result_beats` names them) from its six words."""
    beat = result_beats([info], [ids], [t], [u], [v], [det], config)[0]
    return {name: int(beat[name]) for name in beat.dtype.names}


# -- documentation table --------------------------------------------------------------------
_HEADER = ("Offset", "Byte offset", "Name", "R/W", "Bits", "Meaning")


def markdown_table() -> str:
    """The register table of ``docs/board-top.md`` (Markdown)."""
    lines = ["| " + " | ".join(_HEADER) + " |", "|" + "|".join("---" for _ in _HEADER) + "|"]
    for r in REGISTER_MAP:
        lines.append(f"| 0x{r.offset:02X} | 0x{4 * r.offset:03X} | {r.name} | {r.access} | "
                     f"{r.bits} | {r.meaning} |")
    return "\n".join(lines) + "\n"


def parse_markdown_table(text: str) -> tuple[Register, ...]:
    """The registers of the first table in ``text`` whose header is the register table's."""
    rows, inside = [], False
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if not inside:
            inside = tuple(cells) == _HEADER
            continue
        if not line.strip().startswith("|"):
            break
        if set(line.replace("|", "").strip()) <= set("-: "):
            continue
        if len(cells) != len(_HEADER):
            raise ValueError(f"register table row with {len(cells)} cells: {line!r}")
        off, boff = int(cells[0], 16), int(cells[1], 16)
        if boff != 4 * off:
            raise ValueError(f"byte offset {cells[1]} is not 4 x {cells[0]}")
        rows.append(Register(off, cells[2], cells[3], cells[4], cells[5]))
    if not rows:
        raise ValueError("no register table found")
    return tuple(rows)
