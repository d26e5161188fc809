"""Compile the certified block kernel in a second process while this one compiles the rest.

From an empty numba cache a certified render compiles about 20 s of CPU in one process; the
block kernel (:func:`raplas_hdl.model.certified.block_screened`: the values, the screen,
the outcomes) is about half of it and shares no compiled code with the rest (the culling,
the listing, the exact pair path, the filter). :func:`start` compiles it in a child process
that writes numba's disk cache; the render's warm-up meanwhile compiles everything else
through a throw-away pass that runs every pair on the exact path, then :func:`join` waits
for the child, and the real warm-up pass loads the kernel from the cache. On two cores the
first certified render takes about as long as its larger half.

Nothing depends on the child for correctness: if it fails, is slow or cannot write the
cache, this process compiles the kernel itself on first use.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

__all__ = ["block_kernel_cold", "start", "join", "main"]


def block_kernel_cold() -> bool:
    """Whether numba's disk cache holds no compiled block kernel (its index file is
    missing) and caching is possible at all."""
    from ..model.certified import block_screened

    try:
        cache = block_screened._cache
        index = Path(cache._cache_file._index_path)
    except AttributeError:              # another numba: no way to tell, do not spawn
        return False
    return not index.exists() and os.access(index.parent if index.parent.exists()
                                            else index.parent.parent, os.W_OK)


def start() -> subprocess.Popen | None:
    """A child process compiling the block kernel into the cache, when the cache has none;
    None otherwise (or when the child cannot start)."""
    if os.environ.get("RAPLAS_NO_COMPILE_AHEAD") or not block_kernel_cold():
        return None
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(root), env.get("PYTHONPATH")]))
    try:
        return subprocess.Popen([sys.executable, "-m", "raplas_hdl.engine.compile_ahead"],
                                env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
    except OSError:
        return None


def join(child: subprocess.Popen | None, timeout: float = 300.0) -> bool:
    """Wait for ``child`` (at most ``timeout`` seconds); whether it compiled the kernel."""
    if child is None:
        return False
    try:
        return child.wait(timeout) == 0
    except subprocess.TimeoutExpired:
        child.kill()
        child.wait()
        return False


def main() -> int:
    """The child: the block kernel on a few pairs, with the argument types of the
    renderer's certified pass (so that the cached signature is the one it asks for)."""
    import numpy as np

    from ..fp import FP24
    from ..fp.kernels import rmode_code
    from ..fp.model import encode
    from ..model.certified import block_screened, certified_constants

    n = 8
    rng = np.random.default_rng(0)
    mem = [np.ascontiguousarray(encode(rng.normal(size=(n, 3)), FP24), np.uint32)
           for _ in range(6)]
    lanes = np.tile(np.arange(n, dtype=np.int64), (5, 1))
    outs = [np.empty(n, np.uint32) for _ in range(4)]
    block_screened(*mem, certified_constants(FP24), lanes[0], lanes[2], lanes[3], 0, n,
                   np.empty(n, np.uint8), *outs, np.empty((n, 3), np.uint8),
                   np.int64(FP24.exp_bits), np.int64(FP24.man_bits), np.int64(rmode_code(FP24)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
