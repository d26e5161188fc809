"""Co-simulation of the board-level top: the host driver against ``board_top``'s Verilog.

:func:`run_board` emits the top's Verilog for a
:class:`~raplas_hdl.model.config.UnitConfig` (cached in memory and under
``build/sim/verilog/``), writes the scene and the runs into a stimulus file and runs
:mod:`raplas_hdl.sim.tb.board`, in which :class:`raplas_hdl.link.driver.BoardDriver`
drives the Wishbone port. It returns, per run, the result stream and the counters exactly as
:func:`raplas_hdl.model.intersection.run_bundle` returns them (counters with ``cycles``).
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

import raplas_hdl
from raplas_hdl.locks import file_lock
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.memory_image import BundleMemory, Run, SceneMemory, as_run
from raplas_hdl.model.records import output_record
from raplas_hdl.rtl.emit import emit_verilog
from raplas_hdl.sim.build.runner import BUILD_ROOT, ICARUS_ARGS, run_cocotb
from raplas_hdl.sim.drive.unit_driver import unit_verilog_digest

__all__ = ["board_verilog", "board_digest", "cached_verilog", "run_board", "encode_stimulus",
           "decode_stimulus", "TOPLEVEL"]

TOPLEVEL = "board_top"
_VERILOG_CACHE: dict = {}
#: The Verilator model of the whole unit runs a few thousand cycles here, while compiling
#: its C++ at -O2 is most of the test's time: -O0 builds in a fraction (the last -O wins).
VERILATOR_ARGS = ("-CFLAGS", "-O0")
_SCENE_FIELDS = ("v0", "e1", "e2", "n", "centres", "radii", "tri_lists", "tri_counts")
_BUNDLE_FIELDS = ("plane_n", "plane_p", "ray_o", "ray_d", "enable")


def board_digest(config: UnitConfig, multiplier: str = "generic",
                 adder: str = "generic") -> str:
    """The cache key of the board top's Verilog (the unit's and the register map's)."""
    h = hashlib.sha256(unit_verilog_digest(config, multiplier, adder).encode())
    h.update((Path(raplas_hdl.__file__).parent / "model" / "board_map.py").read_bytes())
    return h.hexdigest()[:16]


def cached_verilog(name: str, digest: str, emit) -> str:
    """``emit()``'s Verilog text, cached in memory and under ``build/sim/verilog/`` as
    ``<name>-<digest>.v``; a file lock makes concurrent callers (pytest-xdist workers) wait
    for one emission."""
    key = (name, digest)
    if key in _VERILOG_CACHE:
        return _VERILOG_CACHE[key]
    path = BUILD_ROOT / "verilog" / f"{name}-{digest}.v"
    with file_lock(path.with_suffix(".lock")):
        if path.exists():
            text = path.read_text()
        else:
            text = emit()
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_text(text)
            os.replace(tmp, path)
    _VERILOG_CACHE[key] = text
    return text


def board_verilog(config: UnitConfig, multiplier: str = "generic",
                  adder: str = "generic") -> str:
    """The board top's Verilog for ``config`` (module ``board_top``), cached
    (:func:`cached_verilog`, keyed by the parameters and the RTL sources); ``multiplier``
    and ``adder`` ``"virtex4"`` build the unit's DSP48 targets (Yosys's DSP48 simulation
    model appended)."""
    def emit():
        # lazy (here and below): the RTL loads Amaranth, needed only when the cached
        # Verilog is missing
        from raplas_hdl.rtl.board_top import BoardTop

        text, _ = emit_verilog(BoardTop(config, multiplier=multiplier, adder=adder),
                               TOPLEVEL, config.params())
        if "virtex4" in (multiplier, adder):
            from raplas_hdl.rtl.dsp48 import dsp48_sim_model

            text += "\n" + dsp48_sim_model()
        return text

    return cached_verilog(TOPLEVEL, board_digest(config, multiplier, adder), emit)


