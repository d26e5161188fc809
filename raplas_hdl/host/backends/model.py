"""The ``model`` backend: the bit-accurate golden model of the intersection unit, its passes
in the compiled kernels of :mod:`raplas_hdl.engine`."""

from __future__ import annotations

from ...model.intersection import run_runs
from .unit import UnitBackend

__all__ = ["ModelBackend"]


class ModelBackend(UnitBackend):
    """The bit-accurate golden model of the intersection unit (parameters: those of
    :class:`~raplas_hdl.host.backends.unit.UnitBackend`).

    A render's passes run in the compiled kernels (the render mode calls them on
    :meth:`arithmetic`); :meth:`stream` and the on-chip reduction's answers come from
    :func:`raplas_hdl.model.intersection.run_runs`, the model's side of the interface the
    RTL driver has (``config, scene, runs``).
    """

    name = "model"
    runs_compiled = True

    def run_runs(self, config, runs, overlap: bool = False):
        """The model's streams and counters, per run (``overlap`` changes neither)."""
        return run_runs(config, self.scene_memory, runs)
