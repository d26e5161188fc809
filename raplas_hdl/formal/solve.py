"""Run one solver call on a miter, bounded in time, in a child process.

The solver is z3 with a fixed tactic: ``simplify``, ``fpa2bv`` (FloatingPoint terms of the
reference become bit vectors), ``ackermannize_bv`` (the cut product of :mod:`.cut`
becomes fresh variables with consistency constraints), ``solve-eqs`` (the unrolled
transition relation collapses), ``bit-blast`` and z3's SAT solver. On the FP24 adder this
is about three times faster than z3's default ``QF_FPBV`` solver.

z3 honours its own ``timeout`` mostly, but not inside every preprocessing step; the call
therefore runs in a forked child that is killed a few seconds after the time is up, so
that no call outlives its budget.
"""

from __future__ import annotations

import multiprocessing
import time
from dataclasses import dataclass, field

import z3

__all__ = ["SolverRun", "solve", "tactic", "TACTICS", "SOLVER"]

#: The tactic chain (see the module docstring).
TACTICS = ("simplify", "fpa2bv", "ackermannize_bv", "simplify", "solve-eqs", "bit-blast", "sat")

#: The solver name reported in results.
SOLVER = f"z3 {z3.get_version_string()} ({' > '.join(TACTICS)})"

#: Seconds a child gets beyond its timeout before it is killed.
GRACE = 5.0


@dataclass
class SolverRun:
    """Outcome of one call.

    Attributes
    ----------
    result : str
        ``proved`` (the miter is unsatisfiable), ``counterexample`` or ``unknown``.
    seconds : float
        Wall-clock time of the call.
    values : dict
        For a counterexample: the value of each watched term (``int``).
    reason : str
        Why the result is ``unknown`` (timeout, solver message).
    """

    result: str
    seconds: float
    values: dict = field(default_factory=dict)
    reason: str = ""


def tactic(ackermann_limit: int | None = None) -> z3.Tactic:
    """The chain of :data:`TACTICS`; ``ackermann_limit`` raises ``ackermannize_bv``'s limit
    on the consistency lemmas it adds (z3's default 1,000; above it the tactic leaves the
    functions in place and the SAT solver gives up)."""
    steps = [z3.With(t, div0_ackermann_limit=ackermann_limit)
             if t == "ackermannize_bv" and ackermann_limit else t for t in TACTICS]
    return z3.Then(*steps)


def _child(goal, timeout, watch, conn, ackermann_limit):
    try:
        solver = tactic(ackermann_limit).solver()
        solver.set("timeout", max(1, int(timeout * 1000)))
        solver.add(goal)
        r = solver.check()
        if r == z3.unsat:
            conn.send(("proved", {}, ""))
        elif r == z3.sat:
            m = solver.model()
            conn.send(("counterexample",
                       {k: m.eval(t, model_completion=True).as_long() for k, t in watch.items()},
                       ""))
        else:
            conn.send(("unknown", {}, solver.reason_unknown()))
    except Exception as exc:  # noqa: BLE001 (reported as unknown with the reason)
        conn.send(("unknown", {}, f"{type(exc).__name__}: {exc}"))
    finally:
        conn.close()


def solve(goal: z3.BoolRef, timeout: float, watch: dict | None = None, *,
          ackermann_limit: int | None = None) -> SolverRun:
    """Check ``goal`` for satisfiability within ``timeout`` seconds.

    Parameters
    ----------
    goal : z3.BoolRef
        The miter: satisfiable exactly when the property fails.
    timeout : float
        Seconds for the solver; the child is killed :data:`GRACE` seconds later.
    watch : dict, optional
        Name -> bit-vector term whose value a counterexample reports.
    ackermann_limit : int, optional
        See :func:`tactic`.
    """
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    t0 = time.monotonic()
    proc = ctx.Process(target=_child, args=(goal, timeout, watch or {}, send, ackermann_limit),
                       daemon=True)
    proc.start()
    send.close()
    got = None
    if recv.poll(timeout + GRACE):
        try:
            got = recv.recv()
        except EOFError:
            got = None
    seconds = time.monotonic() - t0
    if proc.is_alive():
        proc.kill()
    proc.join()
    if got is None:
        return SolverRun("unknown", seconds, reason=f"no answer after {timeout:g} s")
    result, values, reason = got
    if result == "unknown" and reason in ("timeout", "canceled"):
        reason = f"timeout after {timeout:g} s"
    return SolverRun(result, seconds, values, reason)