# -- stimulus ---------------------------------------------------------------------------------
def encode_stimulus(scene: SceneMemory, runs) -> dict:
    """Arrays (for ``np.savez``) holding the scene and every run's bundle, sphere IDs and
    ``keep_all`` bit (runs as :func:`~raplas_hdl.model.memory_image.as_run` takes them)."""
    stim = {f"scene_{f}": getattr(scene, f) for f in _SCENE_FIELDS}
    for k, (bundle, ids, keep_all) in enumerate(map(as_run, runs)):
        for f in _BUNDLE_FIELDS:
            stim[f"run{k}_{f}"] = getattr(bundle, f)
        stim[f"run{k}_all"] = np.array(int(ids is None))
        stim[f"run{k}_keep_all"] = np.array(int(keep_all))
        stim[f"run{k}_ids"] = np.zeros(0, np.int64) if ids is None else \
            np.asarray(ids, np.int64).reshape(-1)
    stim["n_runs"] = np.array(len(runs))
    return stim


def decode_stimulus(meta: dict, stim: dict):
    """``(config, scene, runs)`` from :func:`encode_stimulus` arrays and the run's meta
    (runs as :class:`~raplas_hdl.model.memory_image.Run`)."""
    config = UnitConfig.from_params(meta["params"])
    scene = SceneMemory(*[stim[f"scene_{f}"] for f in _SCENE_FIELDS])
    runs = []
    for k in range(int(stim["n_runs"])):
        bundle = BundleMemory(*[stim[f"run{k}_{f}"] for f in _BUNDLE_FIELDS])
        ids = None if int(stim[f"run{k}_all"]) else stim[f"run{k}_ids"]
        runs.append(Run(bundle, ids, bool(int(stim[f"run{k}_keep_all"]))))
    return config, scene, runs


def run_board(simulator: str, config: UnitConfig, scene: SceneMemory, runs, *,
              seed: int = 1, gap_density: float = 0.3, prefetch: bool = True,
              build_key: str | None = None, multiplier: str = "generic",
              adder: str = "generic"):
    """Run ``runs`` through the board top.

    Parameters
    ----------
    simulator : {"icarus", "verilator"}
    config : UnitConfig
    scene : SceneMemory
    runs : list of Run, (BundleMemory, sphere_ids or None) or (..., keep_all)
        See :class:`~raplas_hdl.model.memory_image.Run`.
    seed, gap_density : int, float
        The bus master's random idle cycles (see :mod:`raplas_hdl.sim.tb.board`).
    prefetch : bool
        The driver writes the next bundle while a run goes (the double buffer).
    multiplier, adder : {"generic", "virtex4"}
        The unit's DSP48 targets (:func:`board_verilog`).

    Returns
    -------
    results : list of (results, counters)
        As :func:`raplas_hdl.model.intersection.run_bundle` returns them (plus ``cycles``).
    stats : dict
        ``reads``, ``writes`` (the driver's bus accesses), ``sim_ns``, ``run_s``,
        ``build_s`` (the simulator's figures from :func:`raplas_hdl.sim.build.runner.run_cocotb`).

    Raises
    ------
    AssertionError
        When a cocotb test fails (a bus error, a protocol check, a timeout).
    """
    runs = list(runs)
    if not runs:
        raise ValueError("runs is empty")
    scene.check(config)
    text = board_verilog(config, multiplier, adder)
    with tempfile.TemporaryDirectory(prefix="raplas-board-") as tmp:
        stim_path, out_path, meta_path = (Path(tmp) / n for n in
                                          ("stim.npz", "out.npz", "meta.json"))
        np.savez(stim_path, **encode_stimulus(scene, runs))
        meta_path.write_text(json.dumps({"params": config.params(), "seed": seed,
                                         "gap_density": gap_density, "prefetch": prefetch}))
        env = {"BOARD_STIM": str(stim_path), "BOARD_OUT": str(out_path),
               "BOARD_META": str(meta_path)}
        res = run_cocotb(simulator, text, TOPLEVEL, "raplas_hdl.sim.tb.board",
                         build_key or f"board-{config.fmt.name}-{config.rows}x{config.cols}",
                         env=env, build_args=ICARUS_ARGS if simulator == "icarus"
                         else VERILATOR_ARGS,
                         public_all=False)
        out = dict(np.load(out_path, allow_pickle=False))
    beats = out["beats"].astype(output_record(config).dtype())
    names = [str(n) for n in out["counter_names"]]
    results = []
    for k in range(len(runs)):
        counters = {n: int(v) for n, v in zip(names, out["counters"][k])}
        results.append((beats[out["run_of_beat"] == k], counters))
    stats = {"reads": int(out["reads"]), "writes": int(out["writes"]),
             "sim_ns": float(out["sim_ns"]), "run_s": res["run_s"], "build_s": res["build_s"]}
    return results, stats
