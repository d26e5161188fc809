# amaranth: UnusedElaboratable=no
"""``SerialBus`` over a pseudo-terminal, against the UARTBone bridge's RTL (Amaranth simulator).

The bridge and a small Wishbone slave (``tests/support/uartbone_bench.py``) run in the
simulator, their serial lines on a pseudo-terminal driven bit by bit; ``SerialBus`` opens
the terminal by name, as it opens a board's port. Checked: writes gather into bursts (a
run at one address a fixed burst, consecutive addresses an incr one) and read back; one
round trip per read burst, and per batch of reads sent together; ``check`` passes on a clean link and names a bus error; a
byte changed on the wire (the bridge stores another value than the host sent) fails the
CRC comparison; a lost byte makes the next read fail in one line (not a wrong word), and
after ``resync`` the link works again; a read with nobody answering fails in one line
after the timeout; a port that cannot be opened fails in one line.
"""

import os

import pytest

from raplas_hdl.link.serial_bus import LinkError, SerialBus
from tests.support.uartbone_bench import WORDS, PtyBridge


@pytest.fixture
def bridge():
    b = PtyBridge()
    yield b
    b.close()


def test_bursts_round_trips_and_checks(bridge):
    with SerialBus(bridge.name, timeout=20.0) as bus:
        bus.identify()
        for v in (5, 6, 7):                 # one register again and again: a fixed burst
            bus.write(3, v)
        for k in range(4):                  # consecutive registers: an incr burst
            bus.write(6 + k, 100 + k)
        bus.flush()
        assert bus.bytes_out == 6 + 2 * 6 + 7 * 4 and bus.words_written == 7
        trips = bus.round_trips
        assert bus.read_burst(6, 4) == [100, 101, 102, 103]
        assert bus.read(3) == 7
        assert bus.read_burst(3, 2, fixed=True) == [7, 7]
        assert bus.round_trips == trips + 3
        # several reads sent together (the bridge queues their commands while it answers)
        assert bus.read_bursts([(6, 4, False), (3, 1, False), (3, 2, True)] * 8) == \
            [[100, 101, 102, 103], [7], [7, 7]] * 8
        assert bus.round_trips == trips + 4
        bus.check()
        bus.read(WORDS)                     # beyond the slave: a bus error, named by check
        with pytest.raises(LinkError, match="1 access.*bus error"):
            bus.check()
        bus.clear()
        bus.check()


def test_a_changed_byte_fails_the_crc():
    b = PtyBridge(corrupt={7: 0x10})         # a bit of the written word's second byte
    try:
        with SerialBus(b.name, timeout=20.0) as bus:
            bus.write(1, 0x1234_5678)
            bus.flush()
            assert bus.read(1) == 0x1224_5678    # the bridge stored what it received
            with pytest.raises(LinkError, match="LINK_CRC .* differs from the host's"):
                bus.check()
    finally:
        b.close()


def test_a_lost_byte_is_an_error_not_a_wrong_word():
    b = PtyBridge(drop={9})                  # a byte of the written word
    try:
        with SerialBus(b.name, timeout=3.0) as bus:
            bus.write(1, 0x1234_5678)
            bus.flush()
            # the bridge waits for the missing byte and takes the read's first byte in its
            # place; the read is never answered in full: the host says so
            with pytest.raises(LinkError, match="of 4 bytes answered a read"):
                bus.read(1)
            bus.resync(wait_s=0.5)           # past the bridge's timeout: clean again
            bus.write(1, 0x0BAD_F00D)
            assert bus.read(1) == 0x0BAD_F00D
            bus.check()
    finally:
        b.close()


def test_no_answer_and_bad_ports_fail_in_one_line(tmp_path):
    master, slave = os.openpty()            # a terminal with nobody on the other side
    try:
        with pytest.raises(LinkError, match=r"0 of 4 bytes answered a read .* within 0.3 s"):
            SerialBus(os.ttyname(slave), timeout=0.3).read(0)
    finally:
        os.close(master)
        os.close(slave)
    with pytest.raises(LinkError, match="cannot open serial port .*nope"):
        SerialBus(str(tmp_path / "nope"))
