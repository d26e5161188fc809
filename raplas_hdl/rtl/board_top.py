"""Board-level top: the intersection unit behind a 32-bit Wishbone B4 classic slave.

The register map (word addresses, fields, side effects) is
:data:`raplas_hdl.model.board_map.REGISTER_MAP`, shared with the host driver
(:mod:`raplas_hdl.link.driver`) and documented in ``docs/board-top.md``.

Ports (plain names, so that board constraints can name them; see
:mod:`raplas_hdl.rtl.constraints`):

- ``clk``: the only clock; ``rst``: active-high reset, asynchronous to ``clk`` (a button or
  a board's power-on reset). It goes through a two-flop reset synchroniser (asserted at
  once, released on a clock edge), so it needs no timing relation to ``clk``;
- Wishbone B4 classic slave, port size 32, granularity 32: ``wb_adr`` (word address,
  :data:`~raplas_hdl.model.board_map.ADDR_BITS` bits), ``wb_dat_w``, ``wb_dat_r``,
  ``wb_sel`` (accepted, ignored), ``wb_we``, ``wb_cyc``, ``wb_stb``, ``wb_ack``, ``wb_err``.

Bus timing: ``wb_ack`` (or ``wb_err``) is registered, high for one cycle, the cycle after
the slave sees ``wb_cyc & wb_stb``; a write's effect and a read's side effect (the pop of
``RES_INFO``) take place on that same clock edge, once per access. Back-to-back accesses
take two cycles each. ``wb_dat_r`` is valid while ``wb_ack`` is high.

Stages: Wishbone decode (1 cycle) -> unit write port (``MEM_DATA`` writes reach the
unit's write port one cycle after their ack) / one-deep command slot -> the unit's
``cmd`` stream. Results leave the unit's ``o`` stream only on a ``RES_INFO`` read, so a
slow host stalls the unit and no beat is dropped.
"""

from __future__ import annotations

from amaranth.hdl import ClockDomain, Const, Module, Signal
from amaranth.lib import wiring
from amaranth.lib.cdc import ResetSynchronizer
from amaranth.lib.wiring import In, Out

from ..model.board_map import (ADDR_BITS, BOARD_ID, CMD_BANK_BIT, CMD_COUNT_BITS,
                               CMD_INDIRECT_BIT, CMD_KEEP_ALL_BIT, CONTROL_BITS,
                               COUNTER_REGS, MAP_VERSION, MODE_CODES, REGISTERS, RES_INFO_BITS,
                               RES_INFO_WORD, RES_RAY_SHIFT, STATUS_BITS, config_words)
from ..model.config import UnitConfig
from ..model.records import output_record
from .intersection import IntersectionUnit

__all__ = ["BoardTop", "build_board_top", "CLOCK_PORT", "RESET_PORT"]

#: The clock and the asynchronous reset (the only ports whose role constraints need).
CLOCK_PORT = "clk"
RESET_PORT = "rst"

