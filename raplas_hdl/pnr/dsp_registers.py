"""Fabric registers moved into the ECP5 multiplier blocks of a ``synth_ecp5`` netlist.

Yosys maps each ``a * b`` onto a ``MULT18X18D`` with every register of the block unused, so
the registers the RTL puts on each side of the multiply stay in the fabric, and a
register-to-register path runs out of a slice, through the block and back: 3.9 ns of
multiplier and 5-6 ns of routing at speed 6, the slowest path of the plane-sphere array and
the whole intersection unit. Lattice's own synthesis moves such registers into the block;
this pass does the same on the netlist JSON before nextpnr, so a registered block's paths
end at its input registers and start at its output register.

A ``MULT18X18D`` is packed when all of these hold, and left as it is otherwise:

* every ``A`` and ``B`` input bit is a constant or the ``Q`` of a ``TRELLIS_FF``;
* every used ``P`` output bit has one load, the ``DI`` of a ``TRELLIS_FF``, and its net is
  not a port of the module; at least one ``P`` bit is used;
* these flip-flops are plain registers on one clock: ``CLKMUX`` ``CLK`` on the same net,
  the same clock enable (``CEMUX`` ``CE`` on the same net, or all ``INV`` on the same net,
  or all enabled always), no set or reset (``LSR`` the constant 0), reset value 0
  (``REGSET`` ``RESET``, which is also what the block's registers hold after configuration)
  and the same ``GSR`` setting.

Packing then gives the block ``REG_INPUTA_CLK = REG_INPUTB_CLK = REG_OUTPUT_CLK = "CLK0"``
with ``CE0``/``RST0``, connects ``CLK0`` to the clock, ``CE0`` to the enable and ``RST0``
to 0, and wires each ``A``/``B`` bit to its flip-flop's ``DI`` (the block's input register
takes the flip-flop's place) and each ``P`` bit to its flip-flop's ``Q`` net. The block's
``CE0`` has no inversion: an enable the flip-flops took inverted (``CEMUX`` ``INV``, as Yosys
maps ``en = ~x``, the reducer's) comes through a ``LUT4`` inverter, one per net, shared by
the blocks; netlists without such registers pack as before. A flip-flop left without a load
is removed, so an input register shared by several multipliers (Yosys merges equal
registers) becomes one register per block. Every cycle's values are those of the netlist
before packing: the same registers, moved (``tests/pnr/test_dsp_registers.py`` simulates a
packed multiplier, behind a plain and an inverted enable, against the golden model, with a
block model of its own).
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

__all__ = ["pack_dsp_registers", "pack_netlist_file", "mult18x18d_sim_model"]

_CONST = ("0", "1", "x", "z")


def _is_bit(b) -> bool:
    return not isinstance(b, str)


def _io_bits(ports: dict) -> set:
    return {b for p in ports.values() for b in p["bits"] if _is_bit(b)}


def _ff_class(cell: dict):
    """``(clock net, enable net or '1', GSR)`` of a plain flip-flop, else None."""
    par, con = cell["parameters"], cell["connections"]
    if par.get("CLKMUX", "CLK") != "CLK" or par.get("REGSET", "RESET") != "RESET":
        return None
    lsr = con.get("LSR", ["0"])[0]
    if lsr != "0" and par.get("LSRMUX", "LSR") != "0":
        return None
    cemux = str(par.get("CEMUX", "CE")).strip()       # Yosys writes "1 " for always on
    ce = con.get("CE", ["1"])[0]
    if cemux == "1" or (ce == "1" and cemux == "CE"):
        ce = "1"
    elif cemux not in ("CE", "INV") or not _is_bit(ce):
        return None
    elif cemux == "INV":
        ce = ("INV", ce)
    clk = con.get("CLK", [None])[0]
    if not _is_bit(clk):
        return None
    return clk, ce, par.get("GSR", "ENABLED")


def _pack_module(mod: dict) -> dict:
    cells = mod["cells"]
    driver, loads = {}, defaultdict(list)
    for name, c in cells.items():
        dirs = c.get("port_directions", {})
        for port, bits in c["connections"].items():
            for i, b in enumerate(bits):
                if not _is_bit(b):
                    continue
                if dirs.get(port) == "output":
                    driver[b] = (name, port)
                else:
                    loads[b].append((name, port, i))
    io = _io_bits(mod.get("ports", {}))
    stats = {"mult18": 0, "registered": 0, "ff_removed": 0}
    removed: set[str] = set()
    inverted: dict = {}          # enable net -> the net of its LUT4 inverter
    named = [b for n in mod.get("netnames", {}).values() for b in n.get("bits", ())
             if _is_bit(b)]
    next_bit = [max([*driver, *loads, *io, *named, 0]) + 1]      # a net no one uses yet

    def enable_net(ce):
        """The net for ``CE0``: ``ce`` itself, or its inverse through a LUT4."""
        if not isinstance(ce, tuple):
            return ce
        net = ce[1]
        if net not in inverted:
            z = inverted[net] = next_bit[0]
            next_bit[0] += 1
            name = f"$dsp_ce_inv_{net}"
            cells[name] = {"hide_name": 1, "type": "LUT4",
                           "parameters": {"INIT": "0101010101010101"},      # Z = ~A
                           "port_directions": {"A": "input", "B": "input", "C": "input",
                                               "D": "input", "Z": "output"},
                           "connections": {"A": [net], "B": ["0"], "C": ["0"], "D": ["0"],
                                           "Z": [z]}}
            loads[net].append((name, "A", 0))
            driver[z] = (name, "Z")
        return inverted[net]

    for name, c in list(cells.items()):
        if c["type"] != "MULT18X18D":
            continue
        stats["mult18"] += 1
        par, con = c["parameters"], c["connections"]
        if any(str(par.get(f"REG_{r}_CLK", "NONE")).strip() != "NONE"
               for r in ("INPUTA", "INPUTB", "INPUTC", "PIPELINE", "OUTPUT")):
            continue
        plan = _plan(c, cells, driver, loads, io, removed)
        if plan is None:
            continue
        ins, outs, (clk, ce, gsr) = plan
        ce = enable_net(ce)
        for port, ff in ins:                 # the block's input register replaces the FF
            di = cells[ff]["connections"]["DI"][0]
            old = con[port][0]
            con[port] = [di]
            loads[old].remove((name, port, 0))
            if _is_bit(di):
                loads[di].append((name, port, 0))
        for port, ff in outs:                # the block's output register replaces the FF
            q = cells[ff]["connections"]["Q"][0]
            old = con[port][0]
            con[port] = [q]
            loads.pop(old, None)
            driver[q] = (name, port)
            _remove(cells[ff], ff, loads, removed)
        for _, ff in ins:
            q = cells[ff]["connections"]["Q"][0]
            if ff not in removed and not loads[q] and q not in io:
                _remove(cells[ff], ff, loads, removed)
        for reg in ("INPUTA", "INPUTB", "OUTPUT"):
            par[f"REG_{reg}_CLK"] = "CLK0"
            par[f"REG_{reg}_CE"] = "CE0"
            par[f"REG_{reg}_RST"] = "RST0"
        par["GSR"] = gsr
        con["CLK0"], con["CE0"], con["RST0"] = [clk], [ce], ["0"]
        dirs = c.setdefault("port_directions", {})
        dirs["CLK0"] = dirs["CE0"] = dirs["RST0"] = "input"
        loads[clk].append((name, "CLK0", 0))
        if _is_bit(ce):
            loads[ce].append((name, "CE0", 0))
        stats["registered"] += 1
    for ff in removed:
        del cells[ff]
    stats["ff_removed"] = len(removed)
    return stats


def _remove(cell, name, loads, removed):
    """Mark the flip-flop ``name`` removed and take it off the loads of its input nets."""
    removed.add(name)
    for port, bits in cell["connections"].items():
        if cell["port_directions"].get(port) == "input" and _is_bit(bits[0]):
            if (name, port, 0) in loads[bits[0]]:
                loads[bits[0]].remove((name, port, 0))


def _plan(c, cells, driver, loads, io, removed):
    """``(input FFs, output FFs, (clk, ce, gsr))`` when the block can be packed, else None."""
    con = c["connections"]
    classes, ins, outs = set(), [], []
    for port, bits in con.items():
        if port[0] not in "AB" or not port[1:].isdigit():
            continue
        b = bits[0]
        if not _is_bit(b):
            continue
        src = driver.get(b)
        if src is None or src[1] != "Q" or cells[src[0]]["type"] != "TRELLIS_FF" \
                or src[0] in removed:
            return None
        cls = _ff_class(cells[src[0]])
        if cls is None:
            return None
        classes.add(cls)
        ins.append((port, src[0]))
    for port, bits in con.items():
        if port[0] != "P" or not port[1:].isdigit():
            continue
        b = bits[0]
        if not _is_bit(b) or (not loads.get(b) and b not in io):
            continue
        users = loads.get(b, [])
        if b in io or len(users) != 1:
            return None
        ff, fport, _ = users[0]
        if fport != "DI" or cells[ff]["type"] != "TRELLIS_FF":
            return None
        cls = _ff_class(cells[ff])
        if cls is None:
            return None
        classes.add(cls)
        outs.append((port, ff))
    if not ins or not outs or len(classes) != 1:
        return None
    return ins, outs, classes.pop()


def pack_dsp_registers(netlist: dict) -> dict:
    """Pack the registers beside every ``MULT18X18D`` of ``netlist`` (Yosys JSON, changed in
    place). Returns ``{"mult18", "registered", "ff_removed"}`` summed over the modules."""
    total = {"mult18": 0, "registered": 0, "ff_removed": 0}
    for mod in netlist.get("modules", {}).values():
        for k, v in _pack_module(mod).items():
            total[k] += v
    return total


def pack_netlist_file(src: Path, dst: Path) -> dict:
    """:func:`pack_dsp_registers` from the JSON file ``src`` to ``dst``; the counts."""
    net = json.loads(Path(src).read_text())
    stats = pack_dsp_registers(net)
    Path(dst).write_text(json.dumps(net))
    return stats


def mult18x18d_sim_model() -> str:
    """A Verilog model of ``MULT18X18D`` as this pass configures it, for simulating a packed
    netlist (Yosys ships the block only as a black box).

    Covered: ``A * B`` (signed per ``SIGNEDA``/``SIGNEDB``, 36-bit product), and the input
    and output registers off (``"NONE"``) or on ``CLK0``/``CE0``/``RST0`` (synchronous
    reset first, then the clock enable; every register starts at 0). Any other register
    setting stops the simulation with an error, so the model cannot pass for what it does
    not cover."""
    ports = ([f"A{i}" for i in range(18)] + [f"B{i}" for i in range(18)]
             + [f"C{i}" for i in range(18)]
             + ["SIGNEDA", "SIGNEDB", "SOURCEA", "SOURCEB"]
             + [f"{p}{i}" for p in ("CLK", "CE", "RST") for i in range(4)])
    outs = [f"P{i}" for i in range(36)] + ["SIGNEDP"]
    cat = lambda p, n: "{" + ", ".join(f"{p}{i}" for i in reversed(range(n))) + "}"  # noqa: E731
    lines = [f"module MULT18X18D({', '.join(ports + outs)});"]
    lines += [f"  input {p};" for p in ports] + [f"  output {p};" for p in outs]
    for reg in ("INPUTA", "INPUTB", "INPUTC", "PIPELINE", "OUTPUT"):
        lines += [f'  parameter REG_{reg}_CLK = "NONE";', f'  parameter REG_{reg}_CE = "CE0";',
                  f'  parameter REG_{reg}_RST = "RST0";']
    lines += [
        '  parameter GSR = "ENABLED";', '  parameter RESETMODE = "SYNC";',
        '  parameter MULT_BYPASS = "DISABLED";', '  parameter SOURCEB_MODE = "B_SHIFT";',
        '  parameter CAS_MATCH_REG = "FALSE";', '  parameter HIGHSPEED_CLK = "NONE";',
        '  parameter CLK0_DIV = "ENABLED";', '  parameter CLK1_DIV = "ENABLED";',
        '  parameter CLK2_DIV = "ENABLED";', '  parameter CLK3_DIV = "ENABLED";',
        f"  wire [17:0] a = {cat('A', 18)};", f"  wire [17:0] b = {cat('B', 18)};",
        "  reg [17:0] ra = 18'd0, rb = 18'd0;", "  reg [35:0] rp = 36'd0;",
        "  reg sa = 1'b0, sb = 1'b0;",
        '  wire [17:0] xa = (REG_INPUTA_CLK == "NONE") ? a : ra;',
        '  wire [17:0] xb = (REG_INPUTB_CLK == "NONE") ? b : rb;',
        '  wire xsa = (REG_INPUTA_CLK == "NONE") ? SIGNEDA : sa;',
        '  wire xsb = (REG_INPUTB_CLK == "NONE") ? SIGNEDB : sb;',
        "  wire [35:0] wa = xsa ? {{18{xa[17]}}, xa} : {18'd0, xa};",
        "  wire [35:0] wb = xsb ? {{18{xb[17]}}, xb} : {18'd0, xb};",
        "  wire [35:0] prod = wa * wb;",
        '  wire [35:0] p = (REG_OUTPUT_CLK == "NONE") ? prod : rp;',
        f"  assign {cat('P', 36)} = p;",
        "  assign SIGNEDP = xsa ^ xsb;",
        "  initial begin",
        '    if ((REG_INPUTA_CLK != "NONE" && (REG_INPUTA_CLK != "CLK0" || REG_INPUTA_CE != "CE0"'
        ' || REG_INPUTA_RST != "RST0"))',
        '        || (REG_INPUTB_CLK != "NONE" && (REG_INPUTB_CLK != "CLK0"'
        ' || REG_INPUTB_CE != "CE0" || REG_INPUTB_RST != "RST0"))',
        '        || (REG_OUTPUT_CLK != "NONE" && (REG_OUTPUT_CLK != "CLK0"'
        ' || REG_OUTPUT_CE != "CE0" || REG_OUTPUT_RST != "RST0"))',
        '        || REG_INPUTC_CLK != "NONE" || REG_PIPELINE_CLK != "NONE"'
        ' || RESETMODE != "SYNC" || MULT_BYPASS != "DISABLED") begin',
        '      $display("MULT18X18D model: register setting not covered");',
        "      $finish;",
        "    end",
        "  end",
        "  always @(posedge CLK0) begin",
        "    if (RST0) begin ra <= 18'd0; rb <= 18'd0; sa <= 1'b0; sb <= 1'b0; rp <= 36'd0; end",
        "    else if (CE0) begin ra <= a; rb <= b; sa <= SIGNEDA; sb <= SIGNEDB; rp <= prod; end",
        "  end",
        "endmodule",
    ]
    return "\n".join(lines) + "\n"
