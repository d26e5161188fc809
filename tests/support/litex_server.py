"""LiteX's ``litex_server --uart`` on a serial port, for the tests that prove the link speaks
LiteX's UARTBone protocol (LiteX is a test dependency, never the package's)."""

import contextlib
import socket
import subprocess
import sys
import time

import pytest


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def start_litex_server(uart_port: str, timeout_s: float = 60.0):
    """Start ``litex_server --uart`` on ``uart_port``; returns ``(process, tcp_port)`` once
    it accepts connections (``RemoteClient(port=tcp_port)``). The caller terminates it."""
    port = _free_port()
    server = subprocess.Popen(
        [sys.executable, "-m", "litex.tools.litex_server", "--uart", "--uart-port",
         uart_port, "--uart-baudrate", "3000000", "--bind-port", str(port)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + timeout_s
    while True:            # the server listens once it has opened the port
        try:
            socket.create_connection(("localhost", port), timeout=1).close()
            return server, port
        except OSError:
            if server.poll() is not None or time.monotonic() > deadline:
                server.kill()
                pytest.fail(f"litex_server did not start: {server.stdout.read()}")
            time.sleep(0.2)


@contextlib.contextmanager
def litex_client(uart_port: str):
    """LiteX's ``RemoteClient`` through a ``litex_server --uart`` on ``uart_port`` (byte
    addresses, as LiteX counts them); both are closed on exit."""
    from litex.tools.litex_client import RemoteClient

    server, port = start_litex_server(uart_port)
    try:
        wb = RemoteClient(port=port)
        wb.open()
        try:
            yield wb
        finally:
            wb.close()
    finally:
        server.terminate()
        server.wait(timeout=30)
