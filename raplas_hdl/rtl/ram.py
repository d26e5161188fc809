"""Simple dual-port RAM: one write port (with byte-lane style granularity), synchronous reads.

:class:`SyncRAM` has the ports of an Amaranth :class:`~amaranth.lib.memory.Memory` as the
intersection unit uses it (``write_port(granularity=...)``, ``read_port()`` with ``addr``,
``en`` and ``data``; reads are not transparent: a read and a write of the same address in one
clock return the old word) and two implementations:

``"memory"``
    An Amaranth ``Memory``: simulates in Amaranth's simulator. Converting it to Verilog
    writes every word's initial value, which for deep memories (a 70k-triangle mesh needs
    131,072 x 288 bits) takes Amaranth and Yosys tens of minutes.
``"verilog"``
    An instance of the behavioural Verilog module :data:`RAM_MODULE` (no initial values; the
    host writes every word it reads). It converts in no time, simulates under Icarus and
    Verilator, and is the usual block-RAM inference template. Amaranth's simulator cannot
    run it; append :func:`ram_verilog` to the emitted text.

A RAM built ``collision_free`` is one whose user never reads an address in the clock it
writes it (the unit's memories: the host writes the scene memories only between runs, and
only the bank no run reads). Its memory carries Yosys's ``no_rw_check`` attribute (both
implementations), so synthesis maps it to its RAM cells as they are, without the logic that
makes a block RAM, whose ports collide undefined, return the old word: on an ECP5 that logic is
a register of the written word and of the address match per lane and a multiplexer on
every bit of the read data, between the block RAM's output (5.8 ns clock-to-out at speed
6) and its reader's register, and was the certified whole unit's seed-3 path (10.4 ns).
Simulation is unchanged (a collision still returns the old word); only what synthesis
builds for a collision, which the RAM's user never makes, is left undefined.
"""

from __future__ import annotations

from amaranth.hdl import Cat, ClockSignal, Elaboratable, Instance, Module, Mux, Signal
from amaranth.lib.memory import Memory

__all__ = ["SyncRAM", "RAM_IMPLS", "RAM_MODULE", "RAM_MODULE_NO_RW_CHECK", "ram_verilog",
           "BlockRAMFIFO", "CreditSyncFIFO", "BLOCK_RAM_ATTRS", "NO_RW_CHECK_ATTRS", "incr_modulo"]

#: Implementations of :class:`SyncRAM`.
RAM_IMPLS = ("memory", "verilog")

#: Name of the behavioural RAM module the ``"verilog"`` implementation instantiates, and of
#: its ``collision_free`` twin.
RAM_MODULE = "raplas_sdp_ram"
RAM_MODULE_NO_RW_CHECK = "raplas_sdp_ram_no_rw_check"

#: Yosys's attribute on a memory whose reads never meet a write of the same address: it maps
#: to RAM cells without read-during-write logic (``collision_free``).
NO_RW_CHECK_ATTRS = {"no_rw_check": 1}

_RAM_TEMPLATE = """
// Simple dual-port RAM for raplas-hdl (one write port with GRAN-bit lanes, NREAD
// synchronous non-transparent read ports). No initial values: the host writes what it reads.
// {note}
module {name} #(
    parameter WIDTH = 8, DEPTH = 16, ABITS = 4, GRAN = 8, LANES = 1, NREAD = 1) (
    input  wire                     clk,
    input  wire [ABITS-1:0]         waddr,
    input  wire [WIDTH-1:0]         wdata,
    input  wire [LANES-1:0]         wen,
    input  wire [NREAD*ABITS-1:0]   raddr,
    input  wire [NREAD-1:0]         ren,
    output reg  [NREAD*WIDTH-1:0]   rdata);
  {attr}reg [WIDTH-1:0] mem [0:DEPTH-1];
  integer i, r;
  always @(posedge clk) begin
    for (r = 0; r < NREAD; r = r + 1)
      if (ren[r]) rdata[r*WIDTH +: WIDTH] <= mem[raddr[r*ABITS +: ABITS]];
    for (i = 0; i < LANES; i = i + 1)
      if (wen[i] && waddr < DEPTH) mem[waddr][i*GRAN +: GRAN] <= wdata[i*GRAN +: GRAN];
  end
endmodule
"""


