"""Keep numba's on-disk cache honest for modules that inline the FP kernels.

numba keys a cached function on its own source file only: when a compiled function that
another file's kernels call changes (the FP kernels, the fast paths, the unit models' pair
and plane arithmetic, the conservative margins), a caller would load machine code built
from the old source. :func:`drop_stale_cache` compares a hash of those sources with the one recorded
beside the caller's cache and removes the caller's cache entries when they differ. Each
module with ``@njit(cache=True)`` functions that call the kernels calls it at import.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["drop_stale_cache"]

#: Files (relative to the package) whose compiled functions other files' kernels call.
_SOURCES = ("fp/kernels.py", "fp/format.py", "fp/fast.py", "model/ray_triangle.py",
            "model/plane_sphere.py", "model/conservative.py", "engine/kernels.py")


def _kernel_digest() -> str:
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for name in _SOURCES:
        digest.update((root / name).read_bytes())
    return digest.hexdigest()


def drop_stale_cache(module_file: str) -> None:
    """Remove ``module_file``'s numba cache files if the FP kernels changed since."""
    src = Path(module_file).resolve()
    cache_dir = src.parent / "__pycache__"
    stamp = cache_dir / f"{src.stem}.kernels-sha256"
    digest = _kernel_digest()
    try:
        if stamp.exists() and stamp.read_text() == digest:
            return
        for path in cache_dir.glob(f"{src.stem}.*.nb[ic]"):
            path.unlink(missing_ok=True)
        cache_dir.mkdir(exist_ok=True)
        stamp.write_text(digest)
    except OSError:         # read-only checkout: numba cannot cache there either
        pass
