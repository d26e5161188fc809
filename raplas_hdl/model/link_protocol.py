"""The serial link's wire protocol: LiteX's UARTBone, and the link's own registers.

One source for the bridge (:mod:`raplas_hdl.rtl.uartbone`) and the host side
(:mod:`raplas_hdl.link.serial_bus`). No Amaranth, no pyserial.

**UARTBone** (the protocol of LiteX's ``litex_server --uart`` and its ``CommUART``), 8N1
bytes on the wire:

- a command byte (:data:`CMD_WRITE_INCR`, :data:`CMD_READ_INCR`, :data:`CMD_WRITE_FIXED`,
  :data:`CMD_READ_FIXED`), a length byte ``n`` (words, 0-255), a 32-bit *word* address,
  big-endian;
- a write: then ``n`` data words, big-endian; nothing comes back;
- a read: the bridge answers ``n`` data words, big-endian;
- ``incr`` bursts add 1 to the address after each word, ``fixed`` bursts keep it (a
  register such as ``MEM_DATA`` written word after word).

A byte that is not a command where a command is expected is skipped. UARTBone has no
checksum and no error reply, so the bridge adds a block of its own registers at word
address :data:`LINK_BASE` (byte address ``0xFFFF_FC00``, reachable from a 32-bit byte
address):

==============  ==========================================================================
``LINK_ID``     :data:`LINK_ID` (read only): a bridge answers here
``LINK_CRC``    CRC-32 (``zlib.crc32``) of the data words of every access since it was
                cleared, each word as 4 little-endian bytes, in the order the accesses
                completed; accesses to this block do not count. A write clears it.
``LINK_ERRORS`` accesses answered with a bus error (an unmapped address, a refused
                command) since cleared; a write clears it
``LINK_RX``     bytes lost on receive (framing errors, a byte arriving before the previous
                one was taken) since cleared; a write clears it
==============  ==========================================================================

The host keeps the same CRC over what it wrote and read (:func:`crc_words`) and compares
after each batch: a byte changed on the wire, in either direction, shows as a mismatch.
"""

from __future__ import annotations

import zlib

import numpy as np

__all__ = ["CMD_WRITE_INCR", "CMD_READ_INCR", "CMD_WRITE_FIXED", "CMD_READ_FIXED", "COMMANDS",
           "LINK_BASE", "LINK_ID", "LINK_REGS", "MAX_BURST", "CRC_POLY", "crc_words",
           "crc_step_matrix", "command_bytes", "LINK_SPAN", "DEFAULT_BAUD"]

#: The line's rate where none is given: what the ULX3S's FTDI FT231X reaches.
DEFAULT_BAUD = 3_000_000

CMD_WRITE_INCR = 0x01
CMD_READ_INCR = 0x02
CMD_WRITE_FIXED = 0x03
CMD_READ_FIXED = 0x04
#: Command byte -> (write, fixed).
COMMANDS = {CMD_WRITE_INCR: (True, False), CMD_READ_INCR: (False, False),
            CMD_WRITE_FIXED: (True, True), CMD_READ_FIXED: (False, True)}
#: Most words of one command (its length byte).
MAX_BURST = 255

#: Word address of the link's register block (byte address 0xFFFF_FC00).
LINK_BASE = 0x3FFF_FF00
#: Value of ``LINK_ID``: ASCII "UBRG".
LINK_ID = 0x55425247
#: The link's registers: name -> word address.
LINK_REGS = {"LINK_ID": LINK_BASE, "LINK_CRC": LINK_BASE + 1, "LINK_ERRORS": LINK_BASE + 2,
             "LINK_RX": LINK_BASE + 3}
#: Size of the block (word addresses ``LINK_BASE .. LINK_BASE + LINK_SPAN - 1``).
LINK_SPAN = 4

#: The reflected CRC-32 polynomial (zlib's).
CRC_POLY = 0xEDB88320


def crc_words(words, crc: int = 0) -> int:
    """``zlib.crc32`` of 32-bit ``words``, each as 4 little-endian bytes, continuing from
    ``crc`` (0 to start)."""
    data = np.asarray(words, dtype=np.uint64).astype("<u4").tobytes()
    return zlib.crc32(data, crc) & 0xFFFF_FFFF


def _step(state: int, word: int) -> int:
    """The CRC register (not inverted) after the 32 bits of ``word``, bit 0 first."""
    for k in range(32):
        bit = (state ^ (word >> k)) & 1
        state = (state >> 1) ^ (CRC_POLY if bit else 0)
    return state


def crc_step_matrix() -> tuple[list[int], list[int]]:
    """The word step of the CRC register as XOR masks: bit ``k`` of the next register is the
    parity of ``state & S[k]`` XOR the parity of ``word & W[k]``; the register starts at
    ``0xFFFF_FFFF`` and reads out inverted (so its value is :func:`crc_words`)."""
    cols_s = [_step(1 << i, 0) for i in range(32)]
    cols_w = [_step(0, 1 << j) for j in range(32)]
    s_rows = [sum(1 << i for i in range(32) if cols_s[i] >> k & 1) for k in range(32)]
    w_rows = [sum(1 << j for j in range(32) if cols_w[j] >> k & 1) for k in range(32)]
    return s_rows, w_rows


def command_bytes(cmd: int, addr: int, n: int, words=()) -> bytes:
    """The bytes of one UARTBone command of ``n`` words at word address ``addr``: the
    header, then (a write) the ``n`` data ``words``, big-endian.

    Raises
    ------
    ValueError
        On an unknown command, a length outside 0-255, an address outside 32 bits, or a
        write whose word count is not ``n``.
    """
    if cmd not in COMMANDS:
        raise ValueError(f"UARTBone command {cmd:#x} is not one of "
                         f"{', '.join(hex(c) for c in COMMANDS)}")
    if not 0 <= n <= MAX_BURST:
        raise ValueError(f"a UARTBone burst has 0 to {MAX_BURST} words, not {n}")
    if not 0 <= addr < 1 << 32:
        raise ValueError(f"word address {addr:#x} does not fit in 32 bits")
    head = bytes([cmd, n]) + int(addr).to_bytes(4, "big")
    if not COMMANDS[cmd][0]:
        return head
    words = np.asarray(words, dtype=np.uint64).reshape(-1)
    if words.size != n:
        raise ValueError(f"a write of {n} words was given {words.size}")
    return head + words.astype(">u4").tobytes()