class BoardTop(wiring.Component):
    """The intersection unit with a Wishbone register interface.

    Parameters
    ----------
    config : UnitConfig, optional
        Build parameters of the unit; alternatively pass them as keywords.
    multiplier, adder : {"generic", "virtex4"}
        Significand multipliers and FP adders of the unit (see :class:`IntersectionUnit`).
    own_domain : bool
        Define the ``sync`` domain from ``clk`` and ``rst`` (default); False in a design that
        defines it (:class:`~raplas_hdl.rtl.serial_board.SerialBoard`; ``clk`` and ``rst``
        are then unused).

    Members
    -------
    clk, rst : In(1)
        Clock; asynchronous active-high reset (synchronised inside).
    wb_adr : In(ADDR_BITS)
        Word address.
    wb_dat_w, wb_dat_r : In(32), Out(32)
    wb_sel : In(4)
        Ignored (granularity 32).
    wb_we, wb_cyc, wb_stb : In(1)
    wb_ack, wb_err : Out(1)
        ``wb_err`` answers an unmapped address or a refused ``CMD_START``.

    Raises
    ------
    ValueError
        On out-of-range parameters (see :class:`UnitConfig`), or a format wider than 32 bits.
    """

    def __init__(self, config: UnitConfig | None = None, *, multiplier: str = "generic",
                 adder: str = "generic", own_domain: bool = True, **params):
        if config is None:
            config = UnitConfig(**params)
        elif params:
            raise ValueError("pass either a UnitConfig or keyword parameters, not both")
        if not isinstance(config, UnitConfig):
            raise ValueError(f"config must be a UnitConfig, not {config!r}")
        if config.fmt.width > 32:
            raise ValueError(f"the board top reads results as 32-bit words; {config.fmt} is "
                             f"{config.fmt.width} bits wide")
        if config.mode not in MODE_CODES:
            raise ValueError(f"the board top's register map has modes "
                             f"{', '.join(MODE_CODES)}, not {config.mode!r}")
        self._cfg = config
        self._head_fields = {f.name for f in output_record(config).fields}
        self._own_domain = bool(own_domain)
        self._multiplier = multiplier
        self._adder = adder
        super().__init__({
            CLOCK_PORT: In(1), RESET_PORT: In(1),
            "wb_adr": In(ADDR_BITS), "wb_dat_w": In(32), "wb_dat_r": Out(32),
            "wb_sel": In(4), "wb_we": In(1), "wb_cyc": In(1), "wb_stb": In(1),
            "wb_ack": Out(1), "wb_err": Out(1),
        })

    @property
    def config(self) -> UnitConfig:
        return self._cfg

    @property
    def latency(self):
        """None: the delay depends on the scene and on the host."""
        return None

    def elaborate(self, platform):
        cfg = self._cfg
        m = Module()
        if self._own_domain:
            m.domains.sync = cd = ClockDomain("sync")
            m.d.comb += cd.clk.eq(getattr(self, CLOCK_PORT))
            m.submodules.reset_sync = ResetSynchronizer(getattr(self, RESET_PORT),
                                                        domain="sync")
        # (the keyword only when it is not the default: the unit took it later)
        extra = {k: v for k, v in (("multiplier", self._multiplier), ("adder", self._adder))
                 if v != "generic"}
        m.submodules.unit = unit = IntersectionUnit(cfg, **extra)

        # -- registers ----------------------------------------------------------------------
        mem_addr = Signal(32)
        cmd_first = Signal(32)
        cmd_valid = Signal()
        cmd_count = Signal(CMD_COUNT_BITS)
        cmd_bank = Signal()
        cmd_ind = Signal()
        cmd_keep = Signal()
        overrun = Signal()
        latch = Signal(unit.result_layout)

        m.d.comb += [unit.cmd.valid.eq(cmd_valid),
                     unit.cmd.payload.first.eq(cmd_first),
                     unit.cmd.payload.count.eq(cmd_count),
                     unit.cmd.payload.bank.eq(cmd_bank),
                     unit.cmd.payload.indirect.eq(cmd_ind),
                     unit.cmd.payload.keep_all.eq(cmd_keep)]
        with m.If(unit.cmd.valid & unit.cmd.ready):
            m.d.sync += cmd_valid.eq(0)

        # -- Wishbone ------------------------------------------------------------------------
        req = Signal()
        m.d.comb += req.eq(self.wb_cyc & self.wb_stb & ~self.wb_ack & ~self.wb_err)
        m.d.sync += [self.wb_ack.eq(0), self.wb_err.eq(0), unit.wr_en.eq(0), unit.clear.eq(0)]
        rd = Signal(32)      # read data of the addressed register
        mapped = Signal()
        refuse = Signal()
        consts = {"ID": BOARD_ID, "VERSION": MAP_VERSION[0] << 16 | MAP_VERSION[1],
                  **config_words(cfg.params())}
        status = Signal(32)
        sb = STATUS_BITS
        m.d.comb += [status[sb["busy"]].eq(unit.busy | cmd_valid),
                     status[sb["result_valid"]].eq(unit.o.valid),
                     status[sb["fifo_overflow"]].eq(unit.fifo_overflow),
                     status[sb["cmd_full"]].eq(cmd_valid),
                     status[sb["cmd_overrun"]].eq(overrun)]
        info = Signal(32)
        ib = RES_INFO_BITS
        head = unit.o.payload
        m.d.comb += info[ib["valid"]].eq(1)
        # the fields the unit's output record has (answers: no hit; certified: outcome, tight)
        for f in RES_INFO_WORD.fields[1:]:
            if f.name in self._head_fields:
                m.d.comb += info[ib[f.name]:ib[f.name] + f.width].eq(head[f.name])
        write = req & self.wb_we
        read = req & ~self.wb_we
        regs = REGISTERS
        with m.Switch(self.wb_adr):
            for name, value in consts.items():
                with m.Case(regs[name]):
                    m.d.comb += [mapped.eq(1), rd.eq(Const(value, 32))]
            with m.Case(regs["STATUS"]):
                m.d.comb += [mapped.eq(1), rd.eq(status)]
            with m.Case(regs["CONTROL"]):
                m.d.comb += mapped.eq(1)
                with m.If(write):
                    m.d.sync += unit.clear.eq(self.wb_dat_w[CONTROL_BITS["clear_counters"]])
                    with m.If(self.wb_dat_w[CONTROL_BITS["clear_overrun"]]):
                        m.d.sync += overrun.eq(0)
            with m.Case(regs["MEM_ADDR"]):
                m.d.comb += [mapped.eq(1), rd.eq(mem_addr)]
                with m.If(write):
                    m.d.sync += mem_addr.eq(self.wb_dat_w)
            with m.Case(regs["MEM_DATA"]):
                m.d.comb += mapped.eq(1)
                with m.If(write):
                    m.d.sync += [unit.wr_en.eq(1), unit.wr_addr.eq(mem_addr),
                                 unit.wr_data.eq(self.wb_dat_w), mem_addr.eq(mem_addr + 1)]
            with m.Case(regs["CMD_FIRST"]):
                m.d.comb += [mapped.eq(1), rd.eq(cmd_first)]
                with m.If(write):
                    m.d.sync += cmd_first.eq(self.wb_dat_w)
            with m.Case(regs["CMD_START"]):
                m.d.comb += mapped.eq(1)
                with m.If(write):
                    with m.If(cmd_valid):
                        m.d.comb += refuse.eq(1)
                        m.d.sync += overrun.eq(1)
                    with m.Else():
                        w = self.wb_dat_w
                        m.d.sync += [cmd_valid.eq(1), cmd_count.eq(w[:CMD_COUNT_BITS]),
                                     cmd_bank.eq(w[CMD_BANK_BIT]),
                                     cmd_ind.eq(w[CMD_INDIRECT_BIT]),
                                     cmd_keep.eq(w[CMD_KEEP_ALL_BIT])]
            with m.Case(regs["RES_INFO"]):
                m.d.comb += mapped.eq(1)
                with m.If(unit.o.valid):
                    m.d.comb += [rd.eq(info), unit.o.ready.eq(read)]
                    with m.If(read):
                        m.d.sync += latch.eq(head)
            with m.Case(regs["RES_IDS"]):
                m.d.comb += [mapped.eq(1),
                             rd.eq(latch.tri_id | (latch.ray_id << RES_RAY_SHIFT))]
            for name in ("t", "u", "v", "det"):
                with m.Case(regs[f"RES_{name.upper()}"]):
                    m.d.comb += [mapped.eq(1), rd.eq(latch[name])]
            for name, reg in COUNTER_REGS.items():
                with m.Case(regs[reg]):
                    m.d.comb += [mapped.eq(1), rd.eq(unit.counters[name])]
        with m.If(req):
            with m.If(mapped & ~refuse):
                m.d.sync += self.wb_ack.eq(1)
            with m.Else():
                m.d.sync += self.wb_err.eq(1)
            with m.If(~self.wb_we):
                m.d.sync += self.wb_dat_r.eq(rd)
        return m


def build_board_top(fmt=None, multiplier: str = "generic", adder: str = "generic",
                    **params) -> BoardTop:
    """Builder for ``raplas-hdl verilog board-top`` (keywords of :class:`UnitConfig`, and
    ``multiplier``, ``adder``)."""
    if fmt is not None:
        params["fmt"] = fmt
    return BoardTop(UnitConfig(**params), multiplier=multiplier, adder=adder)
