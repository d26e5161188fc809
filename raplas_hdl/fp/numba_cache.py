"""Keep numba's on-disk cache honest for modules that inline the FP kernels.

numba keys a cached function on its own source file only: when ``kernels.py`` (or the
format) changes, a caller in another file would load machine code built from the old
kernels. :func:`drop_stale_cache` compares a hash of those sources with the one recorded
beside the caller's cache and removes the caller's cache entries when they differ. Each
module with ``@njit(cache=True)`` functions that call the kernels calls it at import.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["drop_stale_cache"]

_SOURCES = ("kernels.py", "format.py")


def _kernel_digest() -> str:
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for name in _SOURCES:
        digest.update((here / name).read_bytes())
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
