"""Golden model of the on-chip reduction: one answer per ray leaves the unit, not one beat per pair.

With ``UnitConfig(reduce=True)`` the intersection unit folds each run's result stream (the
beats of :data:`~raplas_hdl.model.records.RESULT`, as :func:`run_runs` makes them without
the reduction) into the answers of its rays (:data:`~raplas_hdl.model.records.ANSWER`):

- a pair is a *candidate* when the host would accept it: ``hit``, ``t'`` and ``det``
  finite, ``det != 0``, ``tmin <= t'/det <= tmax[ray]`` and ``tri_id != exclude``. The
  window (``tmin`` and ``exclude`` per bank, ``tmax`` per ray, bit patterns of the format)
  and the bank's ``any_hit`` bit are written by the host with the bundle
  (:func:`~raplas_hdl.model.memory_image.bundle_writes`, the WINDOW region and RAY field 7);
- a *nearest-hit* bundle (``any_hit`` 0): per ray, the candidate with the smallest
  ``t'/det``, equal ratios to the lowest triangle ID, then the earliest in the stream;
- an *any-hit* bundle (shadow rays): per ray, the first candidate of the stream; the unit
  stops issuing the ray's pairs once it has one (the early-out), which never changes it;
- the answers leave in ascending ray order, one beat per ray that has one, the last marked
  ``last``; a run without any gives one ``empty`` beat (``last`` set, all else 0).

A ``certified`` unit (:data:`~raplas_hdl.model.records.ANSWER_CERTIFIED`, ``outcome`` on
every beat): only a certain hit (``outcome`` 1) is a candidate; an *uncertain* pair
(``outcome`` 2) is not folded but leaves the unit for the host as its own beat
(:func:`uncertain_pairs`): every uncertain pair of the run except those of the excluded
triangle (no window test: its ``t'/det`` is not trusted; NaN, say, when the pair is
uncertain because an operation overflowed) and, in an any-hit bundle, except those after
their ray's first candidate (the ray is blocked; only a certain candidate blocks). A run's
beats: its uncertain pairs in stream order (``outcome`` 2), then its answers (``outcome``
1) as above, or, when it has no answer, the ``empty`` beat (``outcome`` 0). The host
re-checks both kinds (``docs/intersection-unit.md``).

Every comparison is exact: ``t'/det`` against ``t2'/det2`` is ``t'*|det2|`` against
``t2'*|det|`` with the signs of ``det`` moved onto the numerators (the RTL multiplies the
significands), and ``tmin <= t'/det`` is ``tmin*|det| <= t'*sign(det)``. Here the products
are float64 products of the patterns' exact values, exact because a significand has at most
25 bits and an exponent 9 (:func:`check_reduce_format`); the order of the ratios is that of
``fl(t'/det)``, one correctly rounded division, since two distinct ratios of significands of
``M+1 <= 25`` bits differ by more than a relative ``2**-(2M+2)``, far more than the
division's rounding, and equal ratios round alike. ``docs/intersection-unit.md`` argues why
the answers equal the host's choice (:func:`raplas_hdl.host.shading.nearest_hits`) on the
unreduced stream.

No Amaranth.
"""

from __future__ import annotations

import numpy as np

from ..fp import model as fpm
from .records import ANSWER, OUTCOME_HIT, OUTCOME_UNCERTAIN, answer_record

__all__ = ["ANSWER_DTYPE", "answer_dtype", "uncertain_pairs", "check_reduce_format",
           "check_window", "candidates", "reduce_run", "first_answers", "early_out_saving",
           "inf_pattern"]

#: One beat of the reduced stream (the dtype of :data:`~raplas_hdl.model.records.ANSWER`).
ANSWER_DTYPE = ANSWER.dtype()


def answer_dtype(config) -> np.dtype:
    """The dtype of ``config``'s reduced stream (:func:`~raplas_hdl.model.records.answer_record`:
    :data:`ANSWER_DTYPE`, with ``outcome`` in ``certified`` mode)."""
    return answer_record(config).dtype()


