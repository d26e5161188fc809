"""Intersection backends behind one interface: ``float64``, ``model`` and ``rtl``.

The renderer talks to the accelerator only through :class:`Backend`:

1. :meth:`Backend.load` writes a scene: triangle records and the leaf spheres of a
   :class:`~raplas_hdl.host.spheres.SphereTree` (the Sphere Memory), and keeps the inner
   nodes' spheres for the host's hierarchy test;
2. :meth:`Backend.prepare` turns a :class:`~raplas_hdl.host.bundles.RayBundle` and the
   rays' enable bits into a :class:`BundleJob` (Plane Memory and Ray Memory);
3. :meth:`Backend.touched` is the plane test of inner nodes (the hierarchy cull), with the
   same arithmetic as the unit's plane-sphere testers;
4. :meth:`Backend.run_many` runs the unit once per ``(job, sphere_ids)`` and returns, per
   run, the issued pairs in the unit's stream order (spheres in run order, rows ascending,
   columns ascending, triangles in list order) with the hit bit, ``t, u, v`` (divided on
   the host), the event flags and the unit's counters.

Backends:

- ``float64``: the reference with no quantisation: float64 planes and spheres,
  ``|n.C + p| <= r`` with a float64-rounding allowance, and the division-free
  Moller-Trumbore decision of ``shared/spec/raplas.md`` evaluated in float64 on the
  original geometry (exact-inequality mode). No event flags.
- ``model``: the bit-accurate golden model of the intersection unit
  (:func:`raplas_hdl.model.intersection.run_bundle`) in any format, rounding and
  ray-triangle mode, with the radius inflation of :mod:`raplas_hdl.host.culling`.
- ``rtl``: the same memories run through the Verilog of the unit under cocotb (Icarus or
  Verilator); it raises :class:`BackendUnavailable` with what is missing when the
  simulator or the unit's driver is not there.

Nothing here imports Amaranth.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field

import numpy as np

from ..fp.format import FP24, FPFormat
from .bundles import RayBundle
from .exact import float64_intersect
from .spheres import SphereTree

__all__ = [
    "BACKENDS",
    "Backend",
    "BackendUnavailable",
    "BundleJob",
    "Float64Backend",
    "ModelBackend",
    "RtlBackend",
    "RunResult",
    "make_backend",
]

BACKENDS = ("float64", "model", "rtl")

#: Relative allowance of the float64 plane test for float64's own rounding (the float64
#: backend has no format to inflate for; this keeps it from rejecting a touching sphere
#: by an ulp of float64).
_F64_SLACK = 1e-9


class BackendUnavailable(RuntimeError):
    """A backend cannot run here; the message says what is missing and how to get it."""


@dataclass
class BundleJob:
    """A bundle as loaded into the unit: the float64 bundle and the backend's memories.

    Attributes
    ----------
    bundle : RayBundle
    enable : ndarray (rows*cols,) bool
        Enable bit of each ray; the host clears bits between runs (early-out).
    memory : object
        Backend data (``BundleMemory`` for the model and RTL backends).
    origin, directions : ndarray
        The rays as the backend sees them (decoded encoded rays for ``model``), float64.
    """

    bundle: RayBundle
    enable: np.ndarray
    memory: object = None
    origin: np.ndarray = None
    directions: np.ndarray = None
    guaranteed: bool = True


@dataclass
class RunResult:
    """The pairs one run issued, in stream order, with their outcome.

    ``t, u, v`` are ``t'/det, u'/det, v'/det`` in float64 (NaN where not a hit).
    """

    ray_id: np.ndarray
    tri_id: np.ndarray
    hit: np.ndarray
    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    flags: np.ndarray
    counters: dict = field(default_factory=dict)

    @classmethod
    def empty(cls, counters=None) -> RunResult:
        z = np.zeros(0, np.int64)
        f = np.zeros(0)
        return cls(z, z.copy(), np.zeros(0, bool), f, f.copy(), f.copy(),
                   np.zeros(0, np.uint8), dict(counters or {}))


COUNTERS = ("spheres", "plane_tests", "pairs_issued", "pairs_skipped", "hits", "overflow",
            "underflow", "invalid")


class Backend:
    """Common part of the backends (see the module docstring for the protocol)."""

    name = "?"
    fmt: FPFormat | None = None
    mode = "paper"

    def __init__(self):
        self.tree: SphereTree | None = None
        self.tris: np.ndarray | None = None

    # -- interface ------------------------------------------------------------------------
    def usable(self, tris: np.ndarray) -> tuple[np.ndarray, dict]:
        """Which triangles this backend can load: ``(bool mask (F,), skipped counts by
        reason)``. The default keeps finite triangles of non-zero area."""
        tris = np.asarray(tris, dtype=np.float64)
        finite = np.isfinite(tris).all(axis=(1, 2))
        safe = np.where(finite[:, None, None], tris, 0.0)
        area = np.linalg.norm(np.cross(safe[:, 1] - safe[:, 0], safe[:, 2] - safe[:, 0]),
                              axis=1)
        ok = finite & (area > 0)
        return ok, {"nonfinite": int((~finite).sum()), "degenerate": int((finite & ~ok).sum())}

    def load(self, tris: np.ndarray, tree: SphereTree, bound: float) -> dict:
        """Write a scene. ``tris`` (F, 3, 3) float64 scene coordinates; ``bound`` the
        normalisation bound. Returns a report dict (counts of skipped items etc.)."""
        self.tris = np.asarray(tris, dtype=np.float64)
        self.tree = tree
        self.bound = float(bound)
        return {}

    def prepare(self, bundle: RayBundle, enable=None) -> BundleJob:
        raise NotImplementedError

    def touched(self, job: BundleJob, nodes: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def run(self, job: BundleJob, sphere_ids) -> RunResult:
        raise NotImplementedError

    def run_many(self, runs) -> list[RunResult]:
        """Run ``[(job, sphere_ids), ...]`` in order (the RTL backend batches them)."""
        return [self.run(job, ids) for job, ids in runs]

    def describe(self) -> str:
        return self.name

    # -- helpers --------------------------------------------------------------------------
    def _enable(self, bundle, enable):
        if enable is None:
            return np.ones(bundle.n_rays, dtype=bool)
        en = np.asarray(enable, dtype=bool).reshape(-1)
        if en.shape != (bundle.n_rays,):
            raise ValueError(f"enable must have {bundle.n_rays} entries, not {en.size}")
        return en.copy()


class _PairConfig:
    """The part of a unit configuration that fixes the pair order (rows, cols)."""

    def __init__(self, rows, cols):
        self.rows, self.cols = rows, cols


class Float64Backend(Backend):
    """Reference backend: float64 culling and float64 Moller-Trumbore, no quantisation."""

    name = "float64"

    def load(self, tris, tree, bound):
        rep = super().load(tris, tree, bound)
        self._r = tree.radii * (1.0 + _F64_SLACK)
        return rep

    def prepare(self, bundle, enable=None):
        return BundleJob(bundle, self._enable(bundle, enable), None, bundle.origin,
                         bundle.directions)

    def _masks(self, job, centres, radii):
        b = job.bundle
        d = centres @ b.plane_n.T + b.plane_p[None, :]
        # allowance for float64 rounding of d, relative to the terms' magnitude
        slack = _F64_SLACK * (np.abs(centres) @ np.abs(b.plane_n.T) + np.abs(b.plane_p))
        keep = np.abs(d) <= radii[:, None] + slack
        return keep[:, :b.rows], keep[:, b.rows:]

    def touched(self, job, nodes):
        rm, cm = self._masks(job, self.tree.centres[nodes], self._r[nodes])
        return rm.any(axis=1) & cm.any(axis=1)

    def run(self, job, sphere_ids):
        from ..model.intersection import enumerate_pairs

        ids = np.asarray(sphere_ids, dtype=np.int64)
        b = job.bundle
        counters = dict.fromkeys(COUNTERS, 0)
        counters["spheres"] = int(ids.size)
        counters["plane_tests"] = int(ids.size) * b.n_planes
        if ids.size == 0:
            return RunResult.empty(counters)
        nodes = self.tree.leaf_node[ids]
        rm, cm = self._masks(job, self.tree.centres[nodes], self._r[nodes])
        lists = self.tree.leaf_tris[ids]
        ray, tri, skipped = enumerate_pairs(_PairConfig(b.rows, b.cols), rm, cm,
                                            (lists >= 0).sum(axis=1), lists, job.enable)
        counters["pairs_skipped"] = skipped
        counters["pairs_issued"] = int(ray.size)
        tv = self.tris[tri]
        r = float64_intersect(np.broadcast_to(b.origin, (ray.size, 3)), b.directions[ray],
                              tv[:, 0], tv[:, 1], tv[:, 2])
        hit = np.asarray(r["hit"], bool)
        t, u, v = (np.where(hit, r[k], np.nan) for k in ("t", "u", "v"))
        counters["hits"] = int(hit.sum())
        return RunResult(ray, tri, hit, t, u, v, np.zeros(ray.size, np.uint8), counters)


class ModelBackend(Backend):
    """The bit-accurate golden model of the intersection unit.

    Parameters
    ----------
    fmt : FPFormat
        Arithmetic format and rounding.
    mode : str
        Ray-triangle mode: ``"paper"`` or ``"conservative"``.
    testers : int or None
        Plane-sphere testers (only changes the RTL's timing, not the results).
    margin_scale : int
        Scale of the conservative margin.
    """

    name = "model"

    def __init__(self, fmt: FPFormat = FP24, mode: str = "conservative", testers=None,
                 margin_scale: int = 1):
        super().__init__()
        if not isinstance(fmt, FPFormat):
            raise ValueError(f"fmt must be an FPFormat, not {fmt!r}")  # noqa: TRY004
        if mode not in ("paper", "conservative"):
            raise ValueError(f"mode must be paper or conservative, not {mode!r}")
        self.fmt, self.mode, self.testers, self.margin_scale = fmt, mode, testers, margin_scale
        self._configs = {}

    def describe(self):
        return f"{self.name} {self.fmt} {self.mode}"

    def config(self, rows, cols):
        """The unit configuration for a ``rows`` x ``cols`` bundle (one per size)."""
        from ..model.memory_image import UnitConfig

        key = (rows, cols)
        if key not in self._configs:
            # Memory depths are rounded up to powers of two (at least 256 triangles and 64
            # spheres) so that scenes of similar size share one RTL build.
            def depth(n, least):
                return max(least, 1 << max(0, int(n) - 1).bit_length())
            self._configs[key] = UnitConfig(
                fmt=self.fmt, rows=rows, cols=cols, testers=self.testers,
                tris_per_sphere=self.tree.tris_per_sphere,
                max_triangles=depth(len(self.tris), 256),
                max_spheres=depth(self.tree.n_leaves, 64),
                mode=self.mode, margin_scale=self.margin_scale)
        return self._configs[key]

    def usable(self, tris):
        """Triangles that :func:`raplas_hdl.host.triangles.make_triangles` keeps (not
        non-finite, degenerate, flushed, or outside the format's domain)."""
        from .triangles import make_triangles

        tris = np.asarray(tris, dtype=np.float64)
        rec = make_triangles(tris, self.fmt, on_bad="skip", check_domain=True)
        self._records = (tris, rec)
        ok = np.zeros(len(tris), bool)
        ok[rec.ids] = True
        return ok, dict(rec.skipped)

    def load(self, tris, tree, bound):
        from ..model.memory_image import SceneMemory

        rep = super().load(tris, tree, bound)
        fmt = self.fmt
        cached = getattr(self, "_records", None)
        if cached is None or cached[0] is not tris and not np.array_equal(cached[0], tris):
            self.usable(tris)
        rec = self._records[1]
        # Triangle Memory is indexed by the scene's triangle ID; rows of skipped
        # triangles stay zero and no sphere lists them.
        v0, e1, e2, n = (np.zeros((len(self.tris), 3), np.uint32) for _ in range(4))
        v0[rec.ids], e1[rec.ids], e2[rec.ids], n[rec.ids] = (rec.v0_bits, rec.e1_bits,
                                                             rec.e2_bits, rec.n_bits)
        from .culling import CullingBudget, encode_spheres

        self.budget = CullingBudget(fmt, o_max=2.0 * self.bound)
        self._centres, _, self._radii, ok = encode_spheres(tree.centres, tree.radii,
                                                           self.budget)
        rep["spheres_out_of_domain"] = int(np.count_nonzero(~ok[tree.leaf_node]))
        leaf = tree.leaf_node
        lists = tree.leaf_tris
        counts = (lists >= 0).sum(axis=1)
        self.scene_memory = SceneMemory(v0, e1, e2, n, self._centres[leaf], self._radii[leaf],
                                        np.where(lists >= 0, lists, 0).astype(np.uint32),
                                        counts.astype(np.uint32))
        self._configs = {}
        return rep

    def prepare(self, bundle, enable=None):
        from ..fp import model as fpm
        from ..model.memory_image import BundleMemory

        fmt = self.fmt
        pn, pp = bundle.encode_planes(fmt)
        o, d = bundle.encode_rays(fmt)
        en = self._enable(bundle, enable)
        mem = BundleMemory(pn, pp, np.broadcast_to(o, d.shape), d, en)
        job = BundleJob(bundle, en, mem, fpm.decode(o, fmt), fpm.decode(d, fmt))
        if fmt.man_bits <= 25:
            from .culling import bundle_slack

            job.guaranteed = self.budget.admits(
                bundle_slack(pn, pp, o, d, bundle.rows, bundle.cols, fmt))
        return job

    def touched(self, job, nodes):
        from ..model.plane_sphere import tester_flags

        mem = job.memory
        keep = tester_flags(mem.plane_n, mem.plane_p, self._centres[nodes], self._radii[nodes],
                            self.fmt)
        r = job.bundle.rows
        return keep[:, :r].any(axis=1) & keep[:, r:].any(axis=1)

    def _convert(self, out, counters) -> RunResult:
        from ..fp import model as fpm

        if out.size == 1 and out["empty"][0]:
            return RunResult.empty(counters)
        hit = out["hit"].astype(bool)
        tuvd = fpm.decode(np.stack([out["t"], out["u"], out["v"], out["det"]]), self.fmt)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(hit, 1.0 / np.where(hit, tuvd[3], 1.0), np.nan)
            t, u, v = tuvd[0] * inv, tuvd[1] * inv, tuvd[2] * inv
        return RunResult(out["ray_id"].astype(np.int64), out["tri_id"].astype(np.int64), hit,
                         t, u, v, out["flags"].astype(np.uint8), counters)

    def run(self, job, sphere_ids):
        from ..model.intersection import run_bundle

        b = job.bundle
        job.memory.enable = job.enable
        out, counters = run_bundle(self.config(b.rows, b.cols), self.scene_memory, job.memory,
                                   np.asarray(sphere_ids, dtype=np.int64))
        return self._convert(out, counters)

    def run_many(self, runs):
        """Many runs with one ray-triangle model call.

        Per run exactly what :func:`raplas_hdl.model.intersection.run_bundle` does (the
        plane-sphere model's masks, :func:`~raplas_hdl.model.intersection.enumerate_pairs`
        for the stream order, the ray-triangle model per pair, the same counters), but the
        pairs of all runs go through :func:`~raplas_hdl.model.ray_triangle.intersect` at
        once: the per-pair arithmetic does not depend on the other pairs, so the results
        are the same bits (a test compares them with ``run_bundle``).
        """
        from ..model.intersection import (RESULT_DTYPE, empty_counters, enumerate_pairs,
                                          event_counters)
        from ..model.plane_sphere import sphere_masks
        from ..model.ray_triangle import intersect

        runs = list(runs)
        sm = self.scene_memory
        parts, counters = [], []
        for job, ids in runs:
            b = job.bundle
            cfg = self.config(b.rows, b.cols)
            ids = np.asarray(ids, dtype=np.int64)
            c = empty_counters()
            c["spheres"] = int(ids.size)
            c["plane_tests"] = int(ids.size) * cfg.n_planes
            if ids.size:
                rm, cm = sphere_masks(job.memory.plane_n, job.memory.plane_p, sm.centres[ids],
                                      sm.radii[ids], cfg.rows, cfg.cols, cfg.fmt)
                ray, tri, skipped = enumerate_pairs(cfg, np.asarray(rm, bool),
                                                    np.asarray(cm, bool), sm.tri_counts[ids],
                                                    sm.tri_lists[ids], job.enable)
            else:
                ray = tri = np.zeros(0, np.int64)
                skipped = 0
            c["pairs_skipped"] = skipped
            c["pairs_issued"] = int(ray.size)
            parts.append((job, ray, tri))
            counters.append(c)
        total = sum(r.size for _, r, _ in parts)
        if total:
            o = np.concatenate([np.broadcast_to(j.memory.ray_o[0], (r.size, 3))
                                for j, r, _ in parts])
            d = np.concatenate([j.memory.ray_d[r] for j, r, _ in parts])
            tri_all = np.concatenate([t for _, _, t in parts])
            res = intersect(o, d, sm.v0[tri_all], sm.e1[tri_all], sm.e2[tri_all],
                            sm.n[tri_all], self.fmt, mode=self.mode,
                            margin_scale=self.margin_scale)
        out, pos = [], 0
        for (job, ray, tri), c in zip(parts, counters):
            n = ray.size
            if n == 0:
                out.append(RunResult.empty(c))
                continue
            beats = np.zeros(n, RESULT_DTYPE)
            beats["ray_id"], beats["tri_id"] = ray, tri
            sl = slice(pos, pos + n)
            beats["hit"] = np.asarray(res["hit"][sl]).astype(np.uint8)
            for key in ("t", "u", "v", "det"):
                beats[key] = res[key][sl]
            fl = np.asarray(res["flags"][sl]).astype(np.uint8)
            beats["flags"] = fl
            beats["last"][-1] = 1
            c["hits"] = int(beats["hit"].sum())
            c.update(event_counters(res["event_counts"][sl]))
            out.append(self._convert(beats, c))
            pos += n
        return out


class RtlBackend(ModelBackend):
    """The Verilog of the intersection unit under cocotb (Icarus or Verilator).

    The host side (memories, hierarchy test, pair order) is the model backend's; the
    runs go through the unit's RTL driver, which loads the memories through the unit's
    write port and collects the result stream and counters. Runs are batched: one
    simulation per :meth:`run_many` call.

    Raises
    ------
    BackendUnavailable
        At construction, when the simulator, or the unit's driver, is missing.
    """

    name = "rtl"
    DRIVER = "raplas_hdl.sim.unit_driver"

    def __init__(self, fmt: FPFormat = FP24, mode: str = "conservative", testers=None,
                 margin_scale: int = 1, sim: str = "icarus"):
        super().__init__(fmt, mode, testers, margin_scale)
        try:
            from raplas_hdl.sim.runner import SimulatorNotFound, require_simulator
        except ImportError as exc:
            raise BackendUnavailable(
                f"the rtl backend needs the raplas_hdl.sim package: {exc}") from exc
        try:
            require_simulator(sim)
        except SimulatorNotFound as exc:
            raise BackendUnavailable(str(exc)) from exc
        except ValueError as exc:
            raise BackendUnavailable(f"unknown simulator {sim!r}: {exc}") from exc
        try:
            self._driver = importlib.import_module(self.DRIVER)
        except ImportError as exc:
            raise BackendUnavailable(
                f"the rtl backend needs the intersection unit's cocotb driver "
                f"({self.DRIVER.replace('.', '/')}.py with run_runs()), which is not "
                f"available: {exc}") from exc
        if not hasattr(self._driver, "run_runs"):
            raise BackendUnavailable(f"{self.DRIVER} has no run_runs(); the rtl backend "
                                     f"cannot drive the unit")
        self.sim = sim

    def describe(self):
        return f"{self.name} ({self.sim}) {self.fmt} {self.mode}"

    def run(self, job, sphere_ids):
        return self.run_many([(job, sphere_ids)])[0]

    def run_many(self, runs):
        runs = list(runs)
        if not runs:
            return []
        by_size = {}
        for k, (job, ids) in enumerate(runs):
            job.memory.enable = job.enable
            b = job.bundle
            by_size.setdefault((b.rows, b.cols), []).append(k)
        out = [None] * len(runs)
        for (rows, cols), idx in by_size.items():
            results = self._driver.run_runs(
                self.sim, self.config(rows, cols), self.scene_memory,
                [(runs[k][0].memory, np.asarray(runs[k][1], dtype=np.int64)) for k in idx])
            for k, (stream, counters) in zip(idx, results):
                out[k] = self._convert(stream, counters)
        return out


def make_backend(name: str, fmt: FPFormat = FP24, mode: str = "conservative",
                 sim: str = "icarus", testers=None) -> Backend:
    """A backend by name (``float64``, ``model``, ``rtl``).

    Raises
    ------
    ValueError
        For an unknown name.
    BackendUnavailable
        For ``rtl`` when the simulator or the unit's driver is missing.
    """
    if name == "float64":
        return Float64Backend()
    if name == "model":
        return ModelBackend(fmt, mode, testers)
    if name == "rtl":
        return RtlBackend(fmt, mode, testers, sim=sim)
    raise ValueError(f"unknown backend {name!r}: use one of {', '.join(BACKENDS)}")
