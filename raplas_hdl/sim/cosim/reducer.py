"""``reducer``: the on-chip reduction alone in the batch harness
(:mod:`raplas_hdl.sim.drive.reducer_harness`), a run per case, every answer compared."""

from __future__ import annotations

import numpy as np

from .base import UnitCosim, beat_lines, report_runs


class ReducerCosim(UnitCosim):
    """``reducer``: a case is one run, a random result stream with a random window
    (:func:`~raplas_hdl.sim.drive.reducer_harness.random_runs`: ties, signs, zeros,
    infinities, NaNs, runs without pairs or hits, nearest-hit and any-hit runs in both
    banks); compared: every field of every ANSWER beat. Random cases only (no vectors file)."""

    name = "reducer"
    outputs = ("answers",)
    case_name = "runs"

    def __init__(self, fmt, options, driver="batch"):
        super().__init__(fmt, options, driver)
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.model.config import UnitConfig

        kw = {k: self.options[k] for k in ("rows", "cols") if k in self.options}
        # the Triangle Memory of tests/rtl/unit/test_reducer.py (the tri IDs of the beats)
        self.config = UnitConfig(fmt=fmt, max_triangles=16, reduce=True, **kw)

    def check(self):
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.model.reduction import check_reduce_format

        check_reduce_format(self.fmt)       # the constructor built the UnitConfig

    def random(self, n, seed):
        # lazy: the reducer's harness loads Amaranth; importing raplas_hdl.sim.cosim needs none
        from ..drive.reducer_harness import random_runs

        return {"runs": random_runs(self.config, n, seed,
                                    beats_per_run=4 * self.config.n_rays)}

    def n_cases(self, cases):
        return len(cases["runs"])

    def expected(self, cases):
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.model.reduction import reduce_run

        return {"answers": [reduce_run(self.config, beats, bundle)
                            for beats, bundle in cases["runs"]]}

    def simulate(self, cases, simulator, *, valid_density, stall_density, seed,
                 timeout_s=None):
        # lazy: the reducer's harness loads Amaranth; importing raplas_hdl.sim.cosim needs none
        from ..drive.reducer_harness import cosim_reducer

        got, want, info = cosim_reducer(simulator, self.config, cases["runs"], seed=seed,
                                        valid_density=valid_density,
                                        stall_density=stall_density,
                                        build_key=f"reducer-{self.fmt.name}")
        # the answers of run k: up to and including its k-th LAST beat
        ends = np.flatnonzero(got["last"]) + 1
        runs = np.split(got, ends[:-1]) if len(ends) == len(cases["runs"]) else [got]
        info = {**info, "n": len(cases["runs"]), "latency": None,
                "vectors_per_s": len(cases["runs"]) / info["run_s"] if info["run_s"] > 0
                else float("inf")}
        return {"answers": runs}, info

    def report(self, cases, expected, got, limit):
        exp, out = expected["answers"], got["answers"]
        if len(out) != len(exp):          # the LAST bits do not split the answers into runs
            return len(exp), [f"    runs         expected {len(exp)}, got {len(out)}"
                              "   <- differs"]
        return report_runs(self, cases, [beat_lines(e, g) for e, g in zip(exp, out)], limit)

    def describe(self, cases, i):
        beats, bundle = cases["runs"][i]
        return (f"run {i}: {len(beats)} result beats, "
                + ("any-hit" if bundle.any_hit else "nearest-hit")
                + f" (bank {i % 2})")
