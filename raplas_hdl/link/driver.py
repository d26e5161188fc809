"""Host driver of the board-level top (:class:`raplas_hdl.rtl.board_top.BoardTop`).

The driver speaks to an abstract 32-bit bus: any object with ``read(addr) -> int`` and
``write(addr, value)``, ``addr`` being a *word* address of the register map
(:data:`raplas_hdl.model.board_map.REGISTER_MAP`). Behind it may be the co-simulation's
Wishbone master (``raplas_hdl/sim/tb/board.py``), a UART or PCIe bridge to a board, or a
test double.
A bus that cannot complete an access (Wishbone ``err``) raises an exception from
``read``/``write``; the driver lets it through.

It loads a scene and bundles through the memory window, starts runs, pops the result
stream and reads the counters, and returns them in the form of
:func:`raplas_hdl.model.intersection.run_bundle` (a
:data:`~raplas_hdl.model.intersection.RESULT_DTYPE` array, or the dtype of the build's
output record in certified mode or with the on-chip reduction, and a
counter dict, here with ``cycles`` too), so the two compare directly.

No Amaranth, no cocotb.
"""

from __future__ import annotations

import numpy as np

from ..fp.format import FPFormat
from ..model.board_map import (BOARD_ID, CONTROL_BITS, COUNTER_REGS, MAP_VERSION,
                               REGISTERS, RES_INFO_BITS, RESULT_REGS, STATUS_BITS,
                               cmd_start_word, config_from_words, config_words,
                               decode_result_words, result_beats)
from ..model.config import UnitConfig
from ..model.memory_image import (BundleMemory, Run, SceneMemory, as_run, bundle_writes,
                                  run_list_writes, scene_writes)

__all__ = ["BoardDriver", "BoardMismatch"]

_VALID = 1 << RES_INFO_BITS["valid"]
#: The identification registers and the counters, each a run of consecutive addresses (read
#: as one burst where the bus can).
_IDENT = ("ID", "VERSION", *config_words(UnitConfig().params()))
_COUNTERS = tuple(COUNTER_REGS.values())
for _run in (_IDENT, _COUNTERS, ("RES_INFO", *RESULT_REGS)):
    assert [REGISTERS[n] - REGISTERS[_run[0]] for n in _run] == list(range(len(_run)))


class BoardMismatch(ValueError):
    """The board is not the build the driver expects (ID, map version or parameters)."""


def _config_from_params(p: dict) -> UnitConfig:
    return UnitConfig(fmt=FPFormat(p["exp_bits"], p["man_bits"], p["rounding"]),
                      rows=p["rows"], cols=p["cols"], testers=p["testers"],
                      tris_per_sphere=p["tris_per_sphere"], max_triangles=p["max_triangles"],
                      max_spheres=p["max_spheres"], mode=p["mode"],
                      margin_scale=p["margin_scale"], fifo_depth=p["fifo_depth"],
                      lanes=p.get("lanes", 1), reduce=p.get("reduce", False))


def _same_geometry(a: BundleMemory, b: BundleMemory) -> bool:
    return a is b or all(np.array_equal(getattr(a, f), getattr(b, f))
                         for f in ("plane_n", "plane_p", "ray_o", "ray_d"))


