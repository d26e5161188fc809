"""Co-simulation of every unit against the golden model, behind one interface.

``raplas-hdl cosim`` drives every unit through its :class:`UnitCosim`
(:func:`unit_cosim`), mostly at full clock rate with no Python per cycle:

``fp-add``, ``fp-mul``
    The batch harness of :mod:`raplas_hdl.sim.build.harness` around the unit, random gaps in
    ``i_valid`` and stalls on ``en``; with the driver ``percycle`` the cocotb driver
    (:class:`raplas_hdl.sim.tb.stream.StreamTB`) instead (:mod:`.fp`).
``ray-triangle``
    The batch harness around the unit's streams (``i`` a packed
    :data:`~raplas_hdl.model.records.PAIR`, ``o`` a
    :data:`~raplas_hdl.model.records.RT_RESULT`), random gaps in ``i.valid`` (held until
    taken) and random back-pressure on ``o.ready``.
``plane-sphere-tester``, ``plane-sphere``
    The same harness around a generated wrapper (:func:`plane_wrapper_verilog`) whose input
    vector is the plane(s) and one sphere. The wrapper keeps the unit's drain rule: when a
    vector brings other planes than the loaded ones, it stops taking spheres, waits until
    nothing is in flight, writes the planes (one per clock) and goes on. The tester's clock
    enable is the output's ready (a held pipeline holds its result).
``intersection-unit``
    A live session of :mod:`raplas_hdl.sim.drive.unit_harness` (scene by backdoor, runs
    through the op stream, results decoded in bulk); a case is one run (a bundle against a
    list of spheres) and every field of every result beat and every counter is compared.
    With ``--waves`` the per-cycle cocotb driver
    (:func:`raplas_hdl.sim.drive.unit_driver.run_runs`) runs instead, as ``render --waves``
    does.
``reducer``
    The reduction alone in the batch harness
    (:mod:`raplas_hdl.sim.drive.reducer_harness`): a case is a random run (result beats and
    a window), every field of every answer compared; random cases only.
``board-top``
    The board top under the host's driver on its Wishbone port
    (:mod:`raplas_hdl.sim.drive.board_sim`), the cases and comparison of
    ``intersection-unit``.

Each unit is a :class:`UnitCosim`: its random cases (seeded), the model's expected results,
its vectors file (:mod:`.vectors`; docs/cosim.md), the simulation and the comparison of
every output field. With ``target="virtex4"`` the units' multipliers are DSP48 primitives
and Yosys's DSP48 model (:func:`raplas_hdl.rtl.dsp48.dsp48_sim_model`) is appended to the
simulated text.
"""

from __future__ import annotations

from .base import RT_ID_BITS, SPHERE_ID_BITS, UnitCosim, compare, unit_verilog
from .board import BoardCosim
from .fp import FPAddCosim, FPMulCosim
from .intersection import IntersectionCosim
from .plane_sphere import ArrayCosim, TesterCosim, plane_wrapper_verilog
from .ray_triangle import RayTriangleCosim
from .reducer import ReducerCosim

__all__ = ["COSIM_UNITS", "ArrayCosim", "BoardCosim", "FPAddCosim", "FPMulCosim",
           "IntersectionCosim", "RT_ID_BITS", "RayTriangleCosim", "ReducerCosim",
           "SPHERE_ID_BITS", "TesterCosim", "UnitCosim", "compare", "plane_wrapper_verilog",
           "unit_cosim", "unit_verilog"]

_CLASSES = {c.name: c for c in (FPAddCosim, FPMulCosim, TesterCosim, ArrayCosim,
                                RayTriangleCosim, IntersectionCosim, ReducerCosim, BoardCosim)}
#: The units co-simulated, by name.
COSIM_UNITS = tuple(_CLASSES)


def unit_cosim(name: str, fmt, options: dict, driver: str = "batch") -> UnitCosim:
    """The :class:`UnitCosim` of unit ``name`` with ``options`` (None: default), run by
    ``driver`` (``"batch"``, or ``"percycle"`` for the FP units)."""
    try:
        cls = _CLASSES[name]
    except KeyError:
        raise ValueError(f"unit must be one of {', '.join(COSIM_UNITS)}, not {name!r}") \
            from None
    return cls(fmt, options, driver)
