# amaranth: UnusedElaboratable=no
"""The UART and the UARTBone bridge, bit by bit on the serial lines (Amaranth simulator).

The testbench is the host's serial port: it drives ``rx`` one bit per ``DIVISOR`` clocks
with the bytes of LiteX's UARTBone commands (:func:`~raplas_hdl.model.link_protocol.
command_bytes`, the framing of LiteX's ``CommUART``) and decodes ``tx`` frame by frame. Behind
the bridge is a small Wishbone slave with the board top's bus timing (a registered ``ack``
the cycle after the request, ``err`` above its last word). Checked: incr and fixed bursts
both ways, big-endian words, the link registers (ID, the CRC of every completed access's
data word against ``zlib.crc32``, bus errors, lost bytes), a junk byte skipped, and a
command cut short dropped after the timeout so that the next one is answered.
"""

import pytest
from amaranth.sim import Simulator

from raplas_hdl.model.link_protocol import (CMD_READ_FIXED, CMD_READ_INCR, CMD_WRITE_FIXED,
                                            CMD_WRITE_INCR, LINK_ID, LINK_REGS, command_bytes,
                                            crc_words)
from raplas_hdl.rtl.uart import UARTRx, UARTTx
from raplas_hdl.rtl.uartbone import UARTBone
from tests.support.uartbone_bench import DIVISOR, TIMEOUT, WORDS, Bench


def run(script):
    """Run ``script(send, recv, idle)`` as the host against the bench; ``send(bytes,
    stop=1)`` drives frames on ``rx``, ``recv(n)`` returns the next ``n`` bytes from ``tx``
    (failing after a generous wait), ``idle(clocks)`` waits."""
    dut = Bench()
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    received = []

    async def listener(ctx):
        while True:
            while ctx.get(dut.tx):                          # to a start bit
                await ctx.tick()
            await ctx.tick().repeat(DIVISOR // 2)
            assert ctx.get(dut.tx) == 0, "a glitch, not a start bit"
            value = 0
            for k in range(8):
                await ctx.tick().repeat(DIVISOR)
                value |= ctx.get(dut.tx) << k
            await ctx.tick().repeat(DIVISOR)
            assert ctx.get(dut.tx) == 1, "stop bit low"
            received.append(value)

    async def host(ctx):
        async def send(data, stop=1):
            for b in data:
                for bit in [0, *((b >> k) & 1 for k in range(8)), stop]:
                    ctx.set(dut.rx, bit)
                    await ctx.tick().repeat(DIVISOR)
                ctx.set(dut.rx, 1)

        async def recv(n):
            for _ in range(n * 20 * DIVISOR + 200):
                if len(received) >= n:
                    break
                await ctx.tick()
            assert len(received) >= n, f"{len(received)} of {n} bytes came back"
            out = bytes(received[:n])
            del received[:n]
            return out

        async def idle(clocks):
            await ctx.tick().repeat(clocks)

        await idle(10)
        await script(send, recv, idle)
        await idle(20 * DIVISOR)
        assert not received, f"unexpected bytes {bytes(received)!r}"

    sim.add_testbench(listener, background=True)
    sim.add_testbench(host)
    sim.run()


def words(raw):
    return [int.from_bytes(raw[k:k + 4], "big") for k in range(0, len(raw), 4)]


def test_bursts_link_registers_and_crc():
    async def script(send, recv, idle):
        async def read(addr, n, cmd=CMD_READ_INCR):
            await send(command_bytes(cmd, addr, n))
            return words(await recv(4 * n))

        done = []           # data words of the accesses that completed, for the CRC
        await send(command_bytes(CMD_WRITE_INCR, 2, 3, [0x11223344, 0xA5A5_0001, 7]))
        done += [0x11223344, 0xA5A5_0001, 7]
        assert await read(2, 3) == [0x11223344, 0xA5A5_0001, 7]
        done += [0x11223344, 0xA5A5_0001, 7]
        await send(b"\x55")                                  # not a command: skipped
        await send(command_bytes(CMD_WRITE_FIXED, 5, 3, [1, 2, 0xDEAD_BEEF]))
        done += [1, 2, 0xDEAD_BEEF]
        assert await read(5, 2, CMD_READ_FIXED) == [0xDEAD_BEEF] * 2
        done += [0xDEAD_BEEF] * 2
        assert await read(LINK_REGS["LINK_ID"], 1) == [LINK_ID]
        assert await read(LINK_REGS["LINK_CRC"], 1) == [crc_words(done)]
        assert await read(LINK_REGS["LINK_ERRORS"], 2) == [0, 0]
        # the slave's err (address 12) and an address beyond the bus (300): answered 0,
        # counted, out of the CRC
        assert await read(WORDS, 1) == [0]
        await send(command_bytes(CMD_WRITE_INCR, 300, 1, [9]))
        assert await read(LINK_REGS["LINK_ERRORS"], 1) == [2]
        assert await read(LINK_REGS["LINK_CRC"], 1) == [crc_words(done)]
        # clearing: a write to each register
        await send(command_bytes(CMD_WRITE_INCR, LINK_REGS["LINK_CRC"], 2, [0, 0]))
        assert await read(LINK_REGS["LINK_CRC"], 2) == [0, 0]
        assert await read(0, 0) == []                          # a zero-length command

    run(script)


def test_lost_bytes_and_timeout():
    async def script(send, recv, idle):
        async def read(addr, n):
            await send(command_bytes(CMD_READ_INCR, addr, n))
            return words(await recv(4 * n))

        await send(command_bytes(CMD_WRITE_INCR, 1, 1, [0x0BAD_F00D]))
        # a frame with a low stop bit is lost and counted
        await send(b"\x02", stop=0)
        await idle(4 * DIVISOR)
        assert await read(LINK_REGS["LINK_RX"], 1) == [1]
        # a command cut short (its address incomplete) is dropped after the timeout
        await send(command_bytes(CMD_READ_INCR, 1, 1)[:4])
        await idle(TIMEOUT + 10)
        assert await read(1, 1) == [0x0BAD_F00D]

    run(script)


def test_uart_checks_its_divisor():
    for bad in (3, 4.0, True):
        with pytest.raises(ValueError, match="divisor"):
            UARTRx(bad)
        with pytest.raises(ValueError, match="divisor"):
            UARTTx(bad)
    with pytest.raises(ValueError, match="addr_bits"):
        UARTBone(DIVISOR, 31)