class BoardDriver:
    """Runs scenes through a board top over a register bus.

    Parameters
    ----------
    bus : object
        ``read(addr) -> int`` and ``write(addr, value)`` on word addresses.
    config : UnitConfig, optional
        The build the caller expects; checked against the board's ID and configuration
        registers (:class:`BoardMismatch` on a difference). Without it the driver takes
        the board's own configuration.
    poll_limit : int
        Reads of a status or result register without progress after which the driver
        gives up (``TimeoutError``).

    Attributes
    ----------
    config : UnitConfig
    reads, writes : int
        Bus accesses made so far.
    """

    def __init__(self, bus, config: UnitConfig | None = None, *, poll_limit: int = 1_000_000):
        if not (callable(getattr(bus, "read", None)) and callable(getattr(bus, "write", None))):
            raise ValueError("bus must have read(addr) and write(addr, value) methods")
        self.bus = bus
        self.poll_limit = int(poll_limit)
        self.reads = 0
        self.writes = 0
        self._mem_addr = None      # what MEM_ADDR holds (None: unknown)
        self._n_spheres = None
        board = self.identify()
        if config is None:
            config = _config_from_params(board["params"])
        else:
            self.check(config, board)
        self.config = config

    # -- registers ----------------------------------------------------------------------------
    def read_reg(self, name: str) -> int:
        self.reads += 1
        return int(self.bus.read(REGISTERS[name])) & 0xFFFFFFFF

    def read_regs(self, first: str, n: int) -> list[int]:
        """``n`` registers from ``first`` up, in address order: one burst on a bus with
        ``read_burst(addr, n)`` (:class:`~raplas_hdl.link.serial_bus.SerialBus`: one round
        trip), else ``n`` reads."""
        self.reads += n
        burst = getattr(self.bus, "read_burst", None)
        addr = REGISTERS[first]
        words = burst(addr, n) if burst is not None else \
            [self.bus.read(addr + k) for k in range(n)]
        return [int(w) & 0xFFFFFFFF for w in words]

    def write_reg(self, name: str, value: int) -> None:
        self.writes += 1
        self.bus.write(REGISTERS[name], int(value) & 0xFFFFFFFF)

    def identify(self) -> dict:
        """``{"id", "version": (major, minor), "params"}`` as the board reports them."""
        words = dict(zip(_IDENT, self.read_regs(_IDENT[0], len(_IDENT))))
        version = words["VERSION"]
        return {"id": words["ID"], "version": (version >> 16, version & 0xFFFF),
                "params": config_from_words(words)}

    def check(self, config: UnitConfig, board: dict | None = None) -> None:
        """Raise :class:`BoardMismatch` naming every difference from ``config``."""
        board = self.identify() if board is None else board
        if board["id"] != BOARD_ID:
            raise BoardMismatch(f"ID register reads 0x{board['id']:08X}, not the board top's "
                                f"0x{BOARD_ID:08X}: is this a raplas-hdl board top?")
        if board["version"][0] != MAP_VERSION[0]:
            raise BoardMismatch(f"register map version {board['version']} is not "
                                f"{MAP_VERSION[0]}.x, which this driver speaks")
        # lanes and reduce appear only when not the default (1, False)
        default = {"lanes": 1, "reduce": False}
        want = {**default, **config.params()}
        want["margin_scale"] &= 0xFFFFFFFF
        got = {**default, **board["params"]}
        diff = [f"{k}: board {got.get(k)!r}, expected {want[k]!r}" for k in want
                if got.get(k) != want[k]]
        if diff:
            raise BoardMismatch("the board is another build: " + "; ".join(diff))

    def status(self) -> dict:
        """``STATUS`` as a dict of booleans (:data:`STATUS_BITS`)."""
        word = self.read_reg("STATUS")
        return {name: bool(word >> bit & 1) for name, bit in STATUS_BITS.items()}

    # -- memories -----------------------------------------------------------------------------
    def write_words(self, addrs, datas) -> None:
        """Write ``datas[k]`` at unit address ``addrs[k]`` through the memory window.

        ``MEM_ADDR`` is written only when the next address is not the one the window's
        auto-increment already holds.
        """
        addrs = np.asarray(addrs, dtype=np.uint64).reshape(-1)
        datas = np.asarray(datas, dtype=np.uint64).reshape(-1)
        if addrs.shape != datas.shape:
            raise ValueError("addrs and datas must have the same length")
        for a, d in zip(addrs.tolist(), datas.tolist()):
            if a != self._mem_addr:
                self.write_reg("MEM_ADDR", a)
            self.write_reg("MEM_DATA", d)
            self._mem_addr = (a + 1) & 0xFFFFFFFF

    def load_scene(self, scene: SceneMemory) -> None:
        """Write Triangle Memory and Sphere Memory (no run may be going)."""
        self.write_words(*scene_writes(self.config, scene))
        self._n_spheres = scene.n_spheres

    def load_bundle(self, bundle: BundleMemory, bank: int = 0, enable_only: bool = False):
        """Write a bundle's planes and rays (or only the enable bits) into ``bank``."""
        self.write_words(*bundle_writes(self.config, bundle, bank, enable_only=enable_only))

    def load_run_list(self, sphere_ids, bank: int = 0) -> None:
        self.write_words(*run_list_writes(self.config, sphere_ids, bank))

    # -- runs ---------------------------------------------------------------------------------
    def _poll(self, what: str, done) -> None:
        for _ in range(self.poll_limit):
            if done():
                return
        raise TimeoutError(f"{what}: no progress after {self.poll_limit} reads "
                           f"(status {self.status()})")

    def start(self, first: int, count: int, bank: int = 0, indirect: bool = False,
              keep_all: bool = False) -> None:
        """Queue a run, waiting for the command slot to be free (``keep_all``: cull
        nothing, for a bundle over the culling budget)."""
        word = cmd_start_word(count, bank, indirect, keep_all)
        self._poll("waiting for the command slot", lambda: not self.status()["cmd_full"])
        self.write_reg("CMD_FIRST", first)
        self.write_reg("CMD_START", word)

    def _pop_words(self) -> tuple | None:
        """Pop one result beat register by register: its six words (``RES_INFO`` and
        :data:`RESULT_REGS`), or None when none waits."""
        info = self.read_reg("RES_INFO")
        if not info & _VALID:
            return None
        return (info, *(self.read_reg(name) for name in RESULT_REGS))

    def pop(self) -> dict | None:
        """Pop one result beat (its fields) or return None when none waits."""
        words = self._pop_batch(1)[0]
        return None if words is None else decode_result_words(*words, self.config)

    def _pop_batch(self, k: int) -> list:
        """Up to ``k`` beats' words, ``None`` for each read that found none waiting: on a bus
        with ``read_bursts`` (the serial link) ``k`` reads of the result window in one round
        trip, else one :meth:`_pop_words`."""
        many = getattr(self.bus, "read_bursts", None)
        if many is None:
            return [self._pop_words()]
        n = 1 + len(RESULT_REGS)
        self.reads += k * n
        out = []
        for words in many([(REGISTERS["RES_INFO"], n, False)] * k):
            words = tuple(int(w) & 0xFFFFFFFF for w in words)
            out.append(words if words[0] & _VALID else None)
        return out

    def collect(self) -> np.ndarray:
        """Pop beats up to the one marked ``last``; returns them as
        :func:`~raplas_hdl.model.board_map.result_beats` gives them for the build.

        On the serial link the result window is read several times per round trip, 4 at
        first and twice as many (up to 64) after a batch that found a beat in each read: a
        read after the run's last beat finds none and pops nothing (the next run starts
        only after this one's beats are in)."""
        rows, k, empty = [], 4, 0
        while True:
            batch = self._pop_batch(k)
            for words in batch:
                if words is None:
                    empty += 1
                    continue
                rows.append(words)
                if words[0] >> RES_INFO_BITS["last"] & 1:
                    return result_beats(*np.array(rows, np.uint64).T, self.config)
            if empty >= self.poll_limit:
                raise TimeoutError(f"no result beat after {self.poll_limit} reads "
                                   f"({len(rows)} beats so far; status {self.status()})")
            k = min(64, 2 * k) if None not in batch else 4

    def read_counters(self) -> dict:
        """``cycles`` and the counters of ``run_bundle``."""
        return dict(zip(COUNTER_REGS, self.read_regs(_COUNTERS[0], len(_COUNTERS))))

    def clear_counters(self) -> None:
        self.write_reg("CONTROL", 1 << CONTROL_BITS["clear_counters"])

    def check_errors(self) -> None:
        """Raise ``RuntimeError`` if the pair FIFO overflowed or a command was refused."""
        st = self.status()
        bad = [name for name in ("fifo_overflow", "cmd_overrun") if st[name]]
        if bad:
            raise RuntimeError(f"board status flags set: {', '.join(bad)}")

    def _sphere_ids(self, sphere_ids):
        if sphere_ids is None:
            if self._n_spheres is None:
                raise ValueError("sphere_ids=None means every sphere of the scene: load the "
                                 "scene first (load_scene)")
            return np.arange(self._n_spheres, dtype=np.int64)
        ids = np.asarray(sphere_ids, dtype=np.int64).reshape(-1)
        if ids.size > self.config.max_spheres:
            raise ValueError(f"a run names at most max_spheres={self.config.max_spheres} "
                             "spheres")
        if ids.size and (ids.min() < 0 or ids.max() >= self.config.max_spheres):
            raise ValueError("sphere_ids names a sphere outside Sphere Memory "
                             f"(max_spheres={self.config.max_spheres})")
        return ids

    def _plan(self, sphere_ids, bank):
        """(writes, first, count, indirect) of a run on ``bank``."""
        ids = self._sphere_ids(sphere_ids)
        if ids.size == 0 or np.array_equal(ids, np.arange(ids[0], ids[0] + ids.size)):
            return (np.zeros(0, np.uint32), np.zeros(0, np.uint32)), \
                (int(ids[0]) if ids.size else 0), ids.size, False
        return run_list_writes(self.config, ids, bank), 0, ids.size, True

    def run_bundle(self, bundle: BundleMemory, sphere_ids=None, bank: int = 0, *,
                   keep_all: bool = False):
        """Load ``bundle`` into ``bank``, run ``sphere_ids`` (default all) against it.

        Returns ``(results, counters)`` as :func:`raplas_hdl.model.intersection.run_bundle`
        (counters of this run alone, plus ``cycles``).
        """
        return self.run_runs([Run(bundle, sphere_ids, keep_all)], first_bank=bank)[0]

    def run_runs(self, runs, scene: SceneMemory | None = None, *, prefetch: bool = True,
                 first_bank: int = 0):
        """Run ``runs`` one after another.

        A run whose bundle has the previous run's planes and rays reuses its bank and
        rewrites only the enable bits (the host's early-out); otherwise the bundle goes
        into the other bank, and with ``prefetch`` it is written while the previous run
        is still going (the unit's double buffer). A contiguous ``sphere_ids`` starts a
        range run, any other a run-list run. The counters are cleared before each run and
        read after its last beat, so they are per run.

        Parameters
        ----------
        runs : list of Run, (BundleMemory, sphere_ids) or (BundleMemory, sphere_ids, keep_all)
            See :class:`~raplas_hdl.model.memory_image.Run` (``sphere_ids`` None: every
            sphere of the loaded scene; ``keep_all``: cull nothing).
        scene : SceneMemory, optional
            Loaded first when given.

        Returns
        -------
        list of (results, counters)
        """
        if scene is not None:
            self.load_scene(scene)
        runs = list(runs)
        plans = []
        bank, prev = first_bank ^ 1, None
        for bundle, ids, keep_all in map(as_run, runs):
            bundle.check(self.config)
            enable_only = prev is not None and _same_geometry(bundle, prev)
            if not enable_only:
                bank ^= 1
            prev = bundle
            list_writes, first, count, indirect = self._plan(ids, bank)
            plans.append((bundle, bank, enable_only, list_writes, first, count, indirect,
                          keep_all))
        loaded = [False] * len(plans)

        def load(k):
            bundle, bank, enable_only, list_writes, *_ = plans[k]
            self.load_bundle(bundle, bank, enable_only=enable_only)
            self.write_words(*list_writes)
            loaded[k] = True

        out = []
        self.clear_counters()
        for k, (_, bank, _, _, first, count, indirect, keep_all) in enumerate(plans):
            if not loaded[k]:
                load(k)
            self.start(first, count, bank, indirect, keep_all)
            if prefetch and k + 1 < len(plans) and plans[k + 1][1] != bank:
                load(k + 1)
            stream = self.collect()
            counters = self.read_counters()
            self.clear_counters()
            out.append((stream, counters))
        self.check_errors()
        return out
