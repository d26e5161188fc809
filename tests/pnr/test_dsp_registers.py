"""Registers moved into the ECP5 multiplier blocks: the packed netlist equals the RTL.

The FP multiplier is synthesised with ``synth_ecp5`` and packed
(:mod:`raplas_hdl.pnr.dsp_registers`); its netlist, flattened to generic logic with Yosys's
cell models and a model of the registered ``MULT18X18D``, runs under Icarus in one testbench
beside the Amaranth Verilog it came from, on the same inputs (special operands, random ones,
random ``en`` stalls). Every output bit of every cycle must be equal, and the valid results
must equal the golden model. The unit tests of the pass check what it refuses to pack.
"""

import copy
import shutil
import subprocess

import numpy as np
import pytest

from raplas_hdl.fp import model
from raplas_hdl.fp.format import parse_format
from raplas_hdl.pnr.dsp_registers import mult18x18d_sim_model, pack_dsp_registers
from raplas_hdl.pnr.ecp5 import synthesize_ecp5
from raplas_hdl.pnr.netlist_sim import simulation_netlist
from raplas_hdl.pnr.unit import unit_verilog

TB = """module tb;
  reg clk = 0, rst = 1, i_valid = 0, en = 1;
  reg [{w1}:0] a = 0, b = 0;
  wire [{w1}:0] o_rtl, o_net; wire [2:0] f_rtl, f_net; wire v_rtl, v_net;
  {top} rtl(.clk(clk), .rst(rst), .a(a), .b(b), .i_valid(i_valid), .en(en), .o(o_rtl),
            .flags(f_rtl), .o_valid(v_rtl));
  net_top net(.clk(clk), .rst(rst), .a(a), .b(b), .i_valid(i_valid), {net_en}, .o(o_net),
              .flags(f_net), .o_valid(v_net));
  reg [63:0] vec [0:{n1}];
  integer i, fd;
  initial begin
    $readmemh("vec.hex", vec);
    fd = $fopen("out.txt", "w");
    #5 clk = 1; #5 clk = 0; #5 clk = 1; #5 clk = 0; rst = 0;
    for (i = 0; i < {n}; i = i + 1) begin
      {{en, i_valid, a, b}} = vec[i];
      #5 clk = 1; #1;
      $fwrite(fd, "%h %h %h %h %h %h\\n", o_rtl, f_rtl, v_rtl, o_net, f_net, v_net);
      #4 clk = 0;
    end
    $fclose(fd);
    $finish;
  end
endmodule
"""


