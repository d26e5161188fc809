"""The ``board`` backend: the intersection unit on a board (or the simulated board) behind a
serial port, under the unit's host side
(:class:`~raplas_hdl.host.backends.unit.UnitBackend`, which the model and rtl backends
share).

The port speaks LiteX's UARTBone protocol to the UARTBone bridge of
:class:`~raplas_hdl.rtl.serial_board.SerialBoard` (:class:`~raplas_hdl.link.serial_bus.SerialBus`),
and :class:`~raplas_hdl.link.driver.BoardDriver` runs the register map. A board is one build:
its format, mode, reduction, bundle lattice, ``tris_per_sphere`` and memory depths are
fixed, read from its configuration registers when the port opens, and checked against what
the render asks for before any work (:meth:`BoardBackend.check_settings`,
:meth:`BoardBackend.load`), each difference named in one line. The scene is written into the
board's memories once per render; after it, and after every round of runs, the link's CRC
and error counts are compared (:meth:`~raplas_hdl.link.serial_bus.SerialBus.check`), so a
corrupted or lost word fails the render instead of changing it.
"""

from __future__ import annotations

import time

from ...fp.format import FP24, FPFormat
from ..modes import get_mode
from .base import BackendUnavailable
from .unit import UnitBackend

__all__ = ["BoardBackend"]


class BoardBackend(UnitBackend):
    """The unit on a board behind ``port``.

    Parameters
    ----------
    port : str
        The serial port (``/dev/ttyUSB0``, or the simulated board's pseudo-terminal).
    fmt : FPFormat
        The format the render asks for: it must be the board's.
    mode : str
        The render mode: its unit mode must be the board's.
    baudrate : int
        The line's rate (the simulated board ignores it).
    reduce : bool or None
        None: as the board is built; True or False: it must be built so.
    timeout : float
        Seconds to wait for an answer on the link.

    Raises
    ------
    BackendUnavailable
        When pyserial is missing, the port cannot be opened, no bridge answers, or the
        board is another build than the render asks for (one line naming the difference).
    """

    name = "board"
    runs_compiled = False

    def __init__(self, port: str, fmt: FPFormat = FP24, mode: str = "certified", *,
                 baudrate: int | None = None, reduce: bool | None = None,
                 timeout: float = 2.0):
        from ...link.driver import BoardDriver, BoardMismatch
        from ...link.serial_bus import DEFAULT_BAUD, LinkError, SerialBus

        try:
            bus = SerialBus(port, baudrate or DEFAULT_BAUD, timeout=timeout)
        except LinkError as exc:
            raise BackendUnavailable(str(exc)) from None
        try:
            bus.identify()
            bus.clear()
            driver = BoardDriver(bus)
        except (LinkError, BoardMismatch) as exc:
            bus.close()
            raise BackendUnavailable(f"board on {port}: {exc}") from None
        board = driver.config
        unit_mode = get_mode(mode).unit_mode
        problems = []
        if board.fmt != fmt:
            problems.append(f"its format is {board.fmt.name}, the render asks for {fmt.name}")
        if board.mode != unit_mode:
            problems.append(f"its unit is {board.mode!r}, --mode {get_mode(mode).name} needs "
                            f"{unit_mode!r}")
        if reduce is not None and bool(reduce) != board.reduce:
            problems.append("it is built " + ("with" if board.reduce else "without")
                            + " the on-chip reduction")
        if problems:
            bus.close()
            raise BackendUnavailable(f"board on {port} is another build: "
                                     + "; ".join(problems))
        super().__init__(fmt, mode, board.testers, board.margin_scale, board.reduce)
        self.port, self.bus, self.driver, self.board_config = port, bus, driver, board
        self._loaded = False
        #: what crossed the link: seconds in the scene load and in the runs, runs, rounds
        self.link_stats = {"load_s": 0.0, "runs_s": 0.0, "runs": 0, "rounds": 0}

    def describe(self):
        c = self.board_config
        return (f"board ({self.port}, {c.rows}x{c.cols}) {self.fmt} {self.render_mode.name}"
                + (" reduce" if self.reduce else ""))

    # -- the build against the render -----------------------------------------------------
    def check_settings(self, settings) -> None:
        """Raise ``ValueError`` (one line) when a bundle lattice of ``settings``, or its
        triangles per sphere, is not the board's."""
        c = self.board_config
        lattices = {"--tile": (settings.rows, settings.cols),
                    "--shadow": (settings.shadow_rows, settings.shadow_cols),
                    "--glossy": (settings.glossy_rows, settings.glossy_cols),
                    "--ao": (settings.ao_rows, settings.ao_cols)}
        for opt, (r, cc) in lattices.items():
            if r and (r, cc) != (c.rows, c.cols):
                off = "" if opt == "--tile" else f", or {opt} 0x0"
                raise ValueError(f"the board's unit takes {c.rows}x{c.cols} bundles, not "
                                 f"{r}x{cc} ({opt}): use {opt} {c.rows}x{c.cols}{off}")
        if settings.tris_per_sphere != c.tris_per_sphere:
            raise ValueError(f"the board's unit holds {c.tris_per_sphere} triangles per "
                             f"sphere, not {settings.tris_per_sphere}: use --tris-per-sphere "
                             f"{c.tris_per_sphere}")

    def config(self, rows, cols):
        c = self.board_config
        if (rows, cols) != (c.rows, c.cols):
            raise ValueError(f"the board's unit takes {c.rows}x{c.cols} bundles, not "
                             f"{rows}x{cols}")
        return c

    def load(self, tris, tree, bound):
        c = self.board_config
        if len(tris) > c.max_triangles:
            raise ValueError(f"the scene has {len(tris):,} triangles; the board's Triangle "
                             f"Memory holds {c.max_triangles:,} (a bigger build, or a "
                             "smaller scene)")
        if tree.n_leaves > c.max_spheres:
            raise ValueError(f"the scene needs {tree.n_leaves:,} leaf spheres; the board's "
                             f"Sphere Memory holds {c.max_spheres:,} (a bigger build, more "
                             "--tris-per-sphere, or a smaller scene)")
        rep = super().load(tris, tree, bound)
        self._loaded = False
        return rep

    # -- runs -------------------------------------------------------------------------------
    def run_runs(self, config, runs, overlap: bool = False):
        """``(stream, counters)`` per run, through the board (one run at a time, each
        bundle written while the run before it goes: ``overlap`` changes nothing); the
        link is checked after the scene load and after the round."""
        runs = list(runs)
        if not runs:
            return []
        if not self._loaded:
            t0 = time.perf_counter()
            self.driver.load_scene(self.scene_memory)
            self.bus.check()
            self._loaded = True
            self.link_stats["load_s"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        results = self.driver.run_runs(runs)
        self.bus.check()
        st = self.link_stats
        st["runs_s"] += time.perf_counter() - t0
        st["runs"] += len(runs)
        st["rounds"] += 1
        return results

    def report(self, stats):
        super().report(stats)
        b = self.bus
        stats["link"] = {**self.link_stats, "words_written": b.words_written,
                         "words_read": b.words_read, "round_trips": b.round_trips,
                         "bytes_out": b.bytes_out, "bytes_in": b.bytes_in}

    def warm_pass(self, *args, **kwargs) -> float:
        """Nothing to compile on the host side."""
        return 0.0

    def close(self):
        self.bus.close()
