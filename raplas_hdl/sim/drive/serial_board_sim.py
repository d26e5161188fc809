"""The simulated board: the serial board design under Verilator, its UART on a
pseudo-terminal.

:class:`SimulatedBoard` emits :class:`~raplas_hdl.rtl.serial_board.SerialBoard` (the
UARTBone bridge, the board top and the unit) for a
:class:`~raplas_hdl.model.config.UnitConfig`, builds it with the C++ main
``raplas_hdl/sim/build/serial_board_main.cpp`` and starts it. That main clocks the design
and drives its ``rx`` pin bit by bit from a pseudo-terminal and decodes ``tx`` back, so
:attr:`SimulatedBoard.port` is a port name that the unmodified host side opens as it would
a board's (``raplas-hdl render --backend board --port PORT``,
:class:`~raplas_hdl.link.serial_bus.SerialBus`, LiteX's ``litex_server --uart``). No Python
runs in the clock loop. ``raplas-hdl board-sim`` starts one from the command line.

The UART runs at :data:`SIM_DIVISOR` clocks per bit (a board's is its clock over its baud
rate: 20 at 60 MHz and 3 Mbaud), so a byte takes 40 clocks, and the bridge drops an
incomplete command after :data:`SIM_TIMEOUT` clocks.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

from raplas_hdl.model.config import UnitConfig
from raplas_hdl.rtl.emit import emit_verilog
from raplas_hdl.sim.build.runner import build_plain_verilator, require_simulator, simulator_env
from raplas_hdl.sim.drive.board_sim import board_digest, cached_verilog

__all__ = ["SimulatedBoard", "serial_board_verilog", "SIM_BAUD", "SIM_DIVISOR", "SIM_TIMEOUT",
           "TOPLEVEL"]

TOPLEVEL = "serial_board"
#: Clocks per bit of the simulated UART (the receiver's least).
SIM_DIVISOR = 4
#: The simulated line's rate for the host (``SerialBus``, ``render --baud``): a byte is
#: 40 clocks, and the whole 8x8 unit simulates at about 0.1-0.2 M clocks/s, so 2.5-5 kbytes
#: a second; a lower rate only makes the host wait longer before it calls a byte lost.
SIM_BAUD = 10_000
#: Clocks without a byte after which the simulated bridge drops a command: 2**20 clocks
#: (several seconds of simulation; longer than the host's pauses between a command's bytes).
SIM_TIMEOUT = 1 << 20
_MAIN = "serial_board_main.cpp"


def serial_board_verilog(config: UnitConfig, divisor: int = SIM_DIVISOR,
                         timeout: int = SIM_TIMEOUT) -> str:
    """The serial board's Verilog (module ``serial_board``), cached with the board top's key,
    the divisor and the timeout."""
    key = hashlib.sha256(json.dumps([board_digest(config), divisor, timeout]).encode())

    def emit():
        from raplas_hdl.rtl.serial_board import SerialBoard

        design = SerialBoard(config, divisor, timeout=timeout)
        return emit_verilog(design, TOPLEVEL, config.params())[0]

    return cached_verilog(TOPLEVEL, key.hexdigest()[:16], emit)


class SimulatedBoard:
    """A :class:`~raplas_hdl.rtl.serial_board.SerialBoard` simulated by Verilator behind a
    pseudo-terminal (module docstring); a context manager, or call :meth:`close`.

    Parameters
    ----------
    config : UnitConfig
        The unit's build.
    divisor, timeout : int
        The UART's clocks per bit; the bridge's command timeout in clocks.
    start_s : float
        Seconds to wait for the simulation to open its terminal (after the build).

    Attributes
    ----------
    port : str
        The pseudo-terminal's name.
    build_s : float
        Seconds spent emitting and building (0 when cached).

    Raises
    ------
    SimulatorNotFound
        When Verilator is missing.
    RuntimeError
        When the simulation does not start (its log's tail in the message).
    """

    def __init__(self, config: UnitConfig, divisor: int = SIM_DIVISOR,
                 timeout: int = SIM_TIMEOUT, *, start_s: float = 30.0):
        require_simulator("verilator")
        self.config, self.divisor = config, divisor
        t0 = time.monotonic()
        text = serial_board_verilog(config, divisor, timeout)
        exe = build_plain_verilator(
            text, TOPLEVEL, f"serial-board-{config.fmt.name}-{config.rows}x{config.cols}",
            main=_MAIN)
        self.build_s = time.monotonic() - t0
        self._dir = Path(tempfile.mkdtemp(prefix="raplas-board-sim-"))
        name_file = self._dir / "pty"
        self._log = open(self._dir / "sim.log", "wb")  # noqa: SIM115 - closed by close()
        self._proc = subprocess.Popen(
            [str(exe), f"+PTY_NAME={name_file}", f"+DIVISOR={int(divisor)}"],
            stdin=subprocess.PIPE, stdout=self._log, stderr=subprocess.STDOUT,
            cwd=self._dir, env=simulator_env("verilator"))
        deadline = time.monotonic() + start_s
        while not name_file.exists():
            if self._proc.poll() is not None or time.monotonic() > deadline:
                tail = self._tail()
                self.close()
                raise RuntimeError(f"the simulated board did not start: {tail}")
            time.sleep(0.01)
        self.port = name_file.read_text().strip()

    def _tail(self) -> str:
        self._log.flush()
        text = (self._dir / "sim.log").read_text(errors="replace").strip()
        return text[-500:] or "(no output)"

    @property
    def alive(self) -> bool:
        return self._proc.poll() is None

    def close(self) -> str:
        """Stop the simulation (its standard input closes); returns its last line
        (``cycles N bytes_in N bytes_out N``)."""
        if self._proc.stdin and not self._proc.stdin.closed:
            self._proc.stdin.close()
        try:
            self._proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        self._log.close()
        last = (self._dir / "sim.log").read_text(errors="replace").strip().splitlines()
        shutil.rmtree(self._dir, ignore_errors=True)
        return last[-1] if last else ""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