def _vectors(fmt, n, seed):
    rng = np.random.default_rng(seed)
    m = fmt.man_bits
    special = np.array([0, 1, fmt.one, fmt.inf, fmt.nan, fmt.max_finite, fmt.min_normal,
                        fmt.man_mask, fmt.one | fmt.man_mask, (fmt.bias + 20) << m,
                        (fmt.bias - 20) << m | 5], dtype=np.int64)
    special = np.concatenate([special, special | fmt.sign_bit])
    a = rng.integers(0, 1 << fmt.width, n)
    b = rng.integers(0, 1 << fmt.width, n)
    pick = rng.random(n)
    a = np.where(pick < 0.2, special[rng.integers(0, special.size, n)], a)
    b = np.where((pick > 0.1) & (pick < 0.3), special[rng.integers(0, special.size, n)], b)
    valid = rng.random(n) < 0.8
    en = np.ones(n, dtype=bool)
    en[n // 4:] = rng.random(n - n // 4) < 0.7          # stalls after a stall-free run
    en[-12:] = True                                     # drain
    valid[-12:] = False
    return a, b, valid, en


#: The multiplier behind an inverted enable (port ``en_n``, the testbench drives ``~en``):
#: Yosys maps its registers with ``CEMUX`` ``INV``, which the pass feeds to the block
#: through a LUT4 inverter.
INVERTED_TOP = """module inv_top(input clk, input rst, input [{w1}:0] a, input [{w1}:0] b,
               input i_valid, input en_n, output [{w1}:0] o, output [2:0] flags,
               output o_valid);
  {top} u(.clk(clk), .rst(rst), .a(a), .b(b), .i_valid(i_valid), .en(~en_n), .o(o),
          .flags(flags), .o_valid(o_valid));
endmodule
"""


@pytest.mark.parametrize("fmt_name,enable", [("e7m16-rtz", "plain"), ("e7m16-rne", "plain"),
                                             ("e7m16-rtz", "inverted")])
def test_packed_multiplier_equals_rtl_and_model(fmt_name, enable, tmp_path):
    if shutil.which("iverilog") is None:
        pytest.fail("Icarus Verilog (iverilog) is needed: apt-get install iverilog")
    fmt = parse_format(fmt_name)
    text, top, latency = unit_verilog("fp-mul", fmt, {})
    synth_text, synth_top = text, top
    if enable == "inverted":
        synth_text += INVERTED_TOP.format(w1=fmt.width - 1, top=top)
        synth_top = "inv_top"
    syn = synthesize_ecp5(synth_text, synth_top, base=tmp_path, use_cache=False)
    assert syn.counts["mult18"] == 1 and syn.counts["mult18_registered"] == 1
    yosys_net = (syn.work / "net-yosys.json").read_text()
    assert ('"CEMUX": "INV"' in yosys_net) == (enable == "inverted")
    net = simulation_netlist(syn.work / "net.json", synth_top, "net_top")
    assert 'REG_INPUTA_CLK("CLK0")' in net and 'REG_OUTPUT_CLK("CLK0")' in net

    n = 3000
    a, b, valid, en = _vectors(fmt, n, seed=len(fmt_name))
    words = ((en.astype(np.int64) << (2 * fmt.width + 1)) | (valid.astype(np.int64)
             << (2 * fmt.width)) | (a << fmt.width) | b)
    (tmp_path / "vec.hex").write_text("".join(f"{w:016x}\n" for w in words))
    (tmp_path / "all.v").write_text(text + net + mult18x18d_sim_model()
                                    + TB.format(w1=fmt.width - 1, n=n, n1=n - 1, top=top,
                                                net_en=(".en_n(~en)" if enable == "inverted"
                                                        else ".en(en)")))
    subprocess.run(["iverilog", "-g2005", "-o", "sim.vvp", "all.v"], cwd=tmp_path, check=True,
                   capture_output=True)
    subprocess.run(["vvp", "-n", "sim.vvp"], cwd=tmp_path, check=True, capture_output=True)
    rows = [line.split() for line in (tmp_path / "out.txt").read_text().splitlines()]
    assert len(rows) == n, "the simulation stopped early"
    for cycle, r in enumerate(rows):
        assert "x" not in "".join(r), f"cycle {cycle}: an undefined output bit: {r}"
        assert r[:3] == r[3:], f"cycle {cycle}: RTL {r[:3]} but packed netlist {r[3:]}"
    # a result is new after an enabled edge (a stall holds it on the outputs)
    got = [(int(r[0], 16), int(r[1], 16)) for r, e in zip(rows, en) if r[2] == "1" and e]
    taken = valid & en
    want_o, want_f = model.mul(a[taken].astype(np.uint32), b[taken].astype(np.uint32), fmt,
                               flags=True)
    assert len(got) == int(taken.sum())
    assert [g[0] for g in got] == [int(x) for x in want_o]
    assert [g[1] for g in got] == [int(x) for x in want_f]
    # the first valid result comes `latency` enabled clocks after its input
    first = int(np.argmax(taken))
    out_cycle = next(i for i, r in enumerate(rows) if r[2] == "1")
    assert int(en[first:out_cycle + 1].sum()) == latency


# -- the pass on small hand-made netlists ---------------------------------------------------
def _ff(d, q, ce=90, lsr="0", **par):
    return {"type": "TRELLIS_FF",
            "parameters": {"CEMUX": "CE", "CLKMUX": "CLK", "GSR": "DISABLED",
                           "LSRMUX": "LSR", "REGSET": "RESET", **par},
            "port_directions": {"CE": "input", "CLK": "input", "DI": "input",
                                "LSR": "input", "Q": "output"},
            "connections": {"CE": [ce], "CLK": [91], "DI": [d], "LSR": [lsr], "Q": [q]}}


def _netlist():
    """One multiply, 2-bit operands: FFs a (DI 2,3 -> Q 10,11), b (4,5 -> 12,13) in, product
    bits P0..P3 (20..23) into FFs (Q 30..33)."""
    cells = {f"fa{i}": _ff(2 + i, 10 + i) for i in range(2)}
    cells.update({f"fb{i}": _ff(4 + i, 12 + i) for i in range(2)})
    cells.update({f"fp{i}": _ff(20 + i, 30 + i) for i in range(4)})
    con = {f"A{i}": [10 + i] if i < 2 else ["0"] for i in range(18)}
    con.update({f"B{i}": [12 + i] if i < 2 else ["0"] for i in range(18)})
    con.update({f"P{i}": [20 + i] if i < 4 else [100 + i] for i in range(36)})
    dirs = {p: ("output" if p[0] == "P" else "input") for p in con}
    cells["mul"] = {"type": "MULT18X18D", "parameters": {}, "port_directions": dirs,
                    "connections": con}
    ports = {"q": {"direction": "output", "bits": [30, 31, 32, 33]}}
    return {"modules": {"top": {"ports": ports, "cells": cells}}}


def test_pack_moves_the_registers_into_the_block():
    net = _netlist()
    stats = pack_dsp_registers(net)
    assert stats == {"mult18": 1, "registered": 1, "ff_removed": 8}
    cells = net["modules"]["top"]["cells"]
    assert set(cells) == {"mul"}
    mul = cells["mul"]
    assert mul["connections"]["A0"] == [2] and mul["connections"]["B1"] == [5]
    assert [mul["connections"][f"P{i}"] for i in range(4)] == [[30], [31], [32], [33]]
    assert mul["connections"]["CLK0"] == [91] and mul["connections"]["CE0"] == [90]
    assert mul["connections"]["RST0"] == ["0"]
    for reg in ("INPUTA", "INPUTB", "OUTPUT"):
        assert mul["parameters"][f"REG_{reg}_CLK"] == "CLK0"


@pytest.mark.parametrize("change", ["sync_reset", "other_enable", "product_to_logic",
                                    "input_from_logic", "inverted_clock", "set_value"])
def test_pack_leaves_what_it_cannot_move(change):
    net = _netlist()
    cells = net["modules"]["top"]["cells"]
    if change == "sync_reset":
        cells["fa0"]["connections"]["LSR"] = [77]
    elif change == "other_enable":
        cells["fp2"]["connections"]["CE"] = [78]
    elif change == "product_to_logic":
        cells["lut"] = {"type": "LUT4", "parameters": {}, "port_directions": {"A": "input",
                        "Z": "output"}, "connections": {"A": [21], "Z": [79]}}
    elif change == "input_from_logic":
        del cells["fb1"]
        cells["lut"] = {"type": "LUT4", "parameters": {}, "port_directions": {"A": "input",
                        "Z": "output"}, "connections": {"A": [5], "Z": [13]}}
    elif change == "inverted_clock":
        cells["fp0"]["parameters"]["CLKMUX"] = "INV"
    else:
        cells["fb0"]["parameters"]["REGSET"] = "SET"
    before = copy.deepcopy(net)
    stats = pack_dsp_registers(net)
    assert stats["registered"] == 0 and stats["ff_removed"] == 0
    assert net == before


def test_an_inverted_enable_reaches_the_block_through_one_inverter():
    net = _netlist()
    cells = net["modules"]["top"]["cells"]
    for c in cells.values():
        if c["type"] == "TRELLIS_FF":
            c["parameters"]["CEMUX"] = "INV"
    twin = copy.deepcopy(cells["mul"])
    twin["connections"].update({f"P{i}": [40 + i] for i in range(4)})
    cells["mul2"] = twin
    cells.update({f"fq{i}": _ff(40 + i, 50 + i, CEMUX="INV") for i in range(4)})
    stats = pack_dsp_registers(net)
    assert stats["registered"] == 2
    luts = [c for c in cells.values() if c["type"] == "LUT4"]
    assert len(luts) == 1                                 # one inverter per enable net
    inv = luts[0]
    assert inv["connections"]["A"] == [90]
    init = inv["parameters"]["INIT"]                      # Z = INIT[{D,C,B,A}], B=C=D=0
    assert init[-1] == "1" and init[-2] == "0"
    z = inv["connections"]["Z"][0]
    assert z not in (90, 91) and cells["mul"]["connections"]["CE0"] == [z]
    assert cells["mul2"]["connections"]["CE0"] == [z]


def test_always_enabled_registers_as_yosys_writes_them_are_packed():
    net = _netlist()
    for c in net["modules"]["top"]["cells"].values():
        if c["type"] == "TRELLIS_FF":
            c["parameters"]["CEMUX"] = "1 "              # padded, as in synth_ecp5's JSON
            del c["connections"]["CE"]
    assert pack_dsp_registers(net)["registered"] == 1
    assert net["modules"]["top"]["cells"]["mul"]["connections"]["CE0"] == ["1"]


def test_plain_and_inverted_enables_do_not_mix():
    net = _netlist()
    net["modules"]["top"]["cells"]["fp1"]["parameters"]["CEMUX"] = "INV"
    before = copy.deepcopy(net)
    assert pack_dsp_registers(net)["registered"] == 0
    assert net == before


def test_shared_input_register_becomes_one_per_block():
    net = _netlist()
    cells = net["modules"]["top"]["cells"]
    twin = copy.deepcopy(cells["mul"])
    twin["connections"].update({f"P{i}": [40 + i] for i in range(4)})
    cells["mul2"] = twin
    cells.update({f"fq{i}": _ff(40 + i, 50 + i) for i in range(4)})
    stats = pack_dsp_registers(net)
    assert stats["registered"] == 2
    assert not any(c["type"] == "TRELLIS_FF" for c in cells.values())
    assert cells["mul2"]["connections"]["A1"] == [3]
