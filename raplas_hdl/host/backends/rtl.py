"""The ``rtl`` backend: the Verilog of the intersection unit, simulated, behind the unit's
host side (:class:`~raplas_hdl.host.backends.unit.UnitBackend`, which the model backend
shares)."""

from __future__ import annotations

import contextlib
import importlib
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ...fp.format import FP24, FPFormat
from ...model.memory_image import as_run
from ...model.records import COUNTERS
from .base import BackendUnavailable
from .unit import UnitBackend


def _fill_counters(results):
    """Zero counters for the runs of an overlapped round that have none of their own."""
    return [(stream, counters if counters is not None else dict.fromkeys(COUNTERS.names, 0))
            for stream, counters in results]


class RtlBackend(UnitBackend):
    """The Verilog of the intersection unit, simulated (Icarus or Verilator).

    The host side (memories, hierarchy test, pair order) is the model backend's
    (:class:`~raplas_hdl.host.backends.unit.UnitBackend`); the render mode folds the runs'
    streams (:meth:`stream`) or, with ``reduce``, the unit's answers. The runs go
    through live simulations of the unit (:class:`raplas_hdl.sim.drive.unit_harness.UnitSession`):
    ``instances`` per unit configuration a render needs (the primary and the shadow bundle
    sizes), started on first use with the scene loaded once each, then fed one round of
    runs per :meth:`stream` call, the round's runs cut into :attr:`CHUNKS` contiguous shares
    per instance (by their sphere counts), each simulated by the first instance free; the
    results are put back in run order, and each run's stream and counters do not depend on
    the runs simulated before it, so they are those of one instance. A :meth:`stream` share
    is an overlapped round (the unit takes the next command while a run goes, as the
    hardware's host would: the bunny 256x256 certified frame's shadow pass takes 32.9 M
    clocks, 40.4 M with a drain after every run); its counters are then the share's totals,
    on its last run (:meth:`UnitBackend.run_runs`). The simulator builds
    are cached on disk across renders. A new scene (:meth:`load`) or :meth:`close` ends the
    sessions. With waveforms asked for (``WAVES=1``, ``render --waves``) the runs go
    through the per-cycle cocotb driver (:func:`raplas_hdl.sim.drive.unit_driver.run_runs`,
    one simulation per round) instead.

    Raises
    ------
    BackendUnavailable
        At construction, when the simulator, or the unit's driver, is missing.
    """

    name = "rtl"
    runs_compiled = False
    DRIVER = "raplas_hdl.sim.drive.unit_harness"

    #: Live simulations per unit configuration by default: one per core, at most two (a
    #: render's passes are sequential, so two cover its rounds; the host needs the rest).
    DEFAULT_INSTANCES = max(1, min(2, os.cpu_count() or 1))
    #: Shares of a round per instance (:meth:`run_runs`); the bunny 256x256 certified frame
    #: took 144.5 s with one share per instance, 133.7 s with 4, 127.2 s with 8 and 129.5 s
    #: with 16 (one run each, benchmarks/bench_rtl_render.py, before the shares were
    #: overlapped rounds).
    CHUNKS = 8

    def __init__(self, fmt: FPFormat = FP24, mode: str = "conservative", testers=None,
                 margin_scale: int = 1, sim: str = "icarus", reduce: bool = False,
                 instances: int | None = None):
        super().__init__(fmt, mode, testers, margin_scale, reduce)
        instances = self.DEFAULT_INSTANCES if instances is None else instances
        if not isinstance(instances, int) or instances < 1:
            raise ValueError(f"instances must be a positive integer, not {instances!r}")
        self.instances = instances
        self._pool = None
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
        #: per configuration: clock cycles (summed over its instances), scene-load cycles
        #: (summed) and seconds (the slowest instance), rounds (summed), ``rounds_s`` (wall
        #: seconds in the rounds: sending jobs, simulating, decoding) and ``instances``
        self.session_stats = {}
        #: a directory to record each session's op stream in (``<rows>x<cols>.<k>.ops`` for
        #: instance ``k``; the benchmark replays them without a host), or None
        self.record_dir = None

    def describe(self):
        return (f"{self.name} ({self.sim}) {self.fmt} {self.render_mode.name}"
                + (" reduce" if self.reduce else ""))

    def load(self, tris, tree, bound):
        self.close()
        return super().load(tris, tree, bound)

    def _map(self, fn, items):
        """``[fn(x) for x in items]``, at once on the backend's threads when more than one
        (the simulators run in processes of their own; the threads wait on them)."""
        if len(items) == 1:
            return [fn(items[0])]
        if self._pool is None:
            self._pool = ThreadPoolExecutor(self.instances, thread_name_prefix="rtl-session")
        return list(self._pool.map(fn, items))

    def sessions(self, config):
        """The live simulations of ``config`` (started, and the scene loaded into each, on
        first use)."""
        ss = self._sessions.get(config)
        if ss is None:
            def start(k):
                record = None
                if self.record_dir is not None:
                    Path(self.record_dir).mkdir(parents=True, exist_ok=True)
                    record = Path(self.record_dir) / f"{config.rows}x{config.cols}.{k}.ops"
                return self._driver.UnitSession(self.sim, config, self.scene_memory,
                                                record=record)

            # the first alone: it emits and builds the harness (cached on disk), which two
            # threads of one process would race on; the others then start at once
            first = start(0)
            ss = self._sessions[config] = [first] + (
                self._map(start, list(range(1, self.instances))) if self.instances > 1 else [])
            self.session_stats[config] = {
                "cycles": sum(s.cycles for s in ss), "load_cycles": sum(s.load_cycles for s in ss),
                "load_s": max(s.load_s for s in ss), "rounds": sum(s.rounds for s in ss),
                "rounds_s": 0.0, "instances": len(ss)}
        return ss

    def session(self, config):
        """The first live simulation of ``config`` (:meth:`sessions`)."""
        return self.sessions(config)[0]

    def _shares(self, runs, parts: int | None = None):
        """``runs`` cut into at most ``parts`` (default :attr:`instances`) contiguous shares
        of about equal sphere counts (a run without a sphere list counts every sphere)."""
        n = min(self.instances if parts is None else parts, len(runs))
        if n <= 1:
            return [list(runs)]
        weight = np.array([1 + (self.scene_memory.n_spheres if r[1] is None
                                else np.asarray(r[1]).size) for r in runs], np.float64)
        cum = np.cumsum(weight)
        cuts = np.searchsorted(cum, cum[-1] * np.arange(1, n) / n, side="right")
        edges = [0, *np.clip(cuts, 1, len(runs) - 1).tolist(), len(runs)]
        return [list(runs[a:b]) for a, b in zip(edges, edges[1:]) if b > a]

    def run_runs(self, config, runs, overlap: bool = False):
        """``(stream, counters)`` per run (:meth:`UnitBackend.run_runs`). With ``overlap``
        each share of the round is one overlapped round of its simulation (the next command
        while a run goes, no drain between runs): its counters, read once at its end, go on
        its last run and zeros on the others; the streams are those of runs one at a time."""
        if os.environ.get("WAVES", "") not in ("", "0"):
            # waveforms (render --waves): the per-cycle cocotb driver, which records them
            from raplas_hdl.sim.drive.unit_driver import run_runs    # lazy: cocotb

            return _fill_counters(run_runs(self.sim, config, self.scene_memory, runs,
                                           overlap=overlap))
        ss = self.sessions(config)
        runs = [as_run(r) for r in runs]
        t0 = time.perf_counter()
        if len(ss) == 1:
            parts = [ss[0].run(runs, overlap=overlap)]
        else:
            # CHUNKS shares per instance, each taken by the first instance free: a share
            # that simulates longer than its sphere count said no longer holds the round
            shares = self._shares(runs, len(ss) * self.CHUNKS)
            parts = [None] * len(shares)
            order = iter(range(len(shares)))
            lock = threading.Lock()

            def serve(k):
                while True:
                    with lock:
                        i = next(order, None)
                    if i is None:
                        return
                    parts[i] = ss[k].run(shares[i], overlap=overlap)

            self._map(serve, list(range(min(len(ss), len(shares)))))
        st = self.session_stats[config]
        st.update(cycles=sum(s.cycles for s in ss), rounds=sum(s.rounds for s in ss))
        st["rounds_s"] += time.perf_counter() - t0
        return _fill_counters([res for part in parts for res in part])

    def close(self):
        """End every live simulation (a later run starts a new one)."""
        sessions, self._sessions = self._sessions, {}
        for ss in sessions.values():
            for s in ss:
                s.close()
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True)

    def __del__(self):
        with contextlib.suppress(Exception):   # interpreter shutdown
            self.close()

    def warm_pass(self, *args, **kwargs) -> float:
        """Nothing to compile on the host side (the simulator builds on first use)."""
        return 0.0
