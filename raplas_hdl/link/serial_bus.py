"""``SerialBus``: the board's register bus over a serial port, in LiteX's UARTBone protocol.

The host side of :class:`raplas_hdl.rtl.uartbone.UARTBone` for
:class:`~raplas_hdl.link.driver.BoardDriver` (``read(addr)``, ``write(addr, value)`` on word
addresses), on ``pyserial``. The wire protocol and the link's registers are
:mod:`raplas_hdl.model.link_protocol`.

**Batching.** A UARTBone write has no reply, so writes are not sent one by one: they
gather into bursts (a run of writes to one address, such as ``MEM_DATA`` filled word after
word, becomes a *fixed* burst; a run to consecutive addresses an *incr* burst; up to 255
words each) and go out when a read needs the line, on :meth:`flush`, or when a megabyte is
waiting. Loading a scene is then a stream at the line's rate, not a round trip per word.
:meth:`read_burst` reads consecutive registers (or one register again and again) in one
round trip, and :meth:`read_bursts` several such reads (sent together, answered in order).

**Checks.** UARTBone has no checksum and no error reply. :meth:`check` reads the bridge's
``LINK_ERRORS``, ``LINK_RX`` and ``LINK_CRC`` and compares the CRC with the one this side
kept over the same words (:func:`~raplas_hdl.model.link_protocol.crc_words`), so a byte lost
or changed in either direction, or an access the board refused, raises :class:`LinkError`
rather than passing unseen; a driver calls it after each load and each result batch. A
read whose answer does not arrive within ``timeout`` seconds raises :class:`LinkError`
naming how many bytes came of how many (a byte lost on the way), and :meth:`resync` waits
out the bridge's timeout so that the next command starts clean.
"""

from __future__ import annotations

import time

import numpy as np

from ..model.link_protocol import (CMD_READ_FIXED, CMD_READ_INCR, CMD_WRITE_FIXED,
                                   CMD_WRITE_INCR, DEFAULT_BAUD, LINK_BASE, LINK_ID, LINK_REGS,
                                   LINK_SPAN, MAX_BURST, command_bytes, crc_words)

__all__ = ["SerialBus", "LinkError", "DEFAULT_BAUD"]

#: Pending write bytes that make :meth:`SerialBus.write` send them at once.
FLUSH_BYTES = 1 << 20


class LinkError(RuntimeError):
    """The serial link failed: no answer, a short answer, a CRC mismatch, bytes lost, or
    accesses the board answered with a bus error."""


def _is_link(addr: int) -> bool:
    return LINK_BASE <= addr < LINK_BASE + LINK_SPAN


