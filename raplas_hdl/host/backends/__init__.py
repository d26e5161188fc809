"""Intersection backends behind one interface: ``float64``, ``model``, ``rtl`` and ``board``.

The renderer talks to the accelerator only through :class:`Backend`, a pass at a time:

1. :meth:`Backend.load` writes a scene: triangle records and the leaf spheres of a
   :class:`~raplas_hdl.host.spheres.SphereTree` (the Sphere Memory), and keeps the inner
   nodes' spheres for the host's hierarchy test;
2. :meth:`Backend.batch` turns ``B`` bundles of one size, given as arrays (origins, screen
   centres and axes, enable bits), into a :class:`~raplas_hdl.engine.passes.BundleBatch`:
   Plane Memory and Ray Memory in the backend's arithmetic, and the *keep-all* bit of
   every bundle whose quantisation slack is over the culling budget
   (:mod:`raplas_hdl.host.culling`): neither the host nor the unit culls with it;
3. :meth:`Backend.cull` is the hierarchy cull of the whole batch, with the same arithmetic
   as the unit's plane-sphere testers;
4. :meth:`Backend.trace` runs the unit over the batch's runs and hands them to the
   backend's render mode (:mod:`raplas_hdl.host.modes`), which folds each ray's nearest (or
   any) hit; :meth:`Backend.stream` gives the runs' pair streams instead (the unit's result
   beats with ``t, u, v`` divided on the host), for checks, analyses and the modes of a
   backend whose runs are not compiled passes.

Backends:

- ``float64``: the reference with no quantisation: float64 planes and spheres,
  ``|n.C + p| <= r`` with a float64-rounding allowance, and the division-free
  Moller-Trumbore decision of ``docs/raplas.md`` evaluated in float64 on the original
  geometry (exact-inequality mode). No event flags.
- ``model`` and ``rtl`` share the unit's host side (:class:`UnitBackend`: memories, batches,
  the cull in the model's arithmetic) and differ in who runs the unit.
- ``model``: the bit-accurate golden model of the intersection unit in any format,
  rounding and ray-triangle mode, with the radius inflation of
  :mod:`raplas_hdl.host.culling`. Its passes run in the compiled kernels of
  :mod:`raplas_hdl.engine`; its streams come from
  :func:`raplas_hdl.model.intersection.run_runs`, the model's side of the interface the RTL
  driver has (``config, scene, runs``).
- ``rtl``: the same memories run through the Verilog of the unit under cocotb (Icarus or
  Verilator) with the driver's ``run_runs``; it raises :class:`BackendUnavailable` with what
  is missing when the simulator or the unit's driver is not there.
- ``board``: the unit on a board (or the simulated board) behind a serial port, through its
  register map (:class:`~raplas_hdl.link.driver.BoardDriver` over
  :class:`~raplas_hdl.link.serial_bus.SerialBus`); the board's build fixes the format, mode,
  lattice and memory depths, checked before any work.

Nothing here imports Amaranth.
"""

from __future__ import annotations

from ...fp.format import FP24, FPFormat
from .base import COUNTERS, Backend, BackendUnavailable, RunResult
from .board import BoardBackend
from .float64 import Float64Backend
from .model import ModelBackend
from .rtl import RtlBackend
from .unit import UnitBackend

__all__ = [
    "BACKENDS",
    "Backend",
    "BackendUnavailable",
    "BoardBackend",
    "COUNTERS",
    "Float64Backend",
    "ModelBackend",
    "RtlBackend",
    "RunResult",
    "UnitBackend",
    "make_backend",
]

BACKENDS = ("float64", "model", "rtl", "board")


def make_backend(name: str, fmt: FPFormat = FP24, mode: str = "conservative",
                 sim: str = "icarus", testers=None, reduce: bool = False,
                 port: str | None = None, baudrate: int | None = None) -> Backend:
    """A backend by name (``float64``, ``model``, ``rtl``, ``board``) in a render ``mode``
    (:func:`raplas_hdl.host.modes.get_mode`; the float64 backend has only ``paper``'s);
    ``reduce``: through the unit built with the on-chip reduction (model and rtl; a board
    is built with it or not, and ``reduce`` True asks for a board built with it);
    ``port``, ``baudrate``: the board's serial port.

    Raises
    ------
    ValueError
        For an unknown name, or ``reduce`` where it does not apply.
    BackendUnavailable
        For ``rtl`` when the simulator or the unit's driver is missing.
    """
    if name == "float64":
        if reduce:
            raise ValueError("the float64 backend has no unit to reduce on: use --backend "
                             "model or rtl with --reduce")
        return Float64Backend()
    if name == "model":
        return ModelBackend(fmt, mode, testers, reduce=reduce)
    if name == "rtl":
        return RtlBackend(fmt, mode, testers, sim=sim, reduce=reduce)
    if name == "board":
        if not port:
            raise ValueError("the board backend needs the board's serial port (--port)")
        return BoardBackend(port, fmt, mode, baudrate=baudrate, reduce=reduce or None)
    raise ValueError(f"unknown backend {name!r}: use one of {', '.join(BACKENDS)}")
