"""An exclusive lock between processes on one machine (simulator builds, kernel compiles)."""

from __future__ import annotations

import contextlib
import fcntl
from pathlib import Path

__all__ = ["file_lock"]


@contextlib.contextmanager
def file_lock(path):
    """Hold an exclusive ``flock`` on ``path`` (created with its folder) for the block."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)
