"""The intersection unit's RAM wrapper: parameters checked, the Verilog implementation free
of per-word initial values (its behaviour is checked against the golden model by the unit's
cocotb tests, which build the unit with ``ram="verilog"``), and a ``collision_free`` RAM
mapped by ``synth_ecp5`` to block RAM alone, with no read-during-write logic."""

import pytest
from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from raplas_hdl.fp import FP24
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.pnr.ecp5 import synthesize_ecp5
from raplas_hdl.rtl.emit import emit_verilog
from raplas_hdl.rtl.intersection import IntersectionUnit
from raplas_hdl.rtl.ram import RAM_MODULE, RAM_MODULE_NO_RW_CHECK, SyncRAM, ram_verilog


def test_bad_parameters_name_the_problem():
    with pytest.raises(ValueError, match="ram must be one of"):
        SyncRAM(8, 16, impl="bram")
    with pytest.raises(ValueError, match="positive width and depth"):
        SyncRAM(8, 0)
    ram = SyncRAM(24, 16)
    with pytest.raises(ValueError, match="does not divide"):
        ram.write_port(granularity=7)
    ram.write_port(granularity=8)
    with pytest.raises(ValueError, match="one write port"):
        ram.write_port()
    with pytest.raises(ValueError, match="read port"):
        ram.add_to(Module())
    with pytest.raises(ValueError, match="ram must be one of"):
        IntersectionUnit(UnitConfig(fmt=FP24), ram="block")


def test_verilog_rams_have_no_initial_values():
    cfg = UnitConfig(fmt=FP24, rows=2, cols=2, testers=1, tris_per_sphere=2,
                     max_triangles=4096, max_spheres=512, fifo_depth=4)
    text, _ = emit_verilog(IntersectionUnit(cfg, ram="verilog"), "intersection_unit",
                           cfg.params())
    # the unit's eight memories, each collision-free (the host never writes what a run reads)
    assert text.count(f"{RAM_MODULE_NO_RW_CHECK} #(") == 8
    assert text.count(f"{RAM_MODULE} #(") == 0
    assert "mem[4095]" not in text and "_mem[0] =" not in text
    rams = ram_verilog()
    assert f"module {RAM_MODULE} " in rams and f"module {RAM_MODULE_NO_RW_CHECK} " in rams
    assert rams.count("(* no_rw_check *) reg [WIDTH-1:0] mem") == 1


def test_unit_memories_carry_no_rw_check():
    cfg = UnitConfig(fmt=FP24, rows=2, cols=2, testers=1, tris_per_sphere=2, fifo_depth=4)
    text, _ = emit_verilog(IntersectionUnit(cfg), "intersection_unit", cfg.params())
    assert text.count("(* no_rw_check = 32'd1 *)") == 8


class _RamTop(wiring.Component):
    """One 72-bit, 1024-word RAM with 24-bit write lanes and one read port."""

    waddr: In(10)
    wdata: In(72)
    wen: In(3)
    raddr: In(10)
    rdata: Out(72)

    def __init__(self, impl, collision_free):
        self.impl, self.collision_free = impl, collision_free
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        ram = SyncRAM(72, 1024, impl=self.impl, name="ram", collision_free=self.collision_free)
        w, r = ram.write_port(granularity=24), ram.read_port()
        m.d.comb += [w.addr.eq(self.waddr), w.data.eq(self.wdata), w.en.eq(self.wen),
                     r.addr.eq(self.raddr), self.rdata.eq(r.data)]
        ram.add_to(m)
        return m


@pytest.mark.parametrize("impl, collision_free",
                         [("memory", False), ("memory", True), ("verilog", True)])
def test_collision_free_ram_is_block_ram_alone_on_ecp5(impl, collision_free, tmp_path):
    text, _ = emit_verilog(_RamTop(impl, collision_free), "ram_top", {})
    if impl == "verilog":
        text += ram_verilog()
    counts = synthesize_ecp5(text, "ram_top", base=tmp_path, use_cache=False).counts
    assert counts["ebr"] >= 4
    if collision_free:
        # the block RAMs' outputs are the read data: no register, no multiplexer behind them
        assert counts["ff"] == 0 and counts["lut4"] <= 2
    else:
        # the old word on a collision: the written word and the address match registered,
        # and a multiplexer on each of the 72 bits
        assert counts["ff"] >= 72 and counts["lut4"] >= 72
