"""The intersection unit's RAM wrapper: parameters checked, and the Verilog implementation
free of per-word initial values (its behaviour is checked against the golden model by the
unit's cocotb tests, which build the unit with ``ram="verilog"``)."""

import pytest
from amaranth.hdl import Module

from raplas_hdl.fp import FP24
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.rtl.emit import emit_verilog
from raplas_hdl.rtl.intersection import IntersectionUnit
from raplas_hdl.rtl.ram import RAM_MODULE, SyncRAM, ram_verilog


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
    assert text.count(f"{RAM_MODULE} #(") == 8          # the unit's eight memories
    assert "mem[4095]" not in text and "_mem[0] =" not in text
    assert f"module {RAM_MODULE}" in ram_verilog()
