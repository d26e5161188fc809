"""Cycle model of the intersection unit: how many cycles its runs take, and so the pairs per
cycle one culling array sustains with ``lanes`` ray-triangle units behind it.

A transaction-level model of the stages of ``docs/intersection-unit.md`` (no Amaranth), run
over the same runs as the golden model (:func:`profile_runs` takes them as
:func:`raplas_hdl.model.intersection.run_runs` does and culls with the same testers), one
job (one enabled ray of one sphere) at a time in a compiled loop:

1. **feeder**: a run's command is taken when the feeder is idle; a bundle not in the array
   waits for the array to drain, then its ``rows + cols`` planes load, one per cycle; then
   one sphere per cycle while the feeder holds a credit for its sphere FIFO, then the run's
   marker;
2. **plane-sphere array**: one sphere every ``G = ceil((rows + cols) / testers)`` cycles,
   ``array_latency`` cycles to its FIFO's head, at most ``array_capacity`` spheres inside;
   a sphere leaves it into the sphere slice (a ``slice_depth`` FIFO) when the slice has
   room, and reaches the selector ``select_offset`` cycles later;
3. **pair selector**: per sphere, one cycle per ray whose row and column planes both keep
   it (one cycle for a culled sphere or a marker); each enabled ray is a job into the job
   FIFO of lane ``job mod lanes`` (depth 4; a full FIFO stalls the iterator);
4. **record fetch** (per lane): one pair per cycle, the next job taken in the cycle the
   last pair of the current one starts; a pair starts only with a credit (one per pair FIFO
   entry, back ``fetch_return`` cycles after the pair ``fifo_depth`` ahead reached the
   ray-triangle unit); at most ``lane_capacity`` pairs between the fetch and the merger
   (pair FIFO, ray-triangle unit and its FIFO);
5. **merger and result framing**: with ``results="stream"`` (the RTL as built) every pair
   is a result beat and the merger passes one per cycle, in job order; with
   ``results="lanes"`` each lane's results are consumed in the lane (a reduction per lane:
   not built, the model's figure of what K lanes could sustain behind one array);
6. the run ends when its last beat leaves ``o`` (always ready here).

:func:`simulate` gives each run's command and last-beat cycles; ``cycles`` of a run in
``sequential`` mode (one run at a time, as the RTL's ``cycles`` counter counts it between
runs) or the total of a round of back-to-back runs (``overlap``: the host never the limit).
The stage constants (:class:`Timing`) come from the RTL's latencies (the bench and the
tests read them from the built components); the model is checked against the RTL's
``cycles`` counter in ``tests/rtl/unit/test_lanes.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from numba import njit
from .config import UnitConfig
from .memory_image import as_run
from .plane_sphere import tester_flags

__all__ = ["Timing", "Profile", "profile_runs", "profile_arrays", "simulate",
           "pairs_per_cycle", "RESULT_PATHS"]

#: How results leave the lanes: ``stream`` (one beat per pair, one per cycle through the
#: merger: the RTL) or ``lanes`` (consumed in each lane: the model's what-if).
RESULT_PATHS = ("stream", "lanes")

JOB_FIFO_DEPTH = 4


@dataclass(frozen=True)
class Timing:
    """Stage constants of the cycle model (cycles).

    ``array_latency`` and ``array_capacity`` are the plane-sphere array's ``latency`` and
    ``fifo_depth``, ``rt_latency`` and ``rt_fifo_depth`` the ray-triangle unit's; the small
    offsets are the stage registers between them (the credit pipelines of the feeder and
    the fetch, the selector's stall pipeline, the FIFOs' read latency), fixed by the RTL's
    structure. Each is checked against the RTL's ``cycles`` counter in ``tests/rtl/unit/test_lanes.py``
    (the credits with runs where they bind), except ``lane_slack``: a lane's capacity behind
    the fetch's credits binds only when the merger starves, which the one-per-cycle merger
    never lets happen in a test run; and ``slice_return`` and ``array_capacity``, which bind
    only while the selector is the limit, and then the selector's pace, not the array's,
    sets every run's cycles (in the test runs ``slice_return`` 2 gives other cycles, -1 to
    1 the same).
    """

    array_latency: int
    array_capacity: int
    rt_latency: int
    rt_fifo_depth: int
    fifo_depth: int = 16
    feed_offset: int = 7        # command taken -> first sphere at the array input
    feed_registers: int = 8     # the feeder's credits, its sphere FIFO's depth (an item
    #                             starts feed_return cycles after the one this many ahead
    #                             is taken by the array)
    feed_return: int = 2        # a credit's way back: the array's take -> a start
    select_offset: int = 2      # into the sphere slice -> the selector can take it
    slice_depth: int = 3        # the FIFO between the array and the selector: an item
    slice_return: int = 1       # leaves the array slice_return cycles after the item
    #                             slice_depth ahead was taken by the selector, at best
    job_offset: int = 2         # job into the job FIFO -> fetch can take it
    fetch_offset: int = 6       # pair started -> at the ray-triangle unit's input
    fetch_return: int = 2       # the record fetch's credit back: unit input -> a start
    out_offset: int = 4         # the marker's result into the result FIFO -> last beat taken
    load_offset: int = 1        # drained -> planes loaded, beyond rows + cols
    drain_offset: int = 2       # the previous run's marker taken by the selector -> drained
    lane_slack: int = -1        # a lane holds fifo_depth + rt_fifo_depth + this many pairs
    #                             (the fetch's credits come back two cycles late)

    @classmethod
    def of(cls, config: UnitConfig, array_latency: int, array_capacity: int,
           rt_latency: int, rt_fifo_depth: int, slice_depth: int = 3) -> Timing:
        """The timing of ``config`` with the array's and the ray-triangle unit's figures and
        the depth of the sphere slice between the array and the selector."""
        return cls(array_latency, array_capacity, rt_latency, rt_fifo_depth,
                   fifo_depth=config.fifo_depth, slice_depth=slice_depth)


@dataclass
class Profile:
    """The runs as the cycle model sees them (flat arrays, runs in order).

    ``item_*``: one item per sphere of a run plus one for the run's marker; ``job_*``: one
    per enabled ray of a sphere with triangles, plus the marker's job (one pair).
    """

    run_items: np.ndarray       # (runs + 1,) item offsets
    run_load: np.ndarray        # (runs,) the run's bundle must be loaded into the array
    item_slots: np.ndarray      # (items,) iterator cycles of the item
    item_jobs: np.ndarray       # (items + 1,) job offsets
    job_slot: np.ndarray        # (jobs,) the iterator cycle of the job within its item
    job_pairs: np.ndarray       # (jobs,) pairs of the job (1 for a marker)
    pairs: int                  # pairs issued (markers not counted)
    spheres: int

    @property
    def n_runs(self) -> int:
        return int(self.run_load.size)


def _run_items(config: UnitConfig, keep, ntris, enable):
    """Items and jobs of one run from its spheres' plane flags ``keep`` (S, rows + cols)."""
    rows, cols = config.rows, config.cols
    s_n = keep.shape[0]
    row, col = keep[:, :rows], keep[:, rows:]
    both = (row[:, :, None] & col[:, None, :]).reshape(s_n, rows * cols)
    both &= (ntris > 0)[:, None]
    n_both = both.sum(axis=1)
    slots = np.maximum(n_both, 1)
    slot_rank = np.cumsum(both, axis=1) - 1
    job = both & enable[None, :]
    s_idx, ray = np.nonzero(job)
    job_slot = slot_rank[s_idx, ray]
    job_pairs = ntris[s_idx]
    jobs_per = np.bincount(s_idx, minlength=s_n)
    # the marker: one slot, one job of one pair
    slots = np.append(slots, 1)
    jobs_per = np.append(jobs_per, 1)
    job_slot = np.append(job_slot, 0)
    job_pairs = np.append(job_pairs, 1)
    pairs = int(job_pairs[:-1].sum())
    return slots, jobs_per, job_slot, job_pairs, pairs


