# amaranth: UnusedElaboratable=no
"""LiteX's own host tools speak to the bridge: the protocol is UARTBone, not a private one.

The bridge's RTL runs in the Amaranth simulator with its serial lines on a pseudo-terminal
(``tests/support/uartbone_bench.py``). LiteX's ``litex_server --uart`` opens the terminal,
and LiteX's ``RemoteClient`` connects to the server over TCP. The client reads the link's
ID, writes words (byte addresses, as LiteX counts them), reads them back one by one and as
a burst, and reads the link's CRC: the same value as ``zlib.crc32`` of the words. LiteX is
a test dependency (``requirements.lock``), never a dependency of the package.
"""

import socket
import subprocess
import sys
import time

import pytest

from raplas_hdl.model.link_protocol import LINK_ID, LINK_REGS, crc_words
from tests.support.uartbone_bench import PtyBridge


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def test_litex_server_and_remote_client_read_and_write_through_the_bridge():
    from litex.tools.litex_client import RemoteClient

    bridge = PtyBridge()
    port = _free_port()
    server = subprocess.Popen(
        [sys.executable, "-m", "litex.tools.litex_server", "--uart", "--uart-port",
         bridge.name, "--uart-baudrate", "3000000", "--bind-port", str(port)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 60
        while True:            # the server listens once it has opened the port
            try:
                socket.create_connection(("localhost", port), timeout=1).close()
                break
            except OSError:
                if server.poll() is not None or time.monotonic() > deadline:
                    pytest.fail(f"litex_server did not start: {server.stdout.read()}")
                time.sleep(0.2)
        wb = RemoteClient(port=port)
        wb.open()
        try:
            assert wb.read(4 * LINK_REGS["LINK_ID"]) == LINK_ID
            wb.write(4 * 2, [0xCAFE_0001, 0xCAFE_0002, 0xCAFE_0003])
            assert wb.read(4 * 3) == 0xCAFE_0002
            assert wb.read(4 * 2, length=3) == [0xCAFE_0001, 0xCAFE_0002, 0xCAFE_0003]
            done = [0xCAFE_0001, 0xCAFE_0002, 0xCAFE_0003, 0xCAFE_0002,
                    0xCAFE_0001, 0xCAFE_0002, 0xCAFE_0003]
            assert wb.read(4 * LINK_REGS["LINK_CRC"]) == crc_words(done)
            assert wb.read(4 * LINK_REGS["LINK_ERRORS"]) == 0
        finally:
            wb.close()
    finally:
        server.terminate()
        server.wait(timeout=30)
        bridge.close()
