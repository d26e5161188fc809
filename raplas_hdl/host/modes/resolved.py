"""The ``certified`` and ``conservative`` modes: the unit's doubtful pairs re-checked on
the host, so the render is the exact reference R's.

- ``certified``: the unit reports per pair hit, miss or uncertain
  (:mod:`raplas_hdl.model.certified`); its misses are final, its hits and uncertain pairs go
  through R's float64 filter, the fold and the exact resolution of what the filter leaves
  (:mod:`raplas_hdl.engine.certified`, :func:`raplas_hdl.host.resolve.resolve_pending`).
- ``conservative``: the unit's hits are a superset of R's (false hits in a band around each
  triangle, docs/conservative-mode.md): each goes through the same filter and resolution as
  an uncertain pair; its misses are final.

The backend's ``mode_stats`` count the work: the unit's certified hits and uncertain pairs,
pairs through the float64 filter, pairs left pending, pairs evaluated exactly and the
seconds that took; a certified render reports them as ``stats["certified"]``.
"""

from __future__ import annotations

import time

import numpy as np

from ...engine import compile_ahead
from ...engine.certified import (CERT_COUNTERS, certified_pass, conservative_pairs,
                                 fold_outcomes)
from ...engine.passes import COUNTER_NAMES, result_beats, runs_of, stream_beats
from ...model.certified import check_certified_format, exact_pairs
from ..resolve import resolve_pending
from .base import RenderMode, register_mode

__all__ = ["ResolvedMode", "CertifiedMode", "ConservativeMode", "resolve_outcomes"]

_N = len(COUNTER_NAMES)
_HITS = COUNTER_NAMES.index("hits")


class ResolvedMode(RenderMode):
    """A unit whose misses are final and whose other pairs R decides on the host."""

    def new_stats(self):
        return dict.fromkeys(("certified_hits", "uncertain", "filtered", "pending", "exact",
                              "exact_s"), 0)

    def trace_compiled(self, backend, batch, run_b, run_start, run_sph, best_t, best_tri,
                       tmin, tmax, exclude, any_hit):
        """:func:`raplas_hdl.engine.certified.certified_pass` (the conservative unit's pairs
        as uncertain ones), then the exact resolution of the pending pairs."""
        if not any_hit and (best_tri[np.asarray(run_b, np.int64)] >= 0).any():
            raise ValueError("a certified nearest-hit pass starts from rays without a hit")
        lo = np.where(best_tri >= 0, best_t, np.inf)
        hi = lo.copy()
        cons = self.unit_mode == "conservative"
        ctr, pending = certified_pass(backend.arithmetic(), backend.scene, batch, run_b,
                                      run_start, run_sph, backend.tris, lo, hi, best_tri, tmin,
                                      tmax, exclude, any_hit,
                                      unit=conservative_pairs if cons
                                      else backend.certified_unit)
        _resolve_pending(backend, batch, pending, lo, hi, best_t, best_tri, tmin, tmax,
                         exclude, any_hit)
        st = backend.mode_stats
        st["certified_hits"] += int(ctr[:, _HITS].sum())
        for k, name in enumerate(CERT_COUNTERS):
            st[name] += int(ctr[:, _N + k].sum())
        if cons:            # every hit of the conservative unit is an "uncertain" pair
            ctr[:, _HITS] = ctr[:, _N]
        backend.beats["result"] += result_beats(ctr[:, :_N])
        return ctr[:, :_N]

    def trace_streams(self, backend, batch, run_b, run_start, run_sph, best_t, best_tri,
                      tmin, tmax, exclude, any_hit):
        """The runs' streams in stream order through :func:`resolve_outcomes` (a
        conservative unit's hits as uncertain pairs)."""
        runs = runs_of(run_b, run_start, run_sph)
        counters = np.zeros((len(runs), _N), np.int64)
        if runs:
            pairs = []
            results = backend.stream(batch, runs)
            for k, ((b, _), res) in enumerate(zip(runs, results)):
                counters[k] = [res.counters.get(n, 0) for n in COUNTER_NAMES]
                out = np.where(res.hit, 2, 0) if res.outcome is None else res.outcome
                pairs.append((b, res.ray_id, res.tri_id, out))
            resolve_outcomes(backend, batch, pairs, best_t, best_tri, tmin, tmax, exclude,
                             any_hit)
            backend.mode_stats["certified_hits"] += int(counters[:, _HITS].sum())
            backend.beats["result"] += stream_beats(results)
        return counters

    def trace_answers(self, backend, batch, run_b, run_start, run_sph, best_t, best_tri,
                      tmin, tmax, exclude, any_hit):
        """The reduced certified unit's answers and uncertain pairs through
        :func:`resolve_outcomes`, as the unreduced render resolves the unit's hits and
        uncertain pairs."""
        runs = runs_of(run_b, run_start, run_sph)
        counters, answers = backend.answers(batch, runs, tmin, tmax, exclude, any_hit)
        keep = [k for k, a in enumerate(answers) if not a["empty"].all()]
        beats = [answers[k][~answers[k]["empty"].astype(bool)] for k in keep]
        backend.beats["uncertain"] += sum(int((a["outcome"] == 2).sum()) for a in beats)
        backend.mode_stats["certified_hits"] += int(counters[:, _HITS].sum())
        resolve_outcomes(backend, batch, [(runs[k][0], a["ray_id"], a["tri_id"], a["outcome"])
                                          for k, a in zip(keep, beats)],
                         best_t, best_tri, tmin, tmax, exclude, any_hit)
        return counters