def profile_arrays(config: UnitConfig, runs) -> Profile:
    """The profile of ``runs``, each ``(planes_n, planes_p, centres, radii, ntris, enable,
    keep_all, bundle_key)``: the run's bundle planes (P, 3) and (P,), its spheres' centres
    (S, 3), inflated radii (S,) and triangle counts (S,) (bit patterns as the memories hold
    them), the bundle's enable bits (rows*cols,), the ``keep_all`` bit, and a key equal
    between runs of one bundle (a new key loads planes)."""
    slots, jobs_per, job_slot, job_pairs, loads, n_items = [], [], [], [], [], []
    pairs = spheres = 0
    prev = object()
    for pn, pp, centres, radii, ntris, enable, keep_all, key in runs:
        ntris = np.asarray(ntris, np.int64)
        s_n = ntris.size
        if keep_all or s_n == 0:
            keep = np.ones((s_n, config.n_planes), bool)
        else:
            keep = tester_flags(pn, pp, centres, radii, config.fmt)
        sl, jp, js, jpair, p = _run_items(config, keep, ntris, np.asarray(enable, bool))
        slots.append(sl)
        jobs_per.append(jp)
        job_slot.append(js)
        job_pairs.append(jpair)
        loads.append(key != prev)
        n_items.append(sl.size)
        prev = key
        pairs += p
        spheres += s_n
    run_items = np.zeros(len(n_items) + 1, np.int64)
    np.cumsum(n_items, out=run_items[1:])
    cat = (lambda parts: np.concatenate(parts).astype(np.int64) if parts
           else np.zeros(0, np.int64))
    jp = cat(jobs_per)
    item_jobs = np.zeros(jp.size + 1, np.int64)
    np.cumsum(jp, out=item_jobs[1:])
    return Profile(run_items, np.array(loads, bool), cat(slots), item_jobs, cat(job_slot),
                   cat(job_pairs), pairs, spheres)


