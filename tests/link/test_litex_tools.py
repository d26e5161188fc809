# amaranth: UnusedElaboratable=no
"""LiteX's own host tools speak to the bridge: the protocol is UARTBone, not a private one.

The bridge's RTL runs in the Amaranth simulator with its serial lines on a pseudo-terminal
(``tests/support/uartbone_bench.py``). LiteX's ``litex_server --uart`` opens the terminal,
and LiteX's ``RemoteClient`` connects to the server over TCP. The client reads the link's
ID, writes words (byte addresses, as LiteX counts them), reads them back one by one and as
a burst, and reads the link's CRC: the same value as ``zlib.crc32`` of the words. LiteX is
a test dependency (``requirements.lock``), never a dependency of the package.
"""

from raplas_hdl.model.link_protocol import LINK_ID, LINK_REGS, crc_words
from tests.support.litex_server import litex_client
from tests.support.uartbone_bench import PtyBridge


def test_litex_server_and_remote_client_read_and_write_through_the_bridge():
    bridge = PtyBridge()
    try:
        with litex_client(bridge.name) as wb:
            assert wb.read(4 * LINK_REGS["LINK_ID"]) == LINK_ID
            wb.write(4 * 2, [0xCAFE_0001, 0xCAFE_0002, 0xCAFE_0003])
            assert wb.read(4 * 3) == 0xCAFE_0002
            assert wb.read(4 * 2, length=3) == [0xCAFE_0001, 0xCAFE_0002, 0xCAFE_0003]
            done = [0xCAFE_0001, 0xCAFE_0002, 0xCAFE_0003, 0xCAFE_0002,
                    0xCAFE_0001, 0xCAFE_0002, 0xCAFE_0003]
            assert wb.read(4 * LINK_REGS["LINK_CRC"]) == crc_words(done)
            assert wb.read(4 * LINK_REGS["LINK_ERRORS"]) == 0
    finally:
        bridge.close()
