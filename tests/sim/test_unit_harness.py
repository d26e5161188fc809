"""The intersection unit's job-stream harness (a live simulation) against the model.

The scene of the cocotb test (200 FP24 triangles, spheres of up to 4) is loaded once,
through the backdoor (``$readmemh`` of the memory images) or through the unit's write port
at full rate from the op stream; then several rounds of runs
go through the same live simulation, with random back-pressure on the result stream: the
cocotb test's seven runs, an early-out round that disables rays of the same bundles
between rounds (enable bits rewritten only), and a round of overlapped runs. Every stream
and every run's counters (the round's totals with overlap) must equal the model's
``run_runs``, bit for bit. A missing simulator is an error, not a skip.
"""

import numpy as np
import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.records import RESULT
from raplas_hdl.sim.drive.unit_harness import (
    HarnessError,
    UnitSession,
    encode_ops,
    ops_bytes,
    parse_beats,
    parse_hex,
    scene_images,
)
from tests.support.unit_scenes import (
    assert_keep_all,
    assert_operation_events,
    check_against_model,
    scene_and_runs,
    with_enable,
)

CFG = UnitConfig(fmt=FP24, rows=4, cols=4, testers=4, tris_per_sphere=4, max_triangles=256,
                 max_spheres=128, fifo_depth=8)


@pytest.fixture(scope="module")
def scene_runs():
    return scene_and_runs(CFG, 200, seed=11)


def _early_out(runs, rng):
    """The first runs again with about half of each bundle's enabled rays switched off."""
    out = []
    for b, ids in runs[:3]:
        out.append((with_enable(b, b.enable & (rng.random(CFG.n_rays) < 0.5)), ids))
    return out


# Icarus runs in the full suite (make test: Verilator here, and Icarus sessions in
# tests/host/test_render_reduce.py::test_rtl_reduce_render_icarus and the rtl renders)
@pytest.mark.parametrize("simulator, backdoor", [
    pytest.param("icarus", True, marks=pytest.mark.full),
    pytest.param("icarus", False, marks=pytest.mark.full),
    ("verilator", True), ("verilator", False)],
    ids=["icarus-backdoor", "icarus-write-port", "verilator-backdoor", "verilator-write-port"])
def test_session_rounds_match_model(simulator, backdoor, scene_runs):
    scene, runs = scene_runs
    rng = np.random.default_rng(5)
    with UnitSession(simulator, CFG, scene, seed=7, ready_density=0.5,
                     backdoor=backdoor) as s:
        assert s.rounds == 1                  # the scene load is round 0
        assert (s.load_cycles > 0) != backdoor
        ref = check_against_model(CFG, scene, runs, s.run(runs))
        assert_keep_all(CFG, scene, runs, ref)
        assert_operation_events(ref)
        assert sum(r[1]["pairs_skipped"] for r in ref) > 0
        early = _early_out(runs, rng)
        ref2 = check_against_model(CFG, scene, early, s.run(early))
        assert sum(r[1]["pairs_skipped"] for r in ref2) > sum(r[1]["pairs_skipped"]
                                                            for r in ref[:3])
        res = s.run(runs, overlap=True)
        check_against_model(CFG, scene, runs, res, overlap=True)
        assert res[-1][1]["_max_fifo_level"] == CFG.fifo_depth
        assert s.run([]) == []
        assert s.rounds == 4 and s.runs_done == 2 * len(runs) + len(early)
    with pytest.raises(HarnessError, match="closed"):
        s.run(runs)


def test_harness_reports_a_stall(scene_runs):
    """A wait without progress for longer than MAX_STALL clocks ends the simulation with
    an error that names it (here: a bound far too small for the first run)."""
    scene, runs = scene_runs
    s = UnitSession("icarus", CFG, scene, max_stall=3, backdoor=False)
    with pytest.raises(HarnessError, match="no progress"):
        s.run(runs[:1])
    s.close()


def test_scene_images_are_the_write_port_words(scene_runs):
    """The backdoor images hold, per word, the lanes the write port stores."""
    scene, _ = scene_runs
    img = scene_images(CFG, scene)
    w = CFG.fmt.width
    tri = [int(x, 16) for x in img["TRI_INIT"].split()]
    assert len(tri) == scene.n_triangles
    fields = np.concatenate([scene.v0, scene.e1, scene.e2, scene.n], axis=1)   # 12 per row
    for k in (0, 7, len(tri) - 1):
        assert [(tri[k] >> (w * j)) & ((1 << w) - 1) for j in range(12)] == \
            [int(x) for x in fields[k]]
    cnt = [int(x, 16) for x in img["CNT_INIT"].split()]
    assert cnt == [int(c) for c in scene.tri_counts]
    sph = [int(x, 16) for x in img["SPH_INIT"].split()]
    assert (sph[3] >> (3 * w)) == int(scene.radii[3])
    tl = [int(x, 16) for x in img["TL_INIT"].split()]
    c = int(scene.tri_counts[0])
    assert tl[:c] == [int(x) for x in scene.tri_lists[0][:c]]


def test_ops_and_beats_round_trip(scene_runs):
    scene, runs = scene_runs
    op, addr, data = encode_ops(CFG, scene, runs)
    raw = ops_bytes(op, addr, data)
    assert len(raw) == 12 * op.size          # three little-endian 32-bit words per op
    back = np.frombuffer(raw, "<u4").reshape(-1, 3)
    assert np.array_equal(back[:, 0], op)
    assert np.array_equal(back[:, 1], addr)
    assert np.array_equal(back[:, 2], data)
    lay = RESULT.bind(CFG)
    vals = np.random.default_rng(0).integers(0, 1 << 62, (50, lay.n_words)).astype(np.uint64)
    vals[:, -1] &= np.uint64((1 << (lay.size - 64 * (lay.n_words - 1))) - 1)
    n32 = -(-lay.size // 32)
    # as $fwrite "%u" writes them: 32-bit words, least significant first, little-endian
    words = [[(sum(int(w) << (64 * j) for j, w in enumerate(v)) >> (32 * k)) & 0xFFFFFFFF
              for k in range(n32)] for v in vals]
    two = np.array(words, "<u4").tobytes()
    assert np.array_equal(parse_beats(two, lay.size), vals)
    # "%z": each word followed by its X/Z mask
    four = np.stack([np.array(words, "<u4"), np.zeros((50, n32), "<u4")], axis=2)
    assert np.array_equal(parse_beats(four.tobytes(), lay.size, four_state=True), vals)
    four[7, 1, 1] = 4                          # an X in beat 7
    with pytest.raises(HarnessError, match="beat 7 has X or Z"):
        parse_beats(four.tobytes(), lay.size, four_state=True)
    with pytest.raises(HarnessError, match="not made of"):
        parse_beats(two[:-4], lay.size)
    digits = -(-lay.size // 4)
    with pytest.raises(HarnessError, match="not hex"):
        parse_hex(b"x" * digits + b"\n", digits)