def profile_runs(config: UnitConfig, scene, runs) -> Profile:
    """The profile of ``runs`` (as :func:`raplas_hdl.model.intersection.run_runs` takes
    them) over ``scene`` (a :class:`~raplas_hdl.model.memory_image.SceneMemory`). A run
    reuses the array's planes when its bundle has the previous run's planes and rays (the
    driver then reuses the bank and rewrites only the enable bits)."""
    def gen():
        prev, key = None, 0
        for run in runs:
            bundle, ids, keep_all = as_run(run)
            ids = (np.arange(scene.n_spheres) if ids is None
                   else np.asarray(ids, np.int64).reshape(-1))
            if prev is None or not all(np.array_equal(getattr(bundle, f), getattr(prev, f))
                                       for f in ("plane_n", "plane_p", "ray_o", "ray_d")):
                key += 1
            prev = bundle
            yield (bundle.plane_n, bundle.plane_p, scene.centres[ids], scene.radii[ids],
                   scene.tri_counts[ids], bundle.enable, bool(keep_all or bundle.keep_all),
                   key)
    return profile_arrays(config, gen())


@njit(cache=True)
def _simulate(run_items, run_load, writes, after, item_slots, item_jobs, job_slot, job_pairs,
              lanes, stream, overlap, passes, n_planes, c_array_lat, c_array_cap, c_select,
              c_job, c_fetch, c_back, c_out, c_feed, c_load, c_lane_cap, job_depth,
              feed_regs, feed_ret, c_drain, depth, fetch_ret, c_slice, c_slice_ret):
    n_runs = run_load.size
    n_items = item_slots.size
    n_jobs = job_pairs.size
    t_cmd = np.zeros(n_runs, np.int64)
    t_last = np.zeros(n_runs, np.int64)
    take = np.zeros(n_items, np.int64)          # selector takes the item
    acc = np.zeros(n_items, np.int64)           # the array takes the item
    leave = np.zeros(n_items, np.int64)         # the item leaves the array (into the slice)
    leave_prev = -(1 << 40)
    p = 0
    pop = np.zeros(n_jobs, np.int64)            # a lane's fetch takes the job
    lane_next = np.zeros(lanes, np.int64)       # earliest next pop of each lane
    lane_count = np.zeros(lanes, np.int64)      # pairs through each lane so far
    ring = np.full((lanes, c_lane_cap), -(1 << 40), np.int64)  # merge times, per lane
    starts = np.zeros((lanes, depth), np.int64)  # the last pairs' start cycles, per lane
    a_prev = -(1 << 40)
    x_free = -(1 << 40)        # the iterator can take the next item from this cycle
    hold = -(1 << 40)          # the enable stage is free from this cycle
    merge_prev = -(1 << 40)
    feed_idle = 0              # the feeder can take a command from this cycle
    marker_take = -(1 << 40)   # the previous run's marker left the array
    last_prev = -1
    for r in range(n_runs):
        if overlap:
            # the host: the run's writes after the previous command (and after the last
            # beat of the run ``after`` names, the bank's previous run), then the command
            ready = writes[r]
            if r >= 1:
                ready = t_cmd[r - 1] + 1 + writes[r]
            if after[r] >= 0:
                ready = max(ready, t_last[after[r]] + 1 + writes[r])
            t = max(feed_idle, ready)
        else:
            t = last_prev + 1 if r else 0
        t_cmd[r] = t
        start = t + 1
        if run_load[r]:
            start = max(start, marker_take + c_drain) + n_planes + c_load
        i0 = run_items[r]
        i1 = run_items[r + 1]
        for s in range(i0, i1):
            # the feeder starts item s when it holds a credit (feed_ret cycles after the
            # item feed_regs ahead is taken by the array); the array takes it c_feed - 1
            # cycles later at best
            p = start if s == i0 else p + 1
            if s - feed_regs >= 0:
                p = max(p, acc[s - feed_regs] + feed_ret)
            a = max(p + c_feed - 1, a_prev + passes)
            if s - c_array_cap >= 0:
                a = max(a, leave[s - c_array_cap] + 1)
            a_prev = a
            acc[s] = a
            # out of the array's FIFO into the slice when the slice has room
            lv = max(a + c_array_lat, leave_prev + 1)
            if s - c_slice >= 0:
                lv = max(lv, take[s - c_slice] + c_slice_ret)
            leave[s] = lv
            leave_prev = lv
            avail = lv + c_select
            tk = max(avail, x_free)
            take[s] = tk
            # slot k is offered from tk + 1 on; the offer after a job waits until the job
            # is written (hold); x: cycle the last offer was accepted, k_last its slot
            x = tk
            k_last = -1
            for j in range(item_jobs[s], item_jobs[s + 1]):
                lane = j % lanes
                k = job_slot[j]
                x = max(x + 1, hold) + (k - k_last - 1)
                k_last = k
                w = x + 1                  # into the lane's job FIFO, when it has room
                back = j - lanes * job_depth
                if back >= 0:
                    w = max(w, pop[back] + 1)
                hold = w
                f = max(w + c_job, lane_next[lane])
                pop[j] = f
                s_start = f
                for m in range(job_pairs[j]):
                    s_start = s_start + 1
                    q = lane_count[lane]
                    if q >= c_lane_cap:
                        s_start = max(s_start, ring[lane, q % c_lane_cap] + 1)
                    # the record fetch's credits: one per pair FIFO entry, back
                    # fetch_ret cycles after the pair D ahead reached the unit
                    if q >= depth:
                        s_start = max(s_start, starts[lane, q % depth] + c_fetch + fetch_ret)
                    starts[lane, q % depth] = s_start
                    mt = s_start + c_fetch + c_back
                    if stream:
                        mt = max(mt, merge_prev + 1)
                        merge_prev = mt
                    ring[lane, q % c_lane_cap] = mt
                    lane_count[lane] = q + 1
                    if s == i1 - 1:
                        t_last[r] = mt + c_out
                lane_next[lane] = s_start
            n = item_slots[s]
            if k_last < n - 1:
                x = max(x + 1, hold) + (n - 1 - k_last - 1)
            x_free = x
        marker_take = take[i1 - 1]
        feed_idle = p + 1
        last_prev = t_last[r]
    return t_cmd, t_last