def _ram_text(name: str, collision_free: bool) -> str:
    note = ("No read ever meets a write of the same address (Yosys's no_rw_check)."
            if collision_free else "A read in the clock of a write of its address: the old word.")
    return _RAM_TEMPLATE.format(name=name, note=note,
                                attr="(* no_rw_check *) " if collision_free else "")


def ram_verilog() -> str:
    """The Verilog text of :data:`RAM_MODULE` and :data:`RAM_MODULE_NO_RW_CHECK` (append it
    once to a design that uses them)."""
    return _ram_text(RAM_MODULE, False) + _ram_text(RAM_MODULE_NO_RW_CHECK, True)


class _Port:
    def __init__(self, abits, width, lanes, name, read=False):
        self.addr = Signal(abits, name=f"{name}_addr")
        self.data = Signal(width, name=f"{name}_data")
        # a read port is enabled unless driven (as an Amaranth read port)
        self.en = Signal(lanes, name=f"{name}_en", init=1 if read else 0)


class SyncRAM:
    """A RAM of ``depth`` words of ``width`` bits; see the module docstring.

    Parameters
    ----------
    width, depth : int
    impl : {"memory", "verilog"}
    name : str
        Prefix of its signals and of the instance.
    collision_free : bool
        No read ever meets a write of the same address in one clock: synthesis may leave a
        collision undefined (see the module docstring).

    Raises
    ------
    ValueError
        On a bad ``impl``, width or depth.
    """

    def __init__(self, width: int, depth: int, impl: str = "memory", name: str = "ram",
                 collision_free: bool = False):
        if impl not in RAM_IMPLS:
            raise ValueError(f"ram must be one of {', '.join(RAM_IMPLS)}, not {impl!r}")
        if width < 1 or depth < 1:
            raise ValueError(f"a RAM needs a positive width and depth, not {width} x {depth}")
        self.width, self.depth, self.impl, self.name = int(width), int(depth), impl, name
        self.collision_free = bool(collision_free)
        self.abits = max(1, (self.depth - 1).bit_length())
        self._wp = None
        self._gran = None
        self._rps = []

    def write_port(self, granularity: int | None = None) -> _Port:
        """The write port (``addr``, ``data``, ``en`` with one bit per ``granularity`` lane)."""
        if self._wp is not None:
            raise ValueError("SyncRAM has one write port")
        gran = self.width if granularity is None else int(granularity)
        if gran < 1 or self.width % gran:
            raise ValueError(f"granularity {gran} does not divide the width {self.width}")
        self._gran = gran
        self._wp = _Port(self.abits, self.width, self.width // gran, f"{self.name}_w")
        return self._wp

    def read_port(self) -> _Port:
        """A synchronous read port: ``data`` is the word at ``addr`` of the last clock with
        ``en`` set (the word before a write of the same clock)."""
        rp = _Port(self.abits, self.width, 1, f"{self.name}_r{len(self._rps)}", read=True)
        self._rps.append(rp)
        return rp

    def add_to(self, m: Module, name: str | None = None) -> None:
        """Build the RAM into ``m`` (after every port has been taken)."""
        if self._wp is None or not self._rps:
            raise ValueError("a SyncRAM needs its write port and a read port before add_to")
        name = name or self.name
        wp, lanes = self._wp, self.width // self._gran
        if self.impl == "memory":
            mem = Memory(shape=self.width, depth=self.depth, init=[],
                         attrs=NO_RW_CHECK_ATTRS if self.collision_free else None)
            m.submodules[name] = mem
            mwp = mem.write_port(granularity=None if lanes == 1 else self._gran)
            m.d.comb += [mwp.addr.eq(wp.addr), mwp.data.eq(wp.data), mwp.en.eq(wp.en)]
            for rp in self._rps:
                mrp = mem.read_port()
                m.d.comb += [mrp.addr.eq(rp.addr), mrp.en.eq(rp.en), rp.data.eq(mrp.data)]
            return
        n = len(self._rps)
        rdata = Signal(n * self.width, name=f"{name}_rdata")
        m.submodules[name] = Instance(
            RAM_MODULE_NO_RW_CHECK if self.collision_free else RAM_MODULE,
            p_WIDTH=self.width, p_DEPTH=self.depth, p_ABITS=self.abits, p_GRAN=self._gran,
            p_LANES=lanes, p_NREAD=n,
            i_clk=ClockSignal("sync"), i_waddr=wp.addr, i_wdata=wp.data, i_wen=wp.en,
            i_raddr=Cat(*[rp.addr for rp in self._rps]),
            i_ren=Cat(*[rp.en for rp in self._rps]), o_rdata=rdata)
        for k, rp in enumerate(self._rps):
            m.d.comb += rp.data.eq(rdata[k * self.width:(k + 1) * self.width])


def incr_modulo(value, modulo: int):
    """``value + 1`` modulo ``modulo`` (a plain increment when that is a power of two): a FIFO
    pointer's step."""
    if modulo == 1 << len(value):
        return value + 1
    return Mux(value == modulo - 1, 0, value + 1)


def _fifo_ports(fifo) -> None:
    """Give ``fifo`` the ports of :class:`amaranth.lib.fifo.SyncFIFO` for its ``width`` and
    ``depth``: ``w_data``, ``w_en``, ``w_rdy``, ``r_data``, ``r_en``, ``r_rdy``, ``level``."""
    shapes = {"w_data": fifo.width, "w_en": 1, "w_rdy": 1, "r_data": fifo.width, "r_en": 1,
              "r_rdy": 1, "level": range(fifo.depth + 1)}
    for name, shape in shapes.items():
        setattr(fifo, name, Signal(shape, name=name))


#: Attributes that make Yosys (``memory_libmap``) and vendor tools map a memory to block RAM.
BLOCK_RAM_ATTRS = {"ram_style": "block"}


class BlockRAMFIFO(Elaboratable):
    """A first-word-fall-through FIFO of ``depth`` words whose storage is block RAM.

    The ports of :class:`amaranth.lib.fifo.SyncFIFO` (``w_data``, ``w_en``, ``w_rdy``,
    ``r_data``, ``r_en``, ``r_rdy``, ``level``) and the structure of
    :class:`~amaranth.lib.fifo.SyncFIFOBuffered`: a memory of ``depth - 1`` words with a
    synchronous, non-transparent read port (marked :data:`BLOCK_RAM_ATTRS`) whose data
    register is the head word. A word written into an empty FIFO shows on ``r_data`` one
    clock later than in ``SyncFIFO`` (two edges after its write). No read ever meets a
    write of the same address.

    Parameters
    ----------
    width : int
    depth : int
        At least 2.
    credits : bool
        The writer holds a credit for every word it writes (it never writes into a full
        FIFO), so the write enable is ``w_en`` alone, not ``w_en & w_rdy``
        (:class:`CreditSyncFIFO`); ``w_rdy`` still says whether a word fits.

    Raises
    ------
    ValueError
        On a width or depth out of range.
    """

    def __init__(self, *, width: int, depth: int, credits: bool = False):
        if width < 1 or depth < 2:
            raise ValueError(f"a block-RAM FIFO needs width >= 1 and depth >= 2, "
                             f"not {width} x {depth}")
        self.width, self.depth = int(width), int(depth)
        self.credits = bool(credits)
        _fifo_ports(self)

    def elaborate(self, platform):
        m = Module()
        inner = self.depth - 1
        inner_level = Signal(range(inner + 1))
        produce = Signal(range(inner))
        consume = Signal(range(inner))
        do_write = Signal()
        do_read = Signal()          # memory -> head register
        m.d.comb += [
            self.w_rdy.eq(inner_level != inner),
            do_write.eq(self.w_en if self.credits else self.w_rdy & self.w_en),
            do_read.eq((inner_level != 0) & (~self.r_rdy | self.r_en)),
            self.level.eq(inner_level + self.r_rdy),
        ]
        mem = m.submodules.storage = Memory(shape=self.width, depth=inner, init=[],
                                            attrs=BLOCK_RAM_ATTRS)
        wp = mem.write_port()
        rp = mem.read_port(domain="sync")
        m.d.comb += [wp.addr.eq(produce), wp.data.eq(self.w_data), wp.en.eq(do_write),
                     rp.addr.eq(consume), rp.en.eq(do_read), self.r_data.eq(rp.data)]

        def incr(p):
            return Mux(p == inner - 1, 0, p + 1)

        with m.If(do_write):
            m.d.sync += produce.eq(incr(produce))
        with m.If(do_read):
            m.d.sync += [consume.eq(incr(consume)), self.r_rdy.eq(1)]
        with m.Elif(self.r_en):
            m.d.sync += self.r_rdy.eq(0)
        m.d.sync += inner_level.eq(inner_level + do_write - do_read)
        return m


class CreditSyncFIFO(Elaboratable):
    """Amaranth's :class:`~amaranth.lib.fifo.SyncFIFO` cycle for cycle (a memory of ``depth``
    words with an asynchronous read port, ``r_data`` the head word), for a writer that holds
    a credit for every word it writes: the write enable is ``w_en`` alone.

    In ``SyncFIFO`` the write enable is ``w_en & w_rdy``, and ``w_rdy`` is the level compared
    with the depth, so the level register reaches every bit of the memory's write port
    through a comparison and a gate. Placed and routed, that net held the certified
    ray-triangle unit (rne, ECP5 speed 6) below 100 MHz. A writer that counts its credits
    never writes into a full FIFO, so the gate changes nothing there; here the write enable
    is the writer's valid register. ``w_rdy`` still says whether a word fits, and gates
    nothing; ``level``, ``r_rdy``, ``r_en`` and the pointers are ``SyncFIFO``'s.

    Parameters
    ----------
    width : int
    depth : int
        At least 1.

    Raises
    ------
    ValueError
        On a width or depth out of range.
    """

    def __init__(self, *, width: int, depth: int):
        if width < 1 or depth < 1:
            raise ValueError(f"a credit FIFO needs width >= 1 and depth >= 1, "
                             f"not {width} x {depth}")
        self.width, self.depth = int(width), int(depth)
        _fifo_ports(self)

    def elaborate(self, platform):
        m = Module()
        do_read = Signal()
        m.d.comb += [self.w_rdy.eq(self.level != self.depth),
                     self.r_rdy.eq(self.level != 0),
                     do_read.eq(self.r_rdy & self.r_en)]
        mem = m.submodules.storage = Memory(shape=self.width, depth=self.depth, init=[])
        wp = mem.write_port()
        rp = mem.read_port(domain="comb")
        produce = Signal(range(self.depth))
        consume = Signal(range(self.depth))
        m.d.comb += [wp.addr.eq(produce), wp.data.eq(self.w_data), wp.en.eq(self.w_en),
                     rp.addr.eq(consume), self.r_data.eq(rp.data)]
        with m.If(self.w_en):
            m.d.sync += produce.eq(incr_modulo(produce, self.depth))
        with m.If(do_read):
            m.d.sync += consume.eq(incr_modulo(consume, self.depth))
        m.d.sync += self.level.eq(self.level + self.w_en - do_read)
        return m
