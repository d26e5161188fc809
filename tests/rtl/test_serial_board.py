# amaranth: UnusedElaboratable=no
"""The serial board (the UARTBone bridge in front of the board top) in the Amaranth
simulator, a small unit behind it: the host's bytes go onto ``rx`` bit by bit.

Checked: a UARTBone read of the board top's ``ID`` answers ``BOARD_ID`` big-endian, and of
``CFG_LATTICE`` the build's rows and columns (the bridge reaches the board top's register
map); the status outputs: the heartbeat toggles every ``2**heartbeat_bits`` clocks, the rx,
tx and bus LEDs light while a byte or an access goes and go dark after ``2**blink_bits``
clocks, and the bus-error LED lights at a read of an unmapped register and stays lit.
"""

from amaranth.sim import Simulator

from raplas_hdl.fp import FP16
from raplas_hdl.model.board_map import BOARD_ID, REGISTERS
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.link_protocol import CMD_READ_INCR, command_bytes
from raplas_hdl.rtl.serial_board import LEDS, SerialBoard
from tests.support.uartbone_bench import read_frame

DIVISOR = 4
CFG = UnitConfig(fmt=FP16, rows=2, cols=3, tris_per_sphere=2, max_triangles=16, max_spheres=8,
                 fifo_depth=3)
UNMAPPED = 0x1F
#: The reset synchroniser holds the design in reset for its first clocks.
OUT_OF_RESET = 10e-6


def test_serial_board_reaches_the_register_map_and_drives_the_leds():
    dut = SerialBoard(CFG, DIVISOR, timeout=2000, heartbeat_bits=4, blink_bits=5)
    sim = Simulator(dut)
    led = {name: k for k, name in enumerate(LEDS)}
    received, seen = [], {name: [] for name in LEDS}

    async def listener(ctx):
        await ctx.delay(OUT_OF_RESET)
        while True:
            received.append(await read_frame(ctx, dut.tx, DIVISOR))

    async def watch(ctx):
        await ctx.delay(OUT_OF_RESET)
        while True:
            await ctx.tick()
            leds = ctx.get(dut.leds)
            for name, k in led.items():
                seen[name].append(leds >> k & 1)

    async def host(ctx):
        async def send(data):
            for b in data:
                for bit in [0, *((b >> k) & 1 for k in range(8)), 1]:
                    ctx.set(dut.rx, bit)
                    await ctx.tick().repeat(DIVISOR)

        async def word():
            want = len(received) + 4
            for _ in range(200 * DIVISOR):
                if len(received) >= want:
                    break
                await ctx.tick()
            assert len(received) >= want, "no answer"
            return int.from_bytes(bytes(received[want - 4:want]), "big")

        await ctx.delay(OUT_OF_RESET)
        await ctx.tick().repeat(64)             # idle: the heartbeat alone
        idle = {name: list(v) for name, v in seen.items()}
        await send(command_bytes(CMD_READ_INCR, REGISTERS["ID"], 1))
        assert await word() == BOARD_ID
        await send(command_bytes(CMD_READ_INCR, REGISTERS["CFG_LATTICE"], 1))
        lattice = await word()
        assert (lattice & 0xFF, lattice >> 8 & 0xFF) == (CFG.rows, CFG.cols)
        await ctx.tick().repeat(2 ** 6)         # every activity LED dark again
        dark = ctx.get(dut.leds)
        assert not seen["bus_error"][-1]
        await send(command_bytes(CMD_READ_INCR, UNMAPPED, 1))
        assert await word() == 0                # a bus error reads 0
        await ctx.tick().repeat(2 ** 6)
        after = ctx.get(dut.leds)
        # heartbeat: toggles every 16 clocks once out of reset, with or without traffic
        hb = idle["heartbeat"][8:]
        edges = [k for k in range(1, len(hb)) if hb[k] != hb[k - 1]]
        assert len(edges) >= 2 and all(b - a == 16 for a, b in zip(edges, edges[1:])), edges
        for name in ("rx", "tx", "bus"):
            assert not any(idle[name]), name        # dark while nothing goes
            assert any(seen[name]), name            # lit by the traffic
            assert not dark >> led[name] & 1, name  # dark 2**5 clocks after it
        assert not dark >> led["bus_error"] & 1
        assert after >> led["bus_error"] & 1        # lit by the unmapped read, and held

    async def clock(ctx):       # the clk port (the design's sync domain comes from it)
        while True:
            ctx.set(dut.clk, 0)
            await ctx.delay(0.5e-6)
            ctx.set(dut.clk, 1)
            await ctx.delay(0.5e-6)

    sim.add_process(clock)
    sim.add_testbench(host)
    sim.add_testbench(listener, background=True)
    sim.add_testbench(watch, background=True)
    sim.run()
