"""``intersection-unit``: a live session of the unit's harness, a run per case, every
result beat and counter compared."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..build.runner import waves_requested
from .base import UnitCosim, beat_lines, report_runs
from .vectors import LineKind


class IntersectionCosim(UnitCosim):
    """``intersection-unit``: a case is one run (a bundle against a list of spheres) on a
    random scene; compared: every field of every result beat, and every counter.

    With ``reduce`` (the on-chip reduction) every bundle carries a random window (``tmin``,
    per-ray ``tmax``, some infinite, an excluded triangle) and nearest-hit and any-hit runs
    alternate; compared: every field of every ANSWER beat, and the counters, except that in
    an any-hit run the unit's early-out may issue fewer pairs than the model (which has none):
    ``pairs_issued``, ``hits`` and the event counters there are checked to be at most the
    model's (``docs/intersection-unit.md``). With ``mode="certified"`` the beats carry the
    pair's ``outcome`` (reduced: the runs' uncertain pairs, then their answers), compared
    like every other field."""

    name = "intersection-unit"
    outputs = ("stream", "counters")
    case_name = "runs"

    def __init__(self, fmt, options, driver="batch"):
        super().__init__(fmt, options, driver)
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.model.config import UnitConfig

        kw = {k: self.options[k] for k in ("rows", "cols", "testers", "tris_per_sphere",
                                           "mode", "lanes", "reduce")
              if self.options.get(k) is not None}
        # the memories of tests/sim/test_unit_harness.py's unit (one build serves both)
        self.config = UnitConfig(fmt=fmt, max_triangles=256, max_spheres=128, fifo_depth=8,
                                 **kw)
        self.header_params = {"rows": self.config.rows, "cols": self.config.cols,
                              "tris_per_sphere": self.config.tris_per_sphere,
                              "mode": self.config.mode,
                              **({"lanes": self.config.lanes} if self.config.lanes != 1
                                 else {}),
                              **({"reduce": True} if self.config.reduce else {})}

    def check(self):
        pass        # the constructor built the UnitConfig (ValueError names the parameter)

    def random(self, n, seed):
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.fp import model as fpm

        from ..drive.unit_driver import random_bundle, random_scene

        cfg = self.config
        rng = np.random.default_rng([seed, 41])
        # at most 60 triangles per list entry: the spheres fit Sphere Memory
        scene = random_scene(cfg, min(160, 60 * cfg.tris_per_sphere), seed=seed, size=1.2,
                             extent=4.0, empty_spheres=2)
        runs = []
        for k in range(n):
            s = int(rng.integers(0, scene.n_spheres))
            target = fpm.decode(scene.centres[s], cfg.fmt)
            b = random_bundle(cfg, seed=seed * 7919 + k, disable=float(rng.uniform(0, 0.5)),
                              spread=0.12, target=target)
            kind = k % 4
            if kind == 0:
                ids = None                                   # every sphere
            elif kind == 1:
                ids = rng.integers(0, scene.n_spheres, int(rng.integers(1, 12)))
            elif kind == 2:
                a = int(rng.integers(0, scene.n_spheres))
                ids = np.arange(a, min(scene.n_spheres, a + int(rng.integers(1, 20))))
            else:
                ids = rng.integers(0, scene.n_spheres, int(rng.integers(0, 4)))
            if cfg.reduce:
                b = self._window(b, scene, rng, k)
            runs.append((b, None if ids is None else np.asarray(ids, np.int64),
                         bool(kind == 3 and k % 8 == 3)))
        return {"scene": scene, "runs": runs}

    def _window(self, bundle, scene, rng, k):
        """``bundle`` with a random window: ``tmin`` 0, 0.05 or 0.1; ``tmax`` 6 to 20 (the
        scene lies 6 to 14 away), 40 % of the rays +infinity; two runs in three exclude a
        triangle the scene lists; odd runs any-hit."""
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.fp import model as fpm
        from raplas_hdl.model.reduction import inf_pattern

        fmt, R = self.config.fmt, self.config.n_rays
        tmax = fpm.encode(rng.uniform(6.0, 20.0, R), fmt)
        tmax[rng.random(R) < 0.4] = inf_pattern(fmt)
        used = scene.tri_lists[scene.tri_counts > 0, 0]
        return replace(bundle, tmin=int(fpm.encode(np.array([0.05 * (k % 3)]), fmt)[0]),
                       tmax=tmax, exclude=int(rng.choice(used)) if k % 3 else -1,
                       any_hit=bool(k % 2))

    def n_cases(self, cases):
        return len(cases["runs"])

    def expected(self, cases):
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.model.intersection import run_runs

        return {"runs": run_runs(self.config, cases["scene"], cases["runs"]),
                "any_hit": [bool(b.any_hit) for b, _, _ in cases["runs"]]}

    def _kinds(self):
        """T, S (the scene), B, PL, RAY (a bundle), RUN, SPH (a run and its sphere list),
        BEAT, CTR (its expected result stream and counters)."""
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.model.records import COUNTERS, result_record

        cfg, w = self.config, self.config.fmt.width
        xyz = lambda v: tuple((f"{v}{c}", w) for c in "xyz")
        res = result_record(cfg).bind(cfg)
        return {
            "T": LineKind("T", xyz("v0") + xyz("e1") + xyz("e2") + xyz("n")),
            "S": LineKind("S", xyz("c") + (("r", w), ("count", cfg.count_bits))
                          + tuple((f"tri{k}", cfg.tri_id_bits)
                                  for k in range(cfg.tris_per_sphere))),
            "B": LineKind("B", ()),
            "PL": LineKind("PL", xyz("n") + (("p", w),)),
            "RAY": LineKind("RAY", xyz("o") + xyz("d") + (("enable", 1),)),
            "RUN": LineKind("RUN", (("bundle", 32), ("keep_all", 1), ("all", 1))),
            "SPH": LineKind("SPH", (("id", cfg.sphere_id_bits),)),
            "BEAT": LineKind("BEAT", tuple((s.name, s.width) for s in res.fields)),
            "CTR": LineKind("CTR", tuple((n, 32) for n in COUNTERS.names if n != "cycles")),
        }

    @property
    def kinds(self):
        return tuple(self._kinds().values())

    def from_items(self, path, items):
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.model.memory_image import BundleMemory, SceneMemory
        from raplas_hdl.model.records import result_record

        cfg, k = self.config, self._kinds()
        by = {t: [] for t in k}
        bundles, runs, exp = [], [], []
        cur_b = cur_run = None

        def close_bundle(lineno):
            if cur_b is None:
                return
            pl, ry = cur_b
            if len(pl) != cfg.n_planes or len(ry) != cfg.n_rays:
                raise ValueError(f"{path}:{lineno}: bundle {len(bundles)} has {len(pl)} PL and "
                                 f"{len(ry)} RAY lines, not {cfg.n_planes} and {cfg.n_rays}")
            pl, ry = np.array(pl, np.uint32), np.array(ry, np.uint32)
            bundles.append(BundleMemory(pl[:, :3], pl[:, 3], ry[:, :3], ry[:, 3:6],
                                        ry[:, 6].astype(bool)))
            return

        def close_run(lineno):
            if cur_run is None:
                return
            b, keep, ids, beats, ctr = cur_run
            if ctr is None:
                raise ValueError(f"{path}:{lineno}: run {len(runs)} has no CTR line")
            stream = np.zeros(len(beats), result_record(cfg).dtype())
            for j, (name, _) in enumerate(k["BEAT"].fields):
                stream[name] = [v[j] for v in beats]
            runs.append((bundles[b], ids, keep))
            exp.append((stream, ctr))

        for lineno, tag, v in items:
            if tag in ("T", "S"):
                if bundles or cur_b is not None:
                    raise ValueError(f"{path}:{lineno}: {tag} lines (the scene) come before "
                                     "the bundles")
                by[tag].append(v)
            elif tag == "B":
                cur_b = close_bundle(lineno)
                cur_b = ([], [])
            elif tag in ("PL", "RAY"):
                if cur_b is None:
                    raise ValueError(f"{path}:{lineno}: a {tag} line outside a bundle (B line)")
                cur_b[0 if tag == "PL" else 1].append(v)
            elif tag == "RUN":
                cur_b = close_bundle(lineno)
                close_run(lineno)
                if v[0] >= len(bundles):
                    raise ValueError(f"{path}:{lineno}: RUN names bundle {v[0]}; the file "
                                     f"has {len(bundles)} so far")
                cur_run = [v[0], bool(v[1]), None if v[2] else [], [], None]
            elif cur_run is None or cur_run[4] is not None and tag != "CTR":
                raise ValueError(f"{path}:{lineno}: a {tag} line outside a run (RUN ... CTR)")
            elif tag == "SPH":
                if cur_run[2] is None or cur_run[3]:
                    raise ValueError(f"{path}:{lineno}: SPH lines follow a RUN with ALL 0, "
                                     "before its BEAT lines")
                cur_run[2].append(v[0])
            elif tag == "BEAT":
                cur_run[3].append(v)
            else:       # CTR
                if cur_run[4] is not None:
                    raise ValueError(f"{path}:{lineno}: a second CTR line for one run")
                cur_run[4] = dict(zip([n for n, _ in k["CTR"].fields], v))
        close_run(items[-1][0])
        if not by["T"] or not by["S"]:
            raise ValueError(f"{path}: no scene (T and S lines)")
        if not runs:
            raise ValueError(f"{path}: no cases (RUN lines)")
        t = np.array(by["T"], np.uint32)
        sp = np.array(by["S"], np.uint32)
        scene = SceneMemory(t[:, 0:3], t[:, 3:6], t[:, 6:9], t[:, 9:12], sp[:, 0:3], sp[:, 3],
                            sp[:, 5:], sp[:, 4])
        scene.check(cfg)
        runs = [(b, None if ids is None else np.array(ids, np.int64), keep)
                for b, ids, keep in runs]
        for b, ids, _ in runs:
            b.check(cfg)
            if ids is not None and ids.size and ids.max() >= scene.n_spheres:
                raise ValueError(f"{path}: a run names sphere {int(ids.max())}; the scene "
                                 f"has {scene.n_spheres}")
        return {"scene": scene, "runs": runs}, {"runs": exp}

    def blocks(self, cases, expected):
        k, sc = self._kinds(), cases["scene"]
        cols = lambda kind, arr: {n: arr[:, j] for j, (n, _) in enumerate(kind.fields)}
        out = [(k["T"], cols(k["T"], np.concatenate([sc.v0, sc.e1, sc.e2, sc.n], 1))),
               (k["S"], cols(k["S"], np.concatenate(
                   [sc.centres, sc.radii[:, None], sc.tri_counts[:, None],
                    _pad(sc.tri_lists, self.config.tris_per_sphere)], 1)))]
        index = {}
        for b, _, _ in cases["runs"]:
            if id(b) in index:
                continue
            index[id(b)] = len(index)
            out.append((k["B"], {}))
            out.append((k["PL"], cols(k["PL"], np.concatenate([b.plane_n, b.plane_p[:, None]],
                                                             1))))
            out.append((k["RAY"], cols(k["RAY"], np.concatenate(
                [b.ray_o, b.ray_d, b.enable[:, None].astype(np.uint32)], 1))))
        for (b, ids, keep), (stream, ctr) in zip(cases["runs"], expected["runs"]):
            out.append((k["RUN"], {"bundle": [index[id(b)]], "keep_all": [int(keep)],
                                   "all": [int(ids is None)]}))
            if ids is not None and len(ids):
                out.append((k["SPH"], {"id": np.asarray(ids)}))
            if len(stream):
                out.append((k["BEAT"], {n: stream[n] for n, _ in k["BEAT"].fields}))
            out.append((k["CTR"], {n: [ctr[n]] for n, _ in k["CTR"].fields}))
        return out

    def simulate(self, cases, simulator, *, valid_density, stall_density, seed,
                 timeout_s=None):
        t0 = time.monotonic()
        if waves_requested():       # the per-cycle cocotb driver records waveforms
            # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
            from ..drive.unit_driver import run_runs

            got = run_runs(simulator, self.config, cases["scene"], cases["runs"], seed=seed,
                           ready_density=1.0 - stall_density, multiplier=self.target,
                           adder=self.adder)
            cycles = sum(int(c.get("cycles", 0)) for _, c in got)
            build_s = 0.0
            run_s = time.monotonic() - t0
        else:
            # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
            from ..drive.unit_harness import UnitSession

            with UnitSession(simulator, self.config, cases["scene"], seed=seed,
                             ready_density=1.0 - stall_density,
                             timeout_s=timeout_s or 24 * 3600.0,
                             multiplier=self.target, adder=self.adder) as s:
                build_s = time.monotonic() - t0 - s.load_s
                t1 = time.monotonic()
                got = s.run(cases["runs"])
                run_s = time.monotonic() - t1
                cycles = s.cycles - s.load_cycles
        n = len(cases["runs"])
        info = {"n": n, "cycles": cycles, "run_s": run_s, "build_s": max(0.0, build_s),
                "vectors_per_s": n / run_s if run_s > 0 else float("inf"), "latency": None}
        return {"runs": got}, info

    def mismatches(self, expected, got) -> list:
        """Per run: None when equal, else the lines that show the differences."""
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.model.records import COUNTERS

        out = []
        any_hit = expected.get("any_hit") or [False] * len(expected["runs"])
        for k, ((es, ec), (gs, gc)) in enumerate(zip(expected["runs"], got["runs"])):
            lines = beat_lines(es, gs)
            for name in COUNTERS.names:
                if name not in ec:                                   # the model has no cycles
                    continue
                e, g = int(ec[name]), int(gc[name])
                if self.config.reduce and any_hit[k] and name in _EARLY_OUT_COUNTERS:
                    if g > e:                   # the early-out only drops pairs
                        lines.append(f"    counter {name}: expected at most {e}, got {g}   "
                                     "<- differs")
                elif e != g:
                    lines.append(f"    counter {name}: expected {e}, got {g}   <- differs")
            out.append(lines or None)
        return out

    def report(self, cases, expected, got, limit):
        return report_runs(self, cases, self.mismatches(expected, got), limit)

    def describe(self, cases, i):
        b, ids, keep = cases["runs"][i]
        what = "every sphere" if ids is None else f"{len(ids)} spheres"
        return (f"run {i}: {int(b.enable.sum())} of {b.enable.size} rays enabled, {what}"
                + (", keep_all" if keep else ""))


#: Counters of the pairs the any-hit early-out may drop (at most the model's in such runs).
_EARLY_OUT_COUNTERS = ("pairs_issued", "hits", "overflow", "underflow", "invalid")


def _pad(a, width: int) -> np.ndarray:
    """``a`` (n, <= width) padded with zero columns to ``width``."""
    out = np.zeros((a.shape[0], width), np.uint32)
    out[:, :a.shape[1]] = a
    return out
