"""Reading what nextpnr-ecp5 and Yosys say about a placed and routed unit.

:func:`parse_report` reads nextpnr's ``--report`` JSON (``fmax.<clock>.achieved``, the device
utilisation and the critical paths) into a :class:`RouteResult`: the achieved Fmax of every
clock and the critical path of the slowest one, as its start and end register, its logic,
routing and clock-to-out delays and the signals it crosses, in the unit's own names where
they survive synthesis. Yosys names a flip-flop cell after the net on its output
(``unpack.s1.diff_TRELLIS_FF_Q``), so a register's name is the cell's name up to the
``_TRELLIS_FF`` suffix; a net that synthesis made up is shortened to the name it grew from.

:func:`synth_counts` turns ``stat -json`` after ``synth_ecp5`` into the resource columns
(LUT4, carry, FF, MULT18X18D, ALU54B, EBR, distributed RAM). :func:`summarise_seeds` gives
the median, minimum and maximum Fmax over seeds. Nothing here runs a tool.
"""

from __future__ import annotations

import re
import statistics
from dataclasses import asdict, dataclass, field

__all__ = ["RouteResult", "CriticalPath", "parse_report", "synth_counts", "summarise_seeds",
           "signal_name", "UTILISATION_KEYS"]

#: nextpnr's utilisation entries the JSON keeps (used and available; ``DCCA``: the nets
#: on the global network).
UTILISATION_KEYS = ("TRELLIS_COMB", "TRELLIS_FF", "TRELLIS_RAMW", "MULT18X18D", "ALU54B",
                    "DP16KD", "TRELLIS_IO", "EHXPLLL", "DCCA")

#: Yosys's ``synth_ecp5`` cell types -> the resource columns of a report.
_SYNTH_COLUMNS = {"LUT4": "lut4", "CCU2C": "carry", "TRELLIS_FF": "ff",
                  "MULT18X18D": "mult18", "ALU54B": "alu54", "DP16KD": "ebr",
                  "TRELLIS_DPR16X4": "dram", "L6MUX21": "l6mux", "PFUMX": "pfumx"}

_CELL_SUFFIX = re.compile(r"_(TRELLIS_FF|TRELLIS_COMB|LUT4|CCU2C|PFUMX|L6MUX21|MULT18X18D|"
                          r"ALU54B|DP16KD|TRELLIS_DPR16X4|TRELLIS_RAMW)(_|\$|$).*")


def signal_name(name: str) -> str:
    """The unit's own signal a cell or net name comes from (``unpack.s1.diff[3]`` ->
    ``unpack.s1.diff``; ``lzc.x_TRELLIS_FF_Q_19_DI_LUT4_Z`` -> ``lzc.x``)."""
    name = _CELL_SUFFIX.sub("", name)
    name = re.sub(r"\$CCU2_.*$", "", name)
    return re.sub(r"\[\d+\]$", "", name)


@dataclass
class CriticalPath:
    """The critical path of one clock, as nextpnr reports it after routing."""

    start: str          # the register (or port) it starts from, in the unit's names
    end: str            # the register (or port) it ends at
    logic_ns: float     # cell delays (LUTs, carry chains, multipliers)
    routing_ns: float   # wire delays
    clk_to_q_ns: float
    setup_ns: float
    total_ns: float
    cells: int          # logic cells crossed
    signals: list = field(default_factory=list)   # the unit's signals along it, in order

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class RouteResult:
    """One nextpnr run: Fmax per clock, utilisation, the critical path."""

    fmax: dict                      # clock -> achieved MHz
    constraint: dict                # clock -> target MHz
    utilisation: dict               # UTILISATION_KEYS -> {"used", "available"}
    critical_path: CriticalPath | None

    def to_dict(self) -> dict:
        d = asdict(self)
        d["critical_path"] = self.critical_path.to_dict() if self.critical_path else None
        return d


def _path(entry: dict) -> CriticalPath:
    segs = entry.get("path", [])
    sums = {"logic": 0.0, "routing": 0.0, "clk-to-q": 0.0, "setup": 0.0}
    signals: list[str] = []
    cells = 0
    for seg in segs:
        kind = seg.get("type", "")
        sums[kind] = sums.get(kind, 0.0) + float(seg.get("delay", 0.0))
        if kind == "logic":
            cells += 1
        net = seg.get("net")
        if kind == "routing" and net and not net.startswith("$nextpnr"):
            sig = signal_name(net)
            if not signals or signals[-1] != sig:
                signals.append(sig)
    start = signal_name(segs[0]["from"]["cell"]) if segs else entry.get("from", "")
    end = signal_name(segs[-1]["to"]["cell"]) if segs else entry.get("to", "")
    return CriticalPath(start=start, end=end, logic_ns=round(sums["logic"], 3),
                        routing_ns=round(sums["routing"], 3),
                        clk_to_q_ns=round(sums["clk-to-q"], 3),
                        setup_ns=round(sums["setup"], 3),
                        total_ns=round(sum(sums.values()), 3), cells=cells, signals=signals)


def parse_report(report: dict) -> RouteResult:
    """A :class:`RouteResult` from nextpnr's ``--report`` JSON (a ``dict``).

    The critical path kept is the longest one of the slowest clock (clock-to-clock paths
    between different clocks are skipped). Raises ``ValueError`` when the report has no
    ``fmax`` entry (nextpnr found no clocked path)."""
    fmax_entries = report.get("fmax") or {}
    if not fmax_entries:
        raise ValueError("the nextpnr report has no clock (no register-to-register path)")
    fmax = {clk: round(float(v["achieved"]), 3) for clk, v in fmax_entries.items()}
    constraint = {clk: float(v.get("constraint", 0.0)) for clk, v in fmax_entries.items()}
    util = {k: {"used": v["used"], "available": v["available"]}
            for k, v in (report.get("utilization") or {}).items() if k in UTILISATION_KEYS}
    paths = [p for p in report.get("critical_paths", []) if p.get("path")]
    crit = max((_path(p) for p in paths), key=lambda p: p.total_ns, default=None)
    return RouteResult(fmax=fmax, constraint=constraint, utilisation=util, critical_path=crit)


def synth_counts(stat: dict) -> dict:
    """The resource columns from Yosys ``stat -json`` of a ``synth_ecp5`` netlist."""
    mods = stat.get("modules", {})
    design = stat.get("design", {})
    cells = design.get("num_cells_by_type") or next(iter(mods.values()), {}).get(
        "num_cells_by_type", {})
    out = {col: 0 for col in _SYNTH_COLUMNS.values()}
    for cell, n in cells.items():
        col = _SYNTH_COLUMNS.get(cell.lstrip("\\"))
        if col:
            out[col] += int(n)
    return out


def summarise_seeds(fmax_per_seed: dict) -> dict:
    """``{clock: {"median", "min", "max", "seeds"}}`` from ``{seed: {clock: MHz}}``."""
    clocks = sorted({c for per in fmax_per_seed.values() for c in per})
    out = {}
    for clk in clocks:
        vals = [per[clk] for per in fmax_per_seed.values() if clk in per]
        out[clk] = {"median": round(statistics.median(vals), 3), "min": min(vals),
                    "max": max(vals), "seeds": len(vals)}
    return out