def simulate(profile: Profile, config: UnitConfig, timing: Timing, *,
             lanes: int | None = None, results: str = "stream", overlap: bool = True,
             host=None):
    """Command and last-beat cycles of every run of ``profile``.

    Parameters
    ----------
    lanes : int, optional
        Ray-triangle lanes (default ``config.lanes``).
    results : {"stream", "lanes"}
        See :data:`RESULT_PATHS`.
    overlap : bool
        Runs back to back (the next command as soon as the feeder is idle) or one at a time
        (the next command after the last beat of the previous run).
    host : (writes, after), optional
        With ``overlap``, the host's part (the job-stream harness's order): before each
        run's command its ``writes[r]`` words at one per cycle, written after the previous
        command and after the last beat of run ``after[r]`` (the last run in the bank it
        writes; -1: none). Default: none (the host never the limit).

    Returns
    -------
    t_cmd, t_last : int64 arrays (runs,)
        The cycle the run's command is taken and the cycle its last beat leaves; a run's
        ``cycles`` (the RTL counter, without overlap) is ``t_last - t_cmd``.
    """
    if results not in RESULT_PATHS:
        raise ValueError(f"results must be one of {', '.join(RESULT_PATHS)}, not {results!r}")
    lanes = config.lanes if lanes is None else int(lanes)
    passes = math.ceil(config.n_planes / config.n_testers)
    lane_cap = timing.fifo_depth + timing.rt_fifo_depth + timing.lane_slack
    if profile.n_runs == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    writes, after = ((np.zeros(profile.n_runs, np.int64), np.full(profile.n_runs, -1))
                     if host is None else host)
    return _simulate(profile.run_items, profile.run_load, np.asarray(writes, np.int64),
                     np.asarray(after, np.int64), profile.item_slots,
                     profile.item_jobs, profile.job_slot, profile.job_pairs, lanes,
                     results == "stream", overlap, passes, config.n_planes,
                     timing.array_latency, timing.array_capacity, timing.select_offset,
                     timing.job_offset, timing.fetch_offset, timing.rt_latency,
                     timing.out_offset, timing.feed_offset, timing.load_offset, lane_cap,
                     JOB_FIFO_DEPTH, timing.feed_registers, timing.feed_return,
                     timing.drain_offset, timing.fifo_depth, timing.fetch_return,
                     timing.slice_depth, timing.slice_return)


def pairs_per_cycle(profile: Profile, config: UnitConfig, timing: Timing, *,
                    lanes: int | None = None, results: str = "stream") -> tuple[int, float]:
    """``(cycles, pairs per cycle)`` of the profile's runs back to back (overlap): the
    cycles from the first command to the last beat."""
    t_cmd, t_last = simulate(profile, config, timing, lanes=lanes, results=results,
                             overlap=True)
    if t_cmd.size == 0:
        return 0, 0.0
    cycles = int(t_last.max() - t_cmd[0])
    return cycles, profile.pairs / cycles