def inf_pattern(fmt) -> int:
    """The +infinity pattern of ``fmt`` (a ray's ``tmax`` when it has none)."""
    return ((1 << fmt.exp_bits) - 1) << fmt.man_bits


def check_reduce_format(fmt):
    """Raise ``ValueError`` unless the reduction is exact in ``fmt`` (significands of at most
    25 bits, exponents of at most 9: float64 holds every product of two values exactly)."""
    if fmt.man_bits > 24 or fmt.exp_bits > 9:
        raise ValueError(f"the on-chip reduction needs man_bits <= 24 and exp_bits <= 9 "
                         f"(exact products in float64), not {fmt}")


def _is_nan(bits, fmt):
    bits = np.asarray(bits, np.int64)
    e = (bits >> fmt.man_bits) & ((1 << fmt.exp_bits) - 1)
    return (e == (1 << fmt.exp_bits) - 1) & ((bits & ((1 << fmt.man_bits) - 1)) != 0)


def check_window(config, bundle):
    """Raise ``ValueError`` unless ``bundle``'s window fits ``config``: ``tmin`` finite,
    ``tmax`` finite or +infinity, ``exclude`` -1 or a triangle ID below ``max_triangles``."""
    fmt = config.fmt
    check_reduce_format(fmt)
    e_max = (1 << fmt.exp_bits) - 1
    if bundle.tmin > fmt.mask or (bundle.tmin >> fmt.man_bits) & e_max == e_max:
        raise ValueError(f"tmin must be a finite pattern of {fmt}, not {bundle.tmin:#x}")
    if bundle.tmax is not None:
        tm = bundle.tmax.astype(np.int64)
        if tm.size and tm.max() > fmt.mask:
            raise ValueError(f"tmax holds patterns wider than {fmt}")
        neg_inf = inf_pattern(fmt) | (1 << (fmt.width - 1))
        if (_is_nan(tm, fmt) | (tm == neg_inf)).any():
            raise ValueError("tmax must be finite or +infinity (no NaN, no -infinity)")
    if not -1 <= bundle.exclude < config.max_triangles:
        raise ValueError(f"exclude must be -1 or a triangle ID below max_triangles="
                         f"{config.max_triangles}, not {bundle.exclude}")


def candidates(fmt, beats, tmin: int, tmax, exclude: int) -> np.ndarray:
    """Which beats of a run's unreduced stream the host would accept (bool array).

    ``beats``: :data:`~raplas_hdl.model.records.RESULT` beats; ``tmin``: a pattern;
    ``tmax``: per ray patterns (indexed by ``ray_id``); ``exclude``: a triangle ID or -1.
    """
    if beats.size == 0 or beats["empty"].any():
        return np.zeros(beats.size, bool)
    t = fpm.decode(beats["t"], fmt)
    det = fpm.decode(beats["det"], fmt)
    lo = float(fpm.decode(np.array([tmin], np.uint32), fmt)[0])
    hi = fpm.decode(np.asarray(tmax, np.uint32), fmt)[beats["ray_id"].astype(np.int64)]
    ok = beats["hit"].astype(bool) & np.isfinite(t) & np.isfinite(det) & (det != 0)
    num = np.where(det < 0, -t, t)          # t'/det = num/|det|, |det| > 0
    den = np.abs(det)
    with np.errstate(invalid="ignore"):
        ok &= (lo * den <= num) & (num <= hi * den)   # exact products (check_reduce_format)
    if exclude >= 0:
        ok &= beats["tri_id"].astype(np.int64) != exclude
    return ok


