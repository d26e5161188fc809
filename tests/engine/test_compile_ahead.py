"""The certified mode's cold start (raplas_hdl/engine/compile_ahead.py, CertifiedMode.warm):
the block kernel compiled in a second process while a first warm-up pass runs every pair on
the exact path; the render is the same either way."""

import os
import subprocess
import sys

import numpy as np
import pytest

from raplas_hdl.engine import compile_ahead
from raplas_hdl.fp import FP24
from raplas_hdl.host.backends import ModelBackend
from raplas_hdl.host.modes import resolved
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene
from raplas_hdl.model import certified

SMALL = RenderSettings(width=16, height=16, rows=4, cols=4, shadow_rows=2, shadow_cols=2,
                       progress=False)


def test_exact_pairs_equal_block_pairs():
    from raplas_hdl.model import stress_cases

    fmt = FP24.with_rounding("rne")
    vec = stress_cases.vectors(fmt, 500, seed=4, special_rate=0.02, random_rate=0.05)
    arrs = [np.ascontiguousarray(vec[k], np.uint32) for k in ("o", "d", "v0", "e1", "e2", "n")]
    cc = certified.certified_constants(fmt)
    n = len(arrs[0])
    lane = np.arange(n, dtype=np.int64)
    key = (np.int64(fmt.exp_bits), np.int64(fmt.man_bits), np.int64(1))
    out = []
    for kernel in (certified.block_pairs, certified.exact_pairs):
        res = [np.zeros(n, np.uint8)] + [np.zeros(n, np.uint32) for _ in range(4)]
        cnt = np.zeros((n, 3), np.uint8)
        kernel(*arrs, cc, lane, lane, lane, 0, n, *res, cnt, *key)
        out.append((res, cnt))
    assert (out[0][0][0] == certified.RECOMPUTE).sum() == 0
    for a, b in zip(out[0][0], out[1][0]):
        assert np.array_equal(a, b)
    assert np.array_equal(out[0][1], out[1][1])


def test_cold_warm_up_renders_the_same(monkeypatch):
    """With a child to wait for, the warm-up runs its pass twice (the first on the exact
    path, the kernel the child compiles left alone) and waits for the child; the render
    equals one without it."""
    scene = get_scene("cornell")
    plain = render(scene, ModelBackend(FP24, mode="certified"), SMALL)
    seen = []
    inner = resolved.certified_pass

    def recording(*args, **kw):
        seen.append(kw.get("unit"))
        return inner(*args, **kw)

    child = subprocess.Popen([sys.executable, "-c", "pass"])
    monkeypatch.setattr(compile_ahead, "start", lambda: child)
    monkeypatch.setattr(resolved, "certified_pass", recording)
    cold = render(scene, ModelBackend(FP24, mode="certified"), SMALL)
    assert child.returncode == 0                          # waited for
    assert seen[0] is certified.exact_pairs and seen[1] is None and None in seen[2:]
    assert certified.exact_pairs not in seen[1:]
    assert np.array_equal(cold.tri_id, plain.tri_id)
    assert np.array_equal(cold.image, plain.image)
    assert np.array_equal(cold.visibility, plain.visibility, equal_nan=True)
    assert cold.stats["certified"]["uncertain"] == plain.stats["certified"]["uncertain"]


def test_no_child_without_a_cold_cache(monkeypatch):
    monkeypatch.setattr(compile_ahead, "block_kernel_cold", lambda: False)
    assert compile_ahead.start() is None
    monkeypatch.setattr(compile_ahead, "block_kernel_cold", lambda: True)
    monkeypatch.setenv("RAPLAS_NO_COMPILE_AHEAD", "1")
    assert compile_ahead.start() is None
    assert compile_ahead.join(None) is False


@pytest.mark.full
def test_child_fills_an_empty_cache(tmp_path):
    """From an empty ``NUMBA_CACHE_DIR`` the cache is cold; the child compiles the block
    kernel into it, after which it is not (about 10 s of compile)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    ask = [sys.executable, "-c", "from raplas_hdl.engine.compile_ahead import "
           "block_kernel_cold; print(block_kernel_cold())"]
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    run = dict(env=env, cwd=root, capture_output=True, text=True, check=True)
    assert subprocess.run(ask, **run).stdout.strip() == "True"
    subprocess.run([sys.executable, "-m", "raplas_hdl.engine.compile_ahead"], **run)
    assert subprocess.run(ask, **run).stdout.strip() == "False"
