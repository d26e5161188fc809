"""Compile the kernels once per machine, before the processes that need them start.

numba compiles a kernel on first use and caches it on disk (``__pycache__`` beside the
sources, or ``NUMBA_CACHE_DIR``); a later process loads it in a fraction of a second. Two
processes that start cold at once (pytest-xdist workers, campaign workers) would each
compile the same kernels. :func:`warm` compiles a chosen set under an exclusive file lock:
the first process compiles, the others wait for the lock and then only load the cache.

Groups:

- ``generic``: the FP model's NumPy API (encode, decode, add, sub, mul, comparisons) and
  the unit models' loops (:func:`raplas_hdl.model.ray_triangle.intersect`,
  :func:`raplas_hdl.model.plane_sphere.tester_flags`); their format is a runtime argument,
  so one compile serves every format;
- ``engine``: the render passes of the model and of float64 (the model's kernels also take
  the format and mode at run time; the formats given only exercise them).
"""

from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path

import numpy as np

from ..fp import FP24
from ..fp import model as fpm
from ..fp.format import FPFormat, parse_format
from ..locks import file_lock
from ..model import plane_sphere, ray_triangle
from ..model.modes import MODES
from .backends import make_backend
from .render import RenderSettings, render
from .scenes import get_scene

__all__ = ["warm", "default_lock"]


def _generic():
    x = np.linspace(-3.0, 3.0, 24)
    a = fpm.encode(x, FP24)
    fpm.encode(x, FP24, direction="up")
    fpm.encode(x, FP24, direction="down")
    fpm.decode(a, FP24)
    for op in (fpm.add, fpm.sub, fpm.mul):
        op(a, a[::-1], FP24, flags=True)
    for cmp in (fpm.le, fpm.lt, fpm.abs_le):
        cmp(a, a[::-1], FP24)
    fpm.neg(a, FP24)
    v = a[:18].reshape(6, 3)
    plane_sphere.tester_flags(v, a[:6], v, a[6:12], FP24, flags=True)
    for mode in ray_triangle.MODES:
        ray_triangle.intersect(v, v, v, v, v, v, FP24, mode)


def _engine(fmt, mode):
    backend = make_backend("float64") if fmt is None else make_backend("model", fmt, mode=mode)
    render(get_scene("soup", n=24), backend,
           RenderSettings(width=8, height=8, rows=4, cols=4, shadow_rows=2, shadow_cols=2,
                          progress=False))


def warm(formats=("FP24/rtz",), modes=MODES, float64: bool = True,
         generic: bool = True, engine: bool = True, lock=None) -> dict:
    """Compile (or load) the kernels of the groups chosen; seconds per group.

    Parameters
    ----------
    formats : iterable of str or FPFormat
        Formats of the engine's model passes.
    modes : iterable of str
    float64, generic, engine : bool
        Which groups.
    lock : path, optional
        Hold this file's lock while compiling (default: none). A lock that cannot be
        created (a read-only install) is skipped: each process then compiles on its own.
    """
    times = {}
    held = contextlib.nullcontext()
    if lock:
        try:
            Path(lock).parent.mkdir(parents=True, exist_ok=True)
            with open(lock, "a+"):
                held = file_lock(lock)
        except OSError:         # a read-only install: compile without the lock
            pass
    with held:
        if generic:
            t0 = time.perf_counter()
            _generic()
            times["generic"] = time.perf_counter() - t0
        if engine:
            for f in formats:
                fmt = f if isinstance(f, FPFormat) else parse_format(f)
                for mode in modes:
                    t0 = time.perf_counter()
                    _engine(fmt, mode)
                    times[f"engine {fmt} {mode}"] = time.perf_counter() - t0
            if float64:
                t0 = time.perf_counter()
                _engine(None, None)
                times["engine float64"] = time.perf_counter() - t0
    return times


def default_lock() -> Path:
    """The lock file beside numba's cache: ``NUMBA_CACHE_DIR`` or the package's folder."""
    base = os.environ.get("NUMBA_CACHE_DIR") or Path(__file__).resolve().parents[1]
    return Path(base) / ".numba-warm.lock"
