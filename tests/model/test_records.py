"""The boundary records (:mod:`raplas_hdl.model.records`) and their views.

- pack / unpack round trips (Python ints and uint64 words, one record and batches, fields
  across word boundaries), and the packers' errors;
- the packed bits equal Amaranth's own packing of the RTL's ``StructLayout`` of the same
  record (``layout.const``), and the layouts' fields agree with the records' offsets and
  widths, field by field, for several builds;
- the ports of the units are those layouts; ``RESULT_DTYPE`` is the record's dtype;
- the host's hand-written plane packer agrees with the record ``PLANE``;
- the model side imports no Amaranth.
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from amaranth.hdl import Shape
from amaranth.lib import data

from raplas_hdl.fp import FP16, FP24, FPFormat
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.records import (CMD, COUNTERS, PAIR, PLANE, PS_RESULT, RECORDS, RESULT,
                                      RT_RESULT, SPHERE, Field, Record, unit_params)
from raplas_hdl.rtl.records import struct_layout

ROOT = Path(__file__).resolve().parents[2]

CONFIGS = [UnitConfig(), UnitConfig(fmt=FP16, rows=2, cols=3, max_triangles=32, max_spheres=24),
           UnitConfig(fmt=FPFormat(5, 6), rows=8, cols=8, tris_per_sphere=16,
                      max_triangles=1 << 20, max_spheres=1 << 16)]
EXTRA = {"id_bits": 13, "rows": 5, "cols": 7}


def bound(record, cfg):
    params = {**unit_params(cfg), **{k: v for k, v in EXTRA.items() if k not in ("rows", "cols")}}
    return record.bind(params)


def random_values(layout, n, rng):
    """Random field values (every bit pattern of each field's width), as a dict."""
    out = {}
    for s in layout:
        shape = (n, len(s.parts)) if s.parts else (n,)
        hi = np.uint64((1 << s.width) - 1)
        v = rng.integers(0, np.iinfo(np.uint64).max, shape, dtype=np.uint64, endpoint=True) & hi
        v[0] = hi                       # all ones in the first record
        v[1] = 0
        out[s.name] = v
    return out


def as_struct(values, layout):
    """Amaranth ``const`` argument: vector fields as dicts of their elements."""
    return {s.name: ({p: int(values[s.name][k]) for k, p in enumerate(s.parts)} if s.parts
                     else int(values[s.name])) for s in layout}


@pytest.mark.parametrize("cfg", CONFIGS, ids=["default", "fp16", "wide"])
@pytest.mark.parametrize("name", list(RECORDS))
def test_record_round_trip_and_amaranth_bits(name, cfg):
    record = RECORDS[name]
    layout = bound(record, cfg)
    rng = np.random.default_rng(len(name))
    vals = random_values(layout, 40, rng)
    ints = layout.pack(vals)
    words = layout.pack_words(vals)
    assert words.shape == (40, layout.n_words)
    assert all(0 <= x < (1 << layout.size) for x in ints)
    back = layout.unpack(ints)
    assert back.dtype == record.dtype()
    for s in layout:
        assert np.array_equal(back[s.name].astype(np.uint64), vals[s.name])
    assert np.array_equal(layout.unpack_words(words), back)
    assert layout.pack(back) == ints                      # a structured array packs too
    assert layout.pack(back[3]) == ints[3]                # one record -> one int
    one = layout.unpack(ints[3])
    assert one.shape == () and layout.pack(one) == ints[3]
    # the RTL's layout packs the same bits
    amaranth = struct_layout(record, layout.params)
    assert Shape.cast(amaranth).width == layout.size
    for k in (0, 1, 7):
        assert amaranth.const(as_struct({n: v[k] for n, v in vals.items()}, layout)) \
            .as_value().value == ints[k]


@pytest.mark.parametrize("cfg", CONFIGS, ids=["default", "fp16", "wide"])
@pytest.mark.parametrize("name", list(RECORDS))
def test_layout_fields_agree(name, cfg):
    layout = bound(RECORDS[name], cfg)
    amaranth = struct_layout(layout)
    members = list(amaranth)
    assert [n for n, _ in members] == [s.name for s in layout]
    for (n, fld), s in zip(members, layout):
        assert fld.offset == s.offset, n
        if s.parts:
            assert isinstance(fld.shape, data.StructLayout)
            assert [(p, f.offset, Shape.cast(f.shape).width) for p, f in fld.shape] == \
                [(p, k * s.width, s.width) for k, p in enumerate(s.parts)]
        else:
            assert Shape.cast(fld.shape).width == s.width, n
    assert {k: v for k, v in layout.offsets().items() if "." not in k} == \
        {s.name: (s.offset, s.width) for s in layout if not s.parts}


def test_unit_ports_are_the_records():
    from raplas_hdl.model.intersection import RESULT_DTYPE
    from raplas_hdl.rtl.intersection import port_layouts
    from raplas_hdl.rtl.plane_sphere import result_layout, sphere_layout
    from raplas_hdl.rtl.ray_triangle import input_layout, output_layout

    assert RESULT_DTYPE == RESULT.dtype()
    assert RESULT_DTYPE == np.dtype([("ray_id", "u4"), ("tri_id", "u4"), ("hit", "u1"),
                                     ("t", "u4"), ("u", "u4"), ("v", "u4"), ("det", "u4"),
                                     ("flags", "u1"), ("last", "u1"), ("empty", "u1")])
    cfg = CONFIGS[0]
    ports = port_layouts(cfg)
    assert ports["cmd"] == struct_layout(CMD, cfg)
    assert ports["result"] == struct_layout(RESULT, cfg)
    assert ports["counters"] == struct_layout(COUNTERS, cfg)
    assert [n for n, _ in ports["counters"]][0] == "cycles"
    assert input_layout(FP24, 5, 9) == struct_layout(PAIR, FP24, ray_id_bits=5, tri_id_bits=9)
    assert output_layout(FP24) == struct_layout(RT_RESULT, FP24, ray_id_bits=16,
                                                tri_id_bits=16)
    assert sphere_layout(FP24, 10) == struct_layout(SPHERE, FP24, id_bits=10)
    assert result_layout(3, 5, 10) == struct_layout(PS_RESULT, id_bits=10, rows=3, cols=5)
    # the widths of this build (the command's fields stay where the RTL had them)
    lay = CMD.bind(cfg)
    assert [(s.name, s.offset, s.width) for s in lay][:4] == [
        ("first", 0, 8), ("count", 8, 9), ("bank", 17, 1), ("indirect", 18, 1)]


def test_words_cross_64_bit_boundaries():
    lay = PAIR.bind(FP24, ray_id_bits=16, tri_id_bits=16)
    assert lay.size == 32 + 18 * 24 and lay.n_words == 8
    vals = {s.name: np.zeros((1, 3) if s.parts else 1, np.uint64) for s in lay}
    vals["e1"][0, 0] = (1 << 24) - 1                       # bits 248..271: words 3 and 4
    word = lay.pack(vals)[0]
    off = lay.offsets()["e1.x"][0]
    assert off == 32 + 9 * 24 and word == ((1 << 24) - 1) << off
    words = lay.pack_words(vals)[0]
    assert words[3] == np.uint64(0xFF << 56) and words[4] == np.uint64(0xFFFF)
    assert not words[[0, 1, 2, 5, 6, 7]].any()
    assert lay.unpack(word)["e1"][0] == (1 << 24) - 1


def test_packer_errors():
    lay = RESULT.bind(CONFIGS[0])
    vals = {n: 0 for n in RESULT.names}
    with pytest.raises(KeyError, match="empty"):
        lay.pack({k: v for k, v in vals.items() if k != "empty"})
    with pytest.raises(ValueError, match="flags.*3 bits"):
        lay.pack({**vals, "flags": 8})
    with pytest.raises(ValueError, match="negative"):
        lay.pack({**vals, "t": -1})
    with pytest.raises(ValueError, match="integer"):
        lay.pack({**vals, "t": 1.5})
    with pytest.raises(ValueError, match="outside 116 bits"):
        lay.unpack(1 << 116)
    with pytest.raises(ValueError, match="needs the parameter.*ray_id_bits"):
        RESULT.bind(FP24)
    with pytest.raises(ValueError, match="last axis"):
        PAIR.bind(FP24, ray_id_bits=4, tri_id_bits=4).pack(
            {"ray_id": 0, "tri_id": 0, **{n: np.zeros(2, np.uint32)
                                         for n in ("o", "d", "v0", "e1", "e2", "n")}})
    with pytest.raises(ValueError, match="not a parameter"):
        Field("x", "width")
    with pytest.raises(ValueError, match="repeated"):
        Record("r", [Field("a", 1), Field("a", 2)])
    # a layout wider than NumPy storage is fine for the RTL, not for the packers
    wide = PS_RESULT.bind(id_bits=8, rows=65, cols=4)
    assert struct_layout(wide).size == 8 + 65 + 4
    with pytest.raises(ValueError, match="row_mask"):
        wide.pack({"id": 0, "row_mask": 0, "col_mask": 0})


def test_markdown_tables():
    text = RESULT.markdown()
    assert "| `t` | W |" in text and "| `ray_id` | ray_id_bits |" in text
    text = PAIR.bind(FP24, ray_id_bits=5, tri_id_bits=10).markdown()
    assert "| `o` (x, y, z) | 86:15 | 3 x 24 |" in text
    assert CMD.bind(CONFIGS[0]).markdown().count("\n") == 2 + len(CMD.names)


def test_host_plane_packer_agrees_with_the_record():
    from raplas_hdl.model.bundles import RayBundle

    b = RayBundle(np.array([0.1, 0.2, -5.0]), np.array([0.0, 0.0, 1.0]),
                  np.array([0.3, 0.0, 0.0]), np.array([0.0, 0.2, 0.0]), 3, 4)
    n, p = b.encode_planes(FP24)
    ours = PLANE.bind(FP24).pack({"nx": n[:, 0], "ny": n[:, 1], "nz": n[:, 2], "p": p})
    assert ours == b.pack_planes(FP24)


def test_model_records_import_no_amaranth():
    code = ("import sys, raplas_hdl.model.records, raplas_hdl.model.intersection, "
            "raplas_hdl.model.board_map; "
            "bad = [m for m in sys.modules if m.split('.')[0] == 'amaranth']; assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)
