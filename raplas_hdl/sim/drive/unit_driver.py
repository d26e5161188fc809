"""Driver of the intersection unit's Verilog under cocotb, and small test scenes.

:func:`run_runs` is the per-cycle cocotb path (the host's ``rtl`` backend takes it only for
waveforms; its renders use the live sessions of :mod:`raplas_hdl.sim.drive.unit_harness`, which
reuse :func:`unit_verilog` and :func:`encode_runs`): it emits the unit's Verilog for a
:class:`~raplas_hdl.model.config.UnitConfig` (one simulator build per configuration,
reused), writes the scene and the runs into a stimulus file, runs
:mod:`raplas_hdl.sim.tb.intersection` and returns, per run, the result stream (the structured array
of :data:`raplas_hdl.model.intersection.RESULT_DTYPE`) and the counters, exactly as
:func:`raplas_hdl.model.intersection.run_bundle` returns them.

:func:`random_scene` and :func:`random_bundle` make the small seeded scenes of the tests.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from raplas_hdl.fp import model as fpm
from raplas_hdl.model.bundles import RayBundle
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.memory_image import (BundleMemory, SceneMemory, as_run, bundle_writes,
                                           run_list_writes, scene_writes)
from raplas_hdl.model.records import COUNTERS, output_record
from raplas_hdl.rtl.emit import emit_verilog
from raplas_hdl.sim.build.runner import BUILD_ROOT, ICARUS_ARGS, run_cocotb, verilator_pch_fix
from raplas_hdl.sim.build.sources import rtl_sources_digest

__all__ = ["random_scene", "random_bundle", "unit_verilog", "run_runs", "encode_runs",
           "decode_results"]

_VERILOG_CACHE: dict = {}


# -- scenes --------------------------------------------------------------------------------
def random_scene(config: UnitConfig, n_tris: int, seed: int = 0, extent: float = 4.0,
                 size: float = 0.6, empty_spheres: int = 0) -> SceneMemory:
    """Random triangles grouped into spheres of 1 .. ``tris_per_sphere`` triangles.

    Triangles are sorted along x and cut into consecutive groups; each sphere encloses
    its triangles (radius rounded up, plus 1 %). ``empty_spheres`` spheres without
    triangles are mixed in.
    """
    rng = np.random.default_rng(seed)
    fmt = config.fmt
    c = rng.uniform(-extent, extent, (n_tris, 3))
    c = c[np.argsort(c[:, 0])]
    v = c[:, None, :] + rng.normal(0.0, size / 2, (n_tris, 3, 3))
    v0e = fpm.encode(v[:, 0], fmt)
    v0 = fpm.decode(v0e, fmt)
    e1 = fpm.encode(v[:, 1] - v0, fmt)
    e2 = fpm.encode(v[:, 2] - v0, fmt)
    n = fpm.encode(np.cross(fpm.decode(e1, fmt), fpm.decode(e2, fmt)), fmt)
    tps = config.tris_per_sphere
    groups, start = [], 0
    while start < n_tris:
        k = int(rng.integers(1, tps + 1))
        groups.append(np.arange(start, min(n_tris, start + k)))
        start += k
    for _ in range(empty_spheres):
        groups.insert(int(rng.integers(0, len(groups) + 1)), np.zeros(0, np.int64))
    s = len(groups)
    centres = np.zeros((s, 3))
    radii = np.zeros(s)
    lists = np.zeros((s, tps), np.uint32)
    counts = np.zeros(s, np.uint32)
    for k, g in enumerate(groups):
        if g.size == 0:
            centres[k] = rng.uniform(-extent, extent, 3)
            radii[k] = size
            continue
        pts = v[g].reshape(-1, 3)
        centres[k] = pts.mean(axis=0)
        radii[k] = np.linalg.norm(pts - centres[k], axis=1).max() * 1.01
        order = rng.permutation(g.size)       # list order need not be ID order
        lists[k, :g.size] = g[order]
        counts[k] = g.size
    return SceneMemory(v0e, e1, e2, n, fpm.encode(centres, fmt),
                       fpm.encode(radii, fmt, direction="up"), lists, counts)


def random_bundle(config: UnitConfig, seed: int = 0, disable: float = 0.0,
                  origin=None, spread: float = 0.5, target=None) -> BundleMemory:
    """A bundle from near ``(0, 0, -10)`` looking at ``target`` (default: a random point
    near the scene's centre); ``disable`` of the rays are switched off."""
    rng = np.random.default_rng(seed)
    fmt = config.fmt
    o = np.array([0.0, 0.0, -10.0]) + rng.normal(0, 1.0, 3) if origin is None else origin
    target = rng.uniform(-2, 2, 3) if target is None else np.asarray(target, float)
    fwd = target - o
    fwd /= np.linalg.norm(fwd)
    a = np.cross(fwd, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(fwd, a)
    bundle = RayBundle(o, o + fwd, a * spread, b * spread, config.rows, config.cols)
    pn, pp = bundle.encode_planes(fmt)
    ro, rd = bundle.encode_rays(fmt)
    enable = rng.random(config.n_rays) >= disable
    return BundleMemory(pn, pp, np.broadcast_to(ro, rd.shape), rd, enable)


# -- Verilog -----------------------------------------------------------------------------------
def unit_verilog_digest(config: UnitConfig, multiplier: str = "generic",
                        adder: str = "generic") -> str:
    """The cache key of the unit's Verilog: its parameters, the targets, Amaranth's version
    and every source it is emitted from
    (:func:`~raplas_hdl.sim.build.sources.rtl_sources_digest`)."""
    # lazy: amaranth only for its version; importers such as the board testbench need none
    import amaranth

    h = hashlib.sha256(json.dumps(config.params(), sort_keys=True).encode())
    if multiplier != "generic":
        h.update(multiplier.encode())
    if adder != "generic":
        h.update(b"adder-" + adder.encode())
    h.update(amaranth.__version__.encode())
    h.update(rtl_sources_digest().encode())
    return h.hexdigest()[:16]


def unit_verilog(config: UnitConfig, multiplier: str = "generic",
                 adder: str = "generic") -> str:
    """The unit's Verilog for ``config`` (module ``intersection_unit``); ``multiplier``
    ``"virtex4"`` builds the DSP48 target (Yosys's DSP48 simulation model appended), and
    ``adder="virtex4"`` the two-DSP48 FP adders.

    Emitting the whole unit takes a while (about 15 s of CPU at FP24), so the text is
    cached in memory and on disk under ``build/sim/verilog/``, keyed by the parameters and
    the contents of the RTL sources.
    """
    if (config, multiplier, adder) in _VERILOG_CACHE:
        return _VERILOG_CACHE[config, multiplier, adder]
    digest = unit_verilog_digest(config, multiplier, adder)
    path = BUILD_ROOT / "verilog" / f"intersection_unit-{digest}.v"
    if path.exists():
        text = path.read_text()
    else:
        # lazy (here and below): the RTL loads Amaranth, only when the cached Verilog is missing
        from raplas_hdl.rtl.intersection import IntersectionUnit
        from raplas_hdl.rtl.ram import ram_verilog

        # behavioural RAMs without initial values: converts in seconds at any depth
        unit = IntersectionUnit(config, ram="verilog", multiplier=multiplier, adder=adder)
        text, _ = emit_verilog(unit, "intersection_unit", {**config.params(), "ram": "verilog"})
        text += ram_verilog()
        if "virtex4" in (multiplier, adder):
            from raplas_hdl.rtl.dsp48 import dsp48_sim_model

            text += "\n" + dsp48_sim_model()
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(text)
        os.replace(tmp, path)
    _VERILOG_CACHE[config, multiplier, adder] = text
    return text


# -- stimulus and results -----------------------------------------------------------------------
def _contiguous(ids):
    return ids.size == 0 or np.array_equal(ids, np.arange(ids[0], ids[0] + ids.size))


def _same_geometry(a: BundleMemory, b: BundleMemory) -> bool:
    return a is b or all(np.array_equal(getattr(a, f), getattr(b, f))
                         for f in ("plane_n", "plane_p", "ray_o", "ray_d", "tmin", "tmax",
                                   "exclude", "any_hit"))


def encode_runs(config: UnitConfig, scene: SceneMemory, runs, *, overlap: bool = False,
                with_scene: bool = True):
    """Stimulus of a simulation as a dict of arrays (saved with ``np.savez``).

    ``runs`` is a list of :class:`~raplas_hdl.model.memory_image.Run`,
    ``(bundle, sphere_ids)`` or ``(bundle, sphere_ids, keep_all)``; a run whose bundle has
    the previous run's planes and rays reuses its bank and rewrites only the enable bits
    (the host's early-out batches), otherwise the bundle goes into the other bank.
    Contiguous ``sphere_ids`` start a range run, others a run-list run. Each run's command
    fields are ``run_first``, ``run_count``, ``run_bank``, ``run_indirect`` and
    ``run_keep_all``. ``with_scene=False`` leaves the scene's writes out (a live session
    loaded it already).
    """
    if with_scene:
        wa, wd = scene_writes(config, scene)
    else:
        wa = wd = np.zeros(0, np.uint32)
    stim = {"scene_addr": wa, "scene_data": wd}
    banks, firsts, counts, inds, keeps, offsets = [], [], [], [], [], [0]
    addrs, datas = [], []
    bank, prev = 1, None
    for bundle, ids, keep_all in map(as_run, runs):
        ids = (np.arange(scene.n_spheres) if ids is None
               else np.asarray(ids, dtype=np.int64).reshape(-1))
        if prev is not None and _same_geometry(bundle, prev):
            a, d = bundle_writes(config, bundle, bank, enable_only=True)
        else:
            bank ^= 1
            a, d = bundle_writes(config, bundle, bank)
        prev = bundle
        if _contiguous(ids):
            first, ind = (int(ids[0]) if ids.size else 0), 0
        else:
            la, ld = run_list_writes(config, ids, bank)
            a, d = np.concatenate([a, la]), np.concatenate([d, ld])
            first, ind = 0, 1
        banks.append(bank)
        firsts.append(first)
        counts.append(ids.size)
        inds.append(ind)
        keeps.append(int(keep_all))
        addrs.append(a)
        datas.append(d)
        offsets.append(offsets[-1] + a.size)
    stim.update(run_bank=np.array(banks, np.uint32), run_first=np.array(firsts, np.uint32),
                run_count=np.array(counts, np.uint32), run_indirect=np.array(inds, np.uint32),
                run_keep_all=np.array(keeps, np.uint32),
                run_addr=np.concatenate(addrs).astype(np.uint32) if addrs else
                np.zeros(0, np.uint32),
                run_data=np.concatenate(datas).astype(np.uint32) if datas else
                np.zeros(0, np.uint32),
                run_offsets=np.array(offsets, np.int64),
                overlap=np.array(int(overlap)))
    return stim


def decode_results(config: UnitConfig, beats) -> np.ndarray:
    """Raw ``o`` payload integers -> structured array of
    :data:`~raplas_hdl.model.intersection.RESULT_DTYPE` (the record
    :data:`~raplas_hdl.model.records.RESULT` of ``config``, ``ANSWER`` with ``config.reduce``)."""
    return output_record(config).bind(config).unpack(beats)


def run_runs(simulator: str, config: UnitConfig, scene: SceneMemory, runs, *,
             seed: int = 1, ready_density: float = 1.0, overlap: bool = False,
             build_key: str | None = None, multiplier: str = "generic",
             adder: str = "generic"):
    """Run ``runs`` through the unit's Verilog.

    Parameters
    ----------
    simulator : {"icarus", "verilator"}
    config : UnitConfig
    scene : SceneMemory
    runs : list of Run, (BundleMemory, sphere_ids or None) or (..., keep_all)
        See :class:`~raplas_hdl.model.memory_image.Run` (``keep_all``: the run culls
        nothing).
    seed : int
        Seed of the testbench's back-pressure.
    ready_density : float
        Probability that the testbench is ready for a result in a cycle.
    overlap : bool
        Start each run without waiting for the previous run's last beat (counters are then
        only meaningful summed over all runs: each run's counters are ``None`` but the
        last's, which holds the totals).
    multiplier : ``"generic"`` or ``"virtex4"``
        The unit's multiplier target (see :func:`unit_verilog`).
    adder : ``"generic"`` or ``"virtex4"``
        The unit's FP adder target (see :func:`unit_verilog`).

    Returns
    -------
    list of (results, counters)
        As :func:`raplas_hdl.model.intersection.run_bundle` returns them; counters also hold
        ``cycles``, and the testbench's ``max_fifo_level`` under ``"_max_fifo_level"``.

    Raises
    ------
    AssertionError
        When the testbench fails (FIFO overflow flag, a protocol error, a timeout).
    """
    runs = [as_run(r) for r in runs]
    if not runs:
        return []
    scene.check(config)
    text = unit_verilog(config, multiplier, adder)
    with tempfile.TemporaryDirectory(prefix="raplas-unit-") as tmp:
        stim_path = Path(tmp) / "stim.npz"
        out_path = Path(tmp) / "out.npz"
        stim = encode_runs(config, scene, runs, overlap=overlap)
        np.savez(stim_path, **stim)
        pairs_bound = sum(int(np.asarray(scene.tri_counts)[
            np.arange(scene.n_spheres) if ids is None else np.asarray(ids, np.int64)].sum())
            for _, ids, _ in runs) * config.n_rays
        max_cycles = int(4 * (stim["scene_addr"].size + stim["run_addr"].size)
                         + (pairs_bound + 64 * len(runs) + scene.n_spheres * len(runs)
                            * (1 + config.n_planes // config.n_testers)) * 4 / ready_density
                         + 10_000)
        meta = {"max_cycles": max_cycles, "params": config.params(), "seed": seed,
                "ready_density": ready_density}
        (Path(tmp) / "meta.json").write_text(json.dumps(meta))
        env = {"UNIT_STIM": str(stim_path), "UNIT_OUT": str(out_path),
               "UNIT_META": str(Path(tmp) / "meta.json")}
        with verilator_pch_fix(simulator):
            run_cocotb(simulator, text, "intersection_unit", "raplas_hdl.sim.tb.intersection",
                       build_key or f"unit-{config.fmt.name}-{config.rows}x{config.cols}",
                       env=env, build_args=ICARUS_ARGS if simulator == "icarus" else (),
                       # the testbench touches only the top's ports; with every signal
                       # public (cocotb's default) Verilator's C++ of this unit does not
                       # compile in useful time on 2 cores
                       public_all=False)
        res = np.load(out_path, allow_pickle=False)
        beats = [int(x, 16) for x in res["beats"]]
        run_of_beat = res["run_of_beat"]
        ctr = res["counters"]
        max_level = int(res["max_fifo_level"])
    results = decode_results(config, beats)
    out = []
    for k in range(len(runs)):
        stream = results[run_of_beat == k]
        if overlap and k != len(runs) - 1:
            counters = None
        else:
            counters = {name: int(ctr[k, i]) for i, name in enumerate(COUNTERS.names)}
            counters["_max_fifo_level"] = max_level
        out.append((stream, counters))
    return out
