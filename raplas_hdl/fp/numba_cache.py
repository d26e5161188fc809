"""Keep numba's on-disk cache honest for modules that inline the FP kernels.

numba keys a cached function on its own source file only: when a compiled function that
another file's kernels call changes (the FP kernels, the fast paths, the unit models' pair
and plane arithmetic, the conservative margins), a caller would load machine code built
from the old source. :func:`drop_stale_cache` compares a hash of those sources with the one
recorded beside the caller's cache (``__pycache__``, and ``NUMBA_CACHE_DIR`` when set) and
removes the caller's cache entries when they differ. Each module with
``@njit(cache=True)`` functions that call other files' kernels calls it at import.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["drop_stale_cache"]

#: Files (relative to the package) whose compiled functions other files' kernels call.
_SOURCES = ("fp/kernels.py", "fp/format.py", "fp/fast.py", "model/pair_kernels.py",
            "model/ray_triangle.py", "model/plane_sphere.py", "model/conservative.py",
            "engine/kernels.py", "engine/exact_filter.py", "model/certified.py")


def _kernel_digest() -> str:
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for name in _SOURCES:
        digest.update((root / name).read_bytes())
    return digest.hexdigest()


def _cache_dirs(src: Path) -> list[Path]:
    """Where numba keeps ``src``'s cache: ``__pycache__`` beside it, and with
    ``NUMBA_CACHE_DIR`` the folder numba's user-provided locator derives from the source's
    folder (its name and a SHA-1 of its path)."""
    dirs = [src.parent / "__pycache__"]
    root = os.environ.get("NUMBA_CACHE_DIR")
    if root:
        folder = str(src.parent)
        dirs.append(Path(root) / f"{src.parent.name}_{hashlib.sha1(folder.encode()).hexdigest()}")
    return dirs


def drop_stale_cache(module_file: str) -> None:
    """Remove ``module_file``'s numba cache files if the kernels it calls changed since."""
    src = Path(module_file).resolve()
    digest = _kernel_digest()
    for cache_dir in _cache_dirs(src):
        stamp = cache_dir / f"{src.stem}.kernels-sha256"
        try:
            if stamp.exists() and stamp.read_text() == digest:
                continue
            for path in cache_dir.glob(f"{src.stem}.*.nb[ic]"):
                path.unlink(missing_ok=True)
            cache_dir.mkdir(parents=True, exist_ok=True)
            stamp.write_text(digest)
        except OSError:         # read-only checkout: numba cannot cache there either
            pass
