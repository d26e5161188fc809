"""``board-top``: the board-level top under the host's driver
(:mod:`raplas_hdl.sim.drive.board_sim`), a run per case, every result beat and counter
compared as for the intersection unit."""

from __future__ import annotations

from .base import UnitCosim
from .intersection import IntersectionCosim


class BoardCosim(IntersectionCosim):
    """``board-top``: the cases, the expected results and the vectors files of
    ``intersection-unit`` (:class:`~.intersection.IntersectionCosim`), run through
    ``board_top``'s Wishbone port by :class:`raplas_hdl.link.driver.BoardDriver`
    under cocotb (:func:`~raplas_hdl.sim.drive.board_sim.run_board`); the bus master idles
    at random (its seed is ``seed``)."""

    name = "board-top"
    harness = "host driver"

    def check(self):
        UnitCosim.check(self)       # built as `raplas-hdl verilog board-top` builds it

    def simulate(self, cases, simulator, *, valid_density, stall_density, seed,
                 timeout_s=None):
        # lazy: the board's driver loads the model (numba); importing raplas_hdl.sim.cosim
        # needs none
        from ..drive.board_sim import run_board

        got, stats = run_board(simulator, self.config, cases["scene"], cases["runs"], seed=seed,
                               multiplier=self.target, adder=self.adder)
        n = len(cases["runs"])
        run_s = stats["run_s"]
        info = {"n": n, "cycles": sum(int(c.get("cycles", 0)) for _, c in got),
                "run_s": run_s, "build_s": stats["build_s"],
                "vectors_per_s": n / run_s if run_s > 0 else float("inf"), "latency": None}
        return {"runs": got}, info
