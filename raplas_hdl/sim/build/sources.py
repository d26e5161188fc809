"""The digest of the sources an emitted unit's Verilog depends on: every module of
``rtl/`` (the whole unit's stages in ``rtl/unit/`` too), ``model/`` (the records and the
parameters the layouts derive from) and ``fp/``, by path and content. The simulator builds
cache the Verilog under it, so a changed source never reuses an older text."""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["rtl_sources_digest"]

_ROOT = Path(__file__).resolve().parents[2]


def rtl_sources_digest() -> str:
    """16 hex digits over the ``rtl``, ``model`` and ``fp`` sources."""
    h = hashlib.sha256()
    for sub in ("rtl", "model", "fp"):
        for p in sorted((_ROOT / sub).rglob("*.py")):
            h.update(p.relative_to(_ROOT).as_posix().encode())
            h.update(b"\0")
            h.update(p.read_bytes())
    return h.hexdigest()[:16]