class SerialBus:
    """Word reads and writes of a board's registers over a serial port.

    Parameters
    ----------
    port : str or serial-like object
        A port name or URL for ``serial.serial_for_url`` (``/dev/ttyUSB0``, a
        pseudo-terminal), or an open object with ``write(bytes)``, ``read(n)`` and
        ``reset_input_buffer()`` (``pyserial``'s).
    baudrate : int
        The line's rate. A read waits ``timeout`` seconds more than the line needs to send
        what is queued before its answer and the answer itself at this rate, so a slow line
        (the simulated board's is about :data:`~raplas_hdl.sim.drive.serial_board_sim.
        SIM_BAUD`) is not taken for a lost byte.
    timeout : float
        Seconds to wait for a read's answer beyond the line's time.

    Raises
    ------
    LinkError
        When the port cannot be opened (one line naming it).

    Attributes
    ----------
    words_written, words_read, round_trips, bytes_out, bytes_in : int
    """

    def __init__(self, port, baudrate: int = DEFAULT_BAUD, *, timeout: float = 2.0):
        self.timeout = float(timeout)
        self.baudrate = int(baudrate)
        self._unanswered = 0          # bytes sent since the last answer came in full
        if isinstance(port, str):
            try:
                import serial    # lazy: only a board render needs pyserial
            except ImportError as exc:
                raise LinkError(f"the serial link needs pyserial ({exc}); pip install "
                                "pyserial") from exc
            try:
                self.port = serial.serial_for_url(port, baudrate=int(baudrate),
                                                  timeout=self.timeout)
            except (serial.SerialException, OSError, ValueError) as exc:
                raise LinkError(f"cannot open serial port {port}: {exc}") from exc
            self.name = port
        else:
            self.port = port
            self.name = getattr(port, "name", None) or type(port).__name__
        self.words_written = self.words_read = self.round_trips = 0
        self.bytes_out = self.bytes_in = 0
        self._crc = 0                 # over the words of every access outside the link block
        self._out = bytearray()       # encoded commands not sent yet
        self._burst = None            # the write burst being gathered: [addr, fixed, words]

    # -- writes -------------------------------------------------------------------------------
    def write(self, addr: int, value: int) -> None:
        """Write one word (gathered into a burst; sent when a read needs the line)."""
        addr, value = int(addr), int(value) & 0xFFFF_FFFF
        b = self._burst
        if b is not None and len(b[2]) < MAX_BURST:
            if b[1] is None and addr in (b[0], b[0] + 1):
                b[1] = addr == b[0]     # the second word decides: one register, or a run
            if b[1] is not None and addr == b[0] + (0 if b[1] else len(b[2])):
                b[2].append(value)
                return
        self._close_burst()
        self._burst = [addr, None, [value]]

    def write_burst(self, addr: int, values, fixed: bool = False) -> None:
        """Write ``values`` at ``addr, addr+1, ...`` (``fixed``: all at ``addr``)."""
        self._close_burst()
        values = [int(v) & 0xFFFF_FFFF for v in np.asarray(values, dtype=np.uint64).reshape(-1)]
        for k in range(0, len(values), MAX_BURST):
            self._burst = [int(addr) + (0 if fixed else k), fixed, values[k:k + MAX_BURST]]
            self._close_burst()

    def _close_burst(self):
        b, self._burst = self._burst, None
        if b is None:
            return
        addr, fixed, words = b
        cmd = CMD_WRITE_FIXED if fixed else CMD_WRITE_INCR
        self._out += command_bytes(cmd, addr, len(words), words)
        self.words_written += len(words)
        if not _is_link(addr):
            self._crc = crc_words(words, self._crc)
        if len(self._out) >= FLUSH_BYTES:
            self.flush()

    def flush(self) -> None:
        """Send every gathered write."""
        self._close_burst()
        if self._out:
            data, self._out = bytes(self._out), bytearray()
            self._send(data)

    def _send(self, data: bytes) -> None:
        try:
            n = self.port.write(data)
        except OSError as exc:
            raise LinkError(f"serial port {self.name}: write failed: {exc}") from exc
        if n is not None and n != len(data):
            raise LinkError(f"serial port {self.name}: wrote {n} of {len(data)} bytes")
        self.bytes_out += len(data)
        self._unanswered += len(data)

    # -- reads --------------------------------------------------------------------------------
    def read(self, addr: int) -> int:
        """Read one word (one round trip)."""
        return self.read_burst(addr, 1)[0]

    def read_burst(self, addr: int, n: int, fixed: bool = False) -> list[int]:
        """Read ``n`` words at ``addr, addr+1, ...`` (``fixed``: ``n`` reads of ``addr``),
        in one round trip."""
        n = int(n)
        parts = [(int(addr) + (0 if fixed else k), min(MAX_BURST, n - k), fixed)
                 for k in range(0, n, MAX_BURST)]
        return [w for part in self.read_bursts(parts) for w in part]

    def read_bursts(self, requests) -> list[list[int]]:
        """Several reads in one round trip: ``requests`` are ``(addr, n, fixed)`` (``n`` up
        to 255), sent one after another without waiting; returns each one's words. The
        bridge answers them in order, so a read with a side effect (``RES_INFO``'s pop)
        takes place in request order."""
        requests = [(int(a), int(n), bool(f)) for a, n, f in requests]
        if not requests:
            return []
        self.flush()
        self._send(b"".join(command_bytes(CMD_READ_FIXED if f else CMD_READ_INCR, a, n)
                            for a, n, f in requests))
        total = sum(n for _, n, _ in requests)
        words = np.frombuffer(self._receive(4 * total, requests[0][0]),
                              dtype=">u4").astype(np.uint64)
        self.round_trips += 1
        self.words_read += total
        out, k = [], 0
        for a, n, _ in requests:
            part = words[k:k + n]
            k += n
            if not _is_link(a):
                self._crc = crc_words(part, self._crc)
            out.append([int(w) for w in part])
        return out

    def _receive(self, n: int, addr: int) -> bytes:
        data = bytearray()
        # the line's time for what is queued ahead of the answer and for the answer (10 bits
        # a byte), then the timeout
        line_s = 10.0 * (self._unanswered + n) / self.baudrate
        deadline = time.monotonic() + line_s + self.timeout
        while len(data) < n:
            try:
                chunk = self.port.read(n - len(data))
            except OSError as exc:
                raise LinkError(f"serial port {self.name}: read failed: {exc}") from exc
            if chunk:
                data += chunk
            elif time.monotonic() > deadline:
                raise LinkError(
                    f"serial port {self.name}: {len(data)} of {n} bytes answered a read at "
                    f"word address {addr:#x} within {line_s + self.timeout:.3g} s: a byte "
                    "was lost, or no UARTBone bridge is listening")
        self.bytes_in += n
        self._unanswered = 0
        return bytes(data)

    # -- the link's own registers ---------------------------------------------------------------
    def identify(self) -> None:
        """Raise :class:`LinkError` unless a UARTBone bridge of this project answers."""
        got = self.read(LINK_REGS["LINK_ID"])
        if got != LINK_ID:
            raise LinkError(f"serial port {self.name}: LINK_ID reads {got:#010x}, not "
                            f"{LINK_ID:#010x}: not a raplas-hdl UARTBone bridge")

    def check(self) -> None:
        """Compare the bridge's ``LINK_CRC`` with this side's, and its error counts with
        zero; :class:`LinkError` naming what differs."""
        crc, errors, lost = self.read_burst(LINK_REGS["LINK_CRC"], 3)
        problems = []
        if errors:
            problems.append(f"{errors} access(es) answered with a bus error (an unmapped "
                            "register or a refused command)")
        if lost:
            problems.append(f"{lost} byte(s) lost on receive")
        if crc != self._crc:
            problems.append(f"LINK_CRC {crc:#010x} differs from the host's {self._crc:#010x}: "
                            "a word changed or went missing on the wire")
        if problems:
            raise LinkError(f"serial link {self.name}: " + "; ".join(problems))

    def clear(self) -> None:
        """Zero the bridge's CRC and error counts, and this side's CRC."""
        self.write_burst(LINK_REGS["LINK_CRC"], [0, 0, 0])
        self.flush()
        self._crc = 0

    def resync(self, wait_s: float = 0.2) -> None:
        """After a failed read: wait out the bridge's timeout (an incomplete command is
        dropped), discard what arrived, and start the checks afresh (:meth:`clear`)."""
        self._out.clear()
        self._burst = None
        self._unanswered = 0
        time.sleep(wait_s)
        reset = getattr(self.port, "reset_input_buffer", None)
        if reset is not None:
            reset()
        self.clear()

    def close(self) -> None:
        """Send what is gathered and close the port."""
        try:
            self.flush()
        finally:
            close = getattr(self.port, "close", None)
            if close is not None:
                close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