def _ratio(fmt, beats):
    """``fl(t'/det)``: a key with the exact order and the exact ties of ``t'/det``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return fpm.decode(beats["t"], fmt) / fpm.decode(beats["det"], fmt)


def first_answers(n_rays: int, ray_id, ok, key=None, tri_id=None) -> np.ndarray:
    """Per ray, the index of its answer among the beats (-1 for none): the first candidate
    in stream order, or with ``key`` the smallest ``key``, then the lowest ``tri_id``, then
    the first in the stream."""
    ray_id = np.asarray(ray_id, np.int64)
    idx = np.flatnonzero(ok)
    best = np.full(n_rays, -1, np.int64)
    if idx.size == 0:
        return best
    if key is None:
        order = idx[np.argsort(ray_id[idx], kind="stable")]
    else:
        order = idx[np.lexsort((idx, np.asarray(tri_id, np.int64)[idx], key[idx],
                                ray_id[idx]))]
    first = np.ones(order.size, bool)
    first[1:] = ray_id[order[1:]] != ray_id[order[:-1]]
    best[ray_id[order[first]]] = order[first]
    return best


def uncertain_pairs(config, beats, bundle, ok=None) -> np.ndarray:
    """Which beats of a certified run's unreduced stream leave the reduced unit as uncertain
    pairs (bool array; all False in another mode): ``outcome`` 2, not the excluded triangle,
    and in an any-hit bundle before their ray's first candidate (``ok``: :func:`candidates`,
    computed when not given)."""
    out = np.zeros(beats.size, bool)
    if config.mode != "certified" or beats.size == 0 or beats["empty"].any():
        return out
    out = beats["outcome"] == OUTCOME_UNCERTAIN
    if bundle.exclude >= 0:
        out &= beats["tri_id"].astype(np.int64) != bundle.exclude
    if bundle.any_hit:
        if ok is None:
            ok = candidates(config.fmt, beats, bundle.tmin, bundle.window_tmax(config),
                            bundle.exclude)
        ray = beats["ray_id"].astype(np.int64)
        first = first_answers(config.n_rays, ray, ok)[ray]
        out &= (first < 0) | (np.arange(beats.size) < first)
    return out


def reduce_run(config, beats, bundle):
    """The reduced stream of one run from its unreduced ``beats``.

    Parameters
    ----------
    config : UnitConfig
    beats : numpy structured array of ``result_dtype(config)``
        The run's result stream (:func:`raplas_hdl.model.intersection.run_runs` without
        the reduction).
    bundle : BundleMemory
        Its window (``tmin``, ``tmax``, ``exclude``) and mode (``any_hit``).

    Returns
    -------
    numpy structured array of :func:`answer_dtype`
        In ``certified`` mode the run's uncertain pairs (:func:`uncertain_pairs`) first.
    """
    fmt = config.fmt
    check_window(config, bundle)
    dtype = answer_dtype(config)
    certified = config.mode == "certified"
    ok = candidates(fmt, beats, bundle.tmin, bundle.window_tmax(config), bundle.exclude)
    ray = beats["ray_id"].astype(np.int64)
    if bundle.any_hit:
        best = first_answers(config.n_rays, ray, ok)
    else:
        best = first_answers(config.n_rays, ray, ok, _ratio(fmt, beats), beats["tri_id"])
    rays = np.flatnonzero(best >= 0)
    unc = beats[uncertain_pairs(config, beats, bundle, ok)]
    out = np.zeros(unc.size + max(1, rays.size), dtype)
    keys = ("ray_id", "tri_id", "t", "u", "v", "det", "flags")
    if rays.size == 0:
        out["empty"][-1] = 1
    else:
        win = beats[best[rays]]
        for key in keys:
            out[key][unc.size:] = win[key]
        if certified:
            out["outcome"][unc.size:] = OUTCOME_HIT
    for key in keys:
        out[key][:unc.size] = unc[key]
    if certified:
        out["outcome"][:unc.size] = OUTCOME_UNCERTAIN
    out["last"][-1] = 1
    return out


def early_out_saving(config, beats, bundle) -> int:
    """Pairs of an any-hit run issued after their ray's first candidate: what an early-out
    with no latency would not issue (the RTL's saving is at most this; 0 for a nearest-hit
    run)."""
    if not bundle.any_hit or beats.size == 0 or beats["empty"].any():
        return 0
    ok = candidates(config.fmt, beats, bundle.tmin, bundle.window_tmax(config),
                    bundle.exclude)
    ray = beats["ray_id"].astype(np.int64)
    first = first_answers(config.n_rays, ray, ok)
    pos = np.arange(beats.size)
    f = first[ray]
    return int(np.count_nonzero((f >= 0) & (pos > f)))
