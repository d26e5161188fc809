"""The ``rtl`` backend: the Verilog of the intersection unit, simulated, behind the unit's
host side (:class:`~raplas_hdl.host.backends.unit.UnitBackend`, which the model backend
shares)."""

from __future__ import annotations

import contextlib
import importlib
import os
import time
from pathlib import Path

from ...fp.format import FP24, FPFormat
from .base import BackendUnavailable
from .unit import UnitBackend


class RtlBackend(UnitBackend):
    """The Verilog of the intersection unit, simulated (Icarus or Verilator).

    The host side (memories, hierarchy test, pair order) is the model backend's
    (:class:`~raplas_hdl.host.backends.unit.UnitBackend`); the render mode folds the runs'
    streams (:meth:`stream`) or, with ``reduce``, the unit's answers. The runs go
    through live simulations of the unit (:class:`raplas_hdl.sim.drive.unit_harness.UnitSession`):
    one per unit configuration a render needs (the primary and the shadow bundle sizes),
    started on first use with the scene loaded once, then fed one round of runs per
    :meth:`stream` call; the simulator builds are cached on disk across renders. A new
    scene (:meth:`load`) or :meth:`close` ends the sessions. With waveforms asked for
    (``WAVES=1``, ``render --waves``) the runs go through the per-cycle cocotb driver
    (:func:`raplas_hdl.sim.drive.unit_driver.run_runs`, one simulation per round) instead.

    Raises
    ------
    BackendUnavailable
        At construction, when the simulator, or the unit's driver, is missing.
    """

    name = "rtl"
    runs_compiled = False
    DRIVER = "raplas_hdl.sim.drive.unit_harness"

    def __init__(self, fmt: FPFormat = FP24, mode: str = "conservative", testers=None,
                 margin_scale: int = 1, sim: str = "icarus", reduce: bool = False):
        super().__init__(fmt, mode, testers, margin_scale, reduce)
        try:    # lazy: the simulator side loads only for an rtl render
            from raplas_hdl.sim.build.runner import SimulatorNotFound, require_simulator
        except ImportError as exc:
            raise BackendUnavailable(
                f"the rtl backend needs the raplas_hdl.sim package: {exc}") from exc
        try:
            require_simulator(sim)
        except SimulatorNotFound as exc:
            raise BackendUnavailable(str(exc)) from exc
        except ValueError as exc:
            raise BackendUnavailable(f"unknown simulator {sim!r}: {exc}") from exc
        try:
            self._driver = importlib.import_module(self.DRIVER)
        except ImportError as exc:
            raise BackendUnavailable(
                f"the rtl backend needs the intersection unit's driver "
                f"({self.DRIVER.replace('.', '/')}.py with UnitSession), which is not "
                f"available: {exc}") from exc
        if not hasattr(self._driver, "UnitSession"):
            raise BackendUnavailable(f"{self.DRIVER} has no UnitSession; the rtl backend "
                                     f"cannot drive the unit")
        self.sim = sim
        self._sessions = {}
        #: per configuration: clock cycles, scene-load cycles and seconds, rounds, and
        #: ``rounds_s`` (wall seconds in the rounds: sending jobs, simulating, decoding)
        self.session_stats = {}
        #: a directory to record each session's op stream in (``<rows>x<cols>.ops``; the
        #: benchmark replays them without a host), or None
        self.record_dir = None

    def describe(self):
        return (f"{self.name} ({self.sim}) {self.fmt} {self.render_mode.name}"
                + (" reduce" if self.reduce else ""))

    def load(self, tris, tree, bound):
        self.close()
        return super().load(tris, tree, bound)

    def session(self, config):
        """The live simulation of ``config`` (started, and the scene loaded, on first use)."""
        s = self._sessions.get(config)
        if s is None:
            record = None
            if self.record_dir is not None:
                Path(self.record_dir).mkdir(parents=True, exist_ok=True)
                record = Path(self.record_dir) / f"{config.rows}x{config.cols}.ops"
            s = self._sessions[config] = self._driver.UnitSession(self.sim, config,
                                                                   self.scene_memory,
                                                                   record=record)
            self.session_stats[config] = {"cycles": s.cycles, "load_cycles": s.load_cycles,
                                          "load_s": s.load_s, "rounds": s.rounds,
                                          "rounds_s": 0.0}
        return s

    def run_runs(self, config, runs):
        if os.environ.get("WAVES", "") not in ("", "0"):
            # waveforms (render --waves): the per-cycle cocotb driver, which records them
            from raplas_hdl.sim.drive.unit_driver import run_runs    # lazy: cocotb

            return run_runs(self.sim, config, self.scene_memory, runs)
        s = self.session(config)
        t0 = time.perf_counter()
        out = s.run(runs)
        st = self.session_stats[config]
        st.update(cycles=s.cycles, rounds=s.rounds)
        st["rounds_s"] += time.perf_counter() - t0
        return out

    def close(self):
        """End every live simulation (a later run starts a new one)."""
        sessions, self._sessions = self._sessions, {}
        for s in sessions.values():
            s.close()

    def __del__(self):
        with contextlib.suppress(Exception):   # interpreter shutdown
            self.close()

    def warm_pass(self, *args, **kwargs) -> float:
        """Nothing to compile on the host side (the simulator builds on first use)."""
        return 0.0
