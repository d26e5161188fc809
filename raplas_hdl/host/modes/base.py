"""What a render mode is, and the registry the backends find one in by name.

A backend runs the intersection unit (:mod:`raplas_hdl.host.backends`); a *render mode*
says which ray-triangle unit it runs (:attr:`RenderMode.unit_mode`, one of
:data:`raplas_hdl.model.modes.MODES`) and what the host does with the runs' results to
give each ray its answer. A backend hands a traced pass to its mode in one of three shapes,
and the mode handles each:

- :meth:`RenderMode.trace_compiled`: the backend's unit runs in the compiled passes of
  :mod:`raplas_hdl.engine` (``float64`` and ``model``): the mode calls the pass it needs on
  the backend's :meth:`~raplas_hdl.host.backends.Backend.arithmetic`;
- :meth:`RenderMode.trace_streams`: the backend gives each run's pair stream
  (:meth:`~raplas_hdl.host.backends.Backend.stream`, the ``rtl`` backend): the mode folds
  them on the host;
- :meth:`RenderMode.trace_answers`: the unit was built with the on-chip reduction and sends
  one ANSWER beat per ray (:meth:`~raplas_hdl.host.backends.UnitBackend.answers`).

A new mode is one module with a :class:`RenderMode` subclass and a call of
:func:`register_mode`; ``make_backend(..., mode=name)`` then renders with it.
"""

from __future__ import annotations

import numpy as np

from ...model.modes import check_mode
from ...model.reduction import check_reduce_format

__all__ = ["RenderMode", "get_mode", "mode_names", "register_mode"]


class RenderMode:
    """How the host turns the unit's runs into each ray's nearest (or any) hit."""

    #: the name the backends and the CLI know the mode by
    name = "?"
    #: the ray-triangle unit the mode runs (:data:`raplas_hdl.model.modes.MODES`)
    unit_mode = "paper"
    #: whether the unit built with the on-chip reduction serves this mode
    reducible = False

    def check(self, fmt, reduce: bool) -> None:
        """Raise ``ValueError`` (one line) unless the mode renders in ``fmt`` (``reduce``:
        through the unit with the on-chip reduction)."""
        if reduce and not self.reducible:
            raise ValueError(f"the on-chip reduction has no {self.name} mode (its hits must "
                             f"reach the host to be resolved): use --mode paper or "
                             f"certified, or no --reduce")
        if reduce:
            check_reduce_format(fmt)

    def new_stats(self) -> dict:
        """The mode's own counts of a render (kept by the backend as ``mode_stats``)."""
        return {}

    def trace(self, backend, batch, run_b, run_start, run_sph, best_t, best_tri, tmin,
              tmax, exclude, any_hit) -> np.ndarray:
        """A pass of runs folded into each ray's ``best_t, best_tri`` (B, R) in place;
        returns the unit's counters per run (U, 8). Picks the shape the backend gives
        (module docstring)."""
        if backend.reduce:
            how = self.trace_answers
        elif backend.runs_compiled:
            how = self.trace_compiled
        else:
            how = self.trace_streams
        return how(backend, batch, run_b, run_start, run_sph, best_t, best_tri, tmin, tmax,
                   exclude, any_hit)

    def trace_compiled(self, backend, batch, run_b, run_start, run_sph, best_t, best_tri,
                       tmin, tmax, exclude, any_hit) -> np.ndarray:
        raise NotImplementedError(f"the {self.name} mode has no compiled pass")

    def trace_streams(self, backend, batch, run_b, run_start, run_sph, best_t, best_tri,
                      tmin, tmax, exclude, any_hit) -> np.ndarray:
        raise NotImplementedError(f"the {self.name} mode does not fold pair streams")

    def trace_answers(self, backend, batch, run_b, run_start, run_sph, best_t, best_tri,
                      tmin, tmax, exclude, any_hit) -> np.ndarray:
        raise NotImplementedError(f"the {self.name} mode has no on-chip reduction")

    def report(self, backend, stats: dict) -> None:
        """Add the mode's figures of a finished render to its ``stats``."""

    def warm(self, backend, run) -> None:
        """The backend's throw-away warm-up pass: ``run()`` runs it (compiling the kernels
        it meets); a mode may run it its own way."""
        run()


_REGISTRY: dict[str, RenderMode] = {}


def register_mode(mode: RenderMode) -> RenderMode:
    """Make ``mode`` known by its name (``make_backend(..., mode=name)``); returns it.

    Raises
    ------
    ValueError
        When another mode already has the name, or its ``unit_mode`` is not a unit's.
    """
    check_mode(mode.unit_mode)
    old = _REGISTRY.get(mode.name)
    if old is not None and type(old) is not type(mode):
        raise ValueError(f"a render mode named {mode.name!r} is already registered "
                         f"({type(old).__name__})")
    _REGISTRY[mode.name] = mode
    return mode


def get_mode(name) -> RenderMode:
    """The registered mode called ``name``.

    Raises
    ------
    ValueError
        Naming the mode and the choices.
    """
    if isinstance(name, RenderMode):
        return name
    mode = _REGISTRY.get(name)
    if mode is None:
        raise ValueError(f"mode must be one of {', '.join(_REGISTRY)}, not {name!r}")
    return mode


def mode_names() -> tuple[str, ...]:
    """The registered modes' names, in registration order."""
    return tuple(_REGISTRY)