class CertifiedMode(ResolvedMode):
    """The certified unit: hit, miss or uncertain per pair."""

    name = "certified"
    unit_mode = "certified"
    reducible = True

    def check(self, fmt, reduce):
        check_certified_format(fmt)
        super().check(fmt, reduce)

    def report(self, backend, stats):
        cert = dict(backend.mode_stats)
        cert["uncertain_fraction"] = (cert.get("uncertain", 0) / stats["pairs_issued"]
                                      if stats["pairs_issued"] else 0.0)
        stats["certified"] = cert

    def warm(self, backend, run):
        """From an empty numba cache, compile the block kernel in a second process
        (:mod:`raplas_hdl.engine.compile_ahead`) while a first throw-away pass with every
        pair on the exact path compiles the rest here; then the pass again, which loads the
        block kernel from the cache. Otherwise the one pass."""
        child = (compile_ahead.start() if backend.runs_compiled and not backend.reduce
                 else None)
        if child is None:
            run()
            return
        backend.certified_unit = exact_pairs
        try:
            run()
        finally:
            backend.certified_unit = None
            compile_ahead.join(child)
        run()


class ConservativeMode(ResolvedMode):
    """The conservative unit: its hits a superset of R's, each re-checked."""

    name = "conservative"
    unit_mode = "conservative"


def resolve_outcomes(backend, batch, pairs, best_t, best_tri, tmin, tmax, exclude, any_hit):
    """R's answer per ray from pairs of known outcome, in stream order, into ``best_t,
    best_tri`` (B, R) in place: ``pairs`` is a list of ``(bundle, ray_ids, tri_ids,
    outcomes)`` (0 miss, 1 certain hit, 2 uncertain). Misses are final; the others go
    through R's float64 filter, the fold and the exact resolution of what it leaves
    (:func:`raplas_hdl.engine.certified.fold_outcomes`,
    :func:`raplas_hdl.host.resolve.resolve_pending`), as in the certified pass; counted in
    the backend's ``mode_stats``."""
    if not pairs:
        return
    R = batch.n_rays
    lanes = np.concatenate([np.stack([np.full(len(ray), b), ray, b * R + ray, tri, out])
                            for b, ray, tri, out in
                            ((b, np.asarray(r, np.int64), np.asarray(t, np.int64),
                              np.asarray(o, np.int64)) for b, r, t, o in pairs)],
                           axis=1).astype(np.int64)
    lo = np.where(best_tri >= 0, best_t, np.inf)
    hi = lo.copy()
    pending = fold_outcomes(lanes, lanes[4], batch, backend.tris, lo, hi, best_tri, tmin,
                            tmax, exclude, any_hit)
    _resolve_pending(backend, batch, pending, lo, hi, best_t, best_tri, tmin, tmax, exclude,
                     any_hit)
    st = backend.mode_stats
    st["pending"] += len(pending)
    st["uncertain"] += int((lanes[4] == 2).sum())
    st["filtered"] += int((lanes[4] != 0).sum())


def _resolve_pending(backend, batch, pending, lo, hi, best_t, best_tri, tmin, tmax, exclude,
                     any_hit):
    """The exact resolution of the pending pairs, counted in ``mode_stats`` (``exact``,
    ``exact_s``)."""
    t0 = time.perf_counter()
    exact = resolve_pending(pending, batch.origin, batch.directions, backend.tris, lo, hi,
                            best_tri, best_t, tmin, tmax, exclude, any_hit)
    backend.mode_stats["exact_s"] += time.perf_counter() - t0
    backend.mode_stats["exact"] += exact


register_mode(ConservativeMode())
register_mode(CertifiedMode())
