"""The ``paper`` mode: the unit's hits are the answer; each ray keeps its nearest.

The paper's exact inequalities on the unit's arithmetic (``docs/raplas.md``): the host folds
each ray's nearest accepted hit (ties to the lower triangle ID) from the compiled pass, from
the runs' pair streams, or from the reduced unit's answers, which made that choice on chip.
"""

from __future__ import annotations

import numpy as np

from ...engine.passes import COUNTER_NAMES, result_beats, runs_of, stream_beats, trace_pass
from ...fp import model as fpm
from ..shading import nearest_hits
from .base import RenderMode, register_mode

__all__ = ["PaperMode"]


class PaperMode(RenderMode):
    """The unit's accepted hits folded into each ray's nearest."""

    name = "paper"
    unit_mode = "paper"
    reducible = True

    def trace_compiled(self, backend, batch, run_b, run_start, run_sph, best_t, best_tri,
                       tmin, tmax, exclude, any_hit):
        """:func:`raplas_hdl.engine.passes.trace_pass` on the backend's arithmetic (the
        nearest hit is folded for shadow rays too)."""
        ctr = trace_pass(backend.arithmetic(), backend.scene, batch, run_b, run_start,
                         run_sph, best_t, best_tri, tmin, tmax, exclude)
        backend.beats["result"] += result_beats(ctr)
        return ctr

    def trace_streams(self, backend, batch, run_b, run_start, run_sph, best_t, best_tri,
                      tmin, tmax, exclude, any_hit):
        """Each run's stream through :func:`raplas_hdl.host.shading.nearest_hits`, then
        against what the bundle's rays had before."""
        runs = runs_of(run_b, run_start, run_sph)
        counters = np.zeros((len(runs), len(COUNTER_NAMES)), np.int64)
        R = batch.n_rays
        results = backend.stream(batch, runs) if runs else []
        for k, ((b, _), res) in enumerate(zip(runs, results)):
            counters[k] = [res.counters.get(n, 0) for n in COUNTER_NAMES]
            hi = np.inf if tmax is None else np.asarray(tmax)[b]
            ex = None if exclude is None else int(np.asarray(exclude)[b])
            tri, t, _ = nearest_hits(R, res.ray_id, res.tri_id, res.hit, res.t, tmin, hi, ex)
            better = (tri >= 0) & ((t < best_t[b]) | ((t == best_t[b]) & (tri < best_tri[b])))
            best_t[b] = np.where(better, t, best_t[b])
            best_tri[b] = np.where(better, tri, best_tri[b])
        backend.beats["result"] += stream_beats(results)
        return counters

    def trace_answers(self, backend, batch, run_b, run_start, run_sph, best_t, best_tri,
                      tmin, tmax, exclude, any_hit):
        """The reduced unit's ANSWER beats (one per ray that hit, per run) folded: a
        bundle's rays may answer in several runs of the pass, so the nearest of them, ties
        to the lower triangle ID, then against what the rays had before."""
        runs = runs_of(run_b, run_start, run_sph)
        counters, answers = backend.answers(batch, runs, tmin, tmax, exclude, any_hit)
        keep = [k for k, a in enumerate(answers) if not a["empty"].all()]
        if not keep:
            return counters
        ans = np.concatenate([answers[k] for k in keep])
        b = np.repeat(np.asarray([runs[k][0] for k in keep], np.int64),
                      [len(answers[k]) for k in keep])
        ray, tri = ans["ray_id"].astype(np.int64), ans["tri_id"].astype(np.int64)
        tf, df = fpm.decode(np.stack([ans["t"], ans["det"]]), backend.fmt)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = tf * (1.0 / df)         # as the compiled passes compute it
        order = np.lexsort((tri, t, b * batch.n_rays + ray))
        key = (b * batch.n_rays + ray)[order]
        first = np.ones(order.size, bool)
        first[1:] = key[1:] != key[:-1]
        sel = order[first]
        bs, rs, ts, trs = b[sel], ray[sel], t[sel], tri[sel]
        cur_t, cur_tri = best_t[bs, rs], best_tri[bs, rs]
        better = (ts < cur_t) | ((ts == cur_t) & (trs < cur_tri))
        best_t[bs[better], rs[better]] = ts[better]
        best_tri[bs[better], rs[better]] = trs[better]
        return counters


register_mode(PaperMode())
