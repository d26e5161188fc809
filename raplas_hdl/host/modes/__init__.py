"""Render modes: what the host does with the unit's runs to give each ray its answer.

The backends (:mod:`raplas_hdl.host.backends`) load, batch, cull and run the unit; a mode
(:class:`RenderMode`) folds a traced pass into each ray's nearest or any hit and adds its
figures to the render's stats. Built in, in this order: ``paper``
(:mod:`.paper`), ``conservative`` and ``certified`` (:mod:`.resolved`). A new mode is one
module with a :class:`RenderMode` subclass and :func:`register_mode`.
"""

from __future__ import annotations

from .base import RenderMode, get_mode, mode_names, register_mode
from .paper import PaperMode
from .resolved import CertifiedMode, ConservativeMode, ResolvedMode, resolve_outcomes

__all__ = ["CertifiedMode", "ConservativeMode", "PaperMode", "RenderMode", "ResolvedMode",
           "get_mode", "mode_names", "register_mode", "resolve_outcomes"]
