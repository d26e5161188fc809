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
every beat) orders only what it knows the order of (:mod:`raplas_hdl.model.ordering`,
:func:`certified_classes`): a candidate must be a *tight* certain hit (``outcome`` 1 and
``tight``, its ``t'`` and ``det`` within a relative ``2**-tight_bits`` of R's) whose
``t'/det`` is not *near* ``tmin`` or ``tmax``; in a nearest-hit bundle a candidate near its
ray's answer (:func:`~raplas_hdl.model.ordering.near`, in stream order) neither replaces
the answer nor is dropped. Everything the unit cannot order leaves it for the host as its
own beat (``outcome`` 2, the pair's fields): an uncertain pair, a certain hit that is not
tight, a tight one near the window, a candidate near its ray's answer; none of the excluded
triangle (no window test on an untrusted ``t'/det``: NaN, say, when the pair is uncertain
because an operation overflowed), and in an any-hit bundle none after its ray's first
candidate (the ray is blocked; only a candidate blocks). A run's beats: those passed on in
stream order, then its answers (``outcome`` 1) as above, or, when it has no answer, the
``empty`` beat (``outcome`` 0). The host resolves both kinds exactly, and R's nearest hit
is among them (``docs/intersection-unit.md``).

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
from .ordering import key_int, key_lt, near, near_int, product_key
from .records import ANSWER, OUTCOME_HIT, OUTCOME_UNCERTAIN, answer_record

__all__ = ["ANSWER_DTYPE", "answer_dtype", "uncertain_pairs", "certified_classes",
           "check_reduce_format",
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


def certified_classes(config, beats, bundle):
    """What a certified unit's reduction does with each beat of a run's unreduced stream
    (bool arrays; :mod:`raplas_hdl.model.ordering`):

    - ``cand``: a *candidate*, a tight certain hit certainly inside the window (the window
      test of :func:`candidates`, and not near ``tmin`` or ``tmax``);
    - ``passed``: passed on to the host as an uncertain pair, subject only to its ray being
      blocked in an any-hit bundle: an uncertain pair, a certain hit that is not tight, or a
      tight one near ``tmin`` or ``tmax`` (each not of the excluded triangle).

    A tight certain hit neither (certainly outside the window, or excluded) is dropped.
    """
    fmt = config.fmt
    n = beats.size
    if n == 0 or beats["empty"].any():
        return np.zeros(n, bool), np.zeros(n, bool)
    not_excl = (beats["tri_id"].astype(np.int64) != bundle.exclude) if bundle.exclude >= 0 \
        else np.ones(n, bool)
    outcome = beats["outcome"]
    tight = beats["tight"].astype(bool)
    passed = ((outcome == OUTCOME_UNCERTAIN) | ((outcome == OUTCOME_HIT) & ~tight)) & not_excl
    cand = np.zeros(n, bool)
    t = beats["t"].astype(np.int64)
    det = beats["det"].astype(np.int64)
    e_max = (1 << fmt.exp_bits) - 1
    sign = fmt.width - 1
    base = np.flatnonzero((outcome == OUTCOME_HIT) & tight & not_excl
                          & (((t >> fmt.man_bits) & e_max) != e_max)
                          & (((det >> fmt.man_bits) & e_max) != e_max)
                          & (((det >> fmt.man_bits) & e_max) != 0))
    if base.size == 0:
        return cand, passed
    t, det = t[base], det[base]
    tmax = np.asarray(bundle.window_tmax(config), np.int64)
    tmax = tmax[beats["ray_id"][base].astype(np.int64)]
    one = np.int64(((1 << (fmt.exp_bits - 1)) - 1) << fmt.man_bits)
    k_num = product_key(fmt, t, one, (t >> sign) ^ (det >> sign))
    k_lo = product_key(fmt, np.full(base.size, bundle.tmin, np.int64), det, bundle.tmin >> sign)
    k_hi = product_key(fmt, tmax, det, tmax >> sign)
    tmax_inf = tmax == inf_pattern(fmt)
    near_w = near(fmt, k_num, k_lo) | (~tmax_inf & near(fmt, k_hi, k_num))
    ok = candidates(fmt, beats[base], bundle.tmin, bundle.window_tmax(config), bundle.exclude)
    cand[base] = ok & ~near_w
    passed[base] |= near_w
    return cand, passed


def _certified_nearest(config, beats, cand):
    """The nearest-hit fold of a certified run's candidates in stream order: per ray the
    index of its answer (-1: none), and which candidates were passed on because they were
    near the ray's answer (:func:`~raplas_hdl.model.ordering.near`) when they came. A
    candidate replaces the answer when its ``t'/det`` is smaller and not near."""
    fmt = config.fmt
    ray = beats["ray_id"].astype(np.int64)
    best = np.full(config.n_rays, -1, np.int64)
    passed = np.zeros(beats.size, bool)
    idx = np.flatnonzero(cand)
    if idx.size == 0:
        return best, passed
    counts = np.bincount(ray[idx], minlength=config.n_rays)
    single = idx[counts[ray[idx]] == 1]
    best[ray[single]] = single
    multi = idx[counts[ray[idx]] > 1]          # rays with two or more: one beat at a time
    if multi.size:
        t = beats["t"].astype(np.int64).tolist()
        det = beats["det"].astype(np.int64).tolist()
        sign = fmt.width - 1
        for i, r in zip(multi.tolist(), ray[multi].tolist()):
            k = int(best[r])
            if k < 0:
                best[r] = i
                continue
            k_new = key_int(fmt, t[i], det[k], (t[i] >> sign) ^ (det[i] >> sign))
            k_cur = key_int(fmt, t[k], det[i], (t[k] >> sign) ^ (det[k] >> sign))
            if near_int(fmt, k_new, k_cur):
                passed[i] = True
            elif key_lt(k_new, k_cur):
                best[r] = i
    return best, passed


def _certified_fold(config, beats, bundle):
    """A certified run's answers (per ray the answer's index, -1: none) and which beats are
    passed on to the host (module docstring)."""
    cand, passed = certified_classes(config, beats, bundle)
    if bundle.any_hit:
        best = first_answers(config.n_rays, beats["ray_id"].astype(np.int64), cand)
        first = best[beats["ray_id"].astype(np.int64)]
        return best, passed & ((first < 0) | (np.arange(beats.size) < first))
    best, near_fold = _certified_nearest(config, beats, cand)
    return best, passed | near_fold


def uncertain_pairs(config, beats, bundle) -> np.ndarray:
    """Which beats of a certified run's unreduced stream leave the reduced unit as uncertain
    pairs (bool array; all False in another mode): those :func:`certified_classes` passes on
    (in an any-hit bundle only before their ray's first candidate), and in a nearest-hit
    bundle the candidates near their ray's answer when they came."""
    if config.mode != "certified" or beats.size == 0 or beats["empty"].any():
        return np.zeros(beats.size, bool)
    return _certified_fold(config, beats, bundle)[1]


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
    ray = beats["ray_id"].astype(np.int64)
    if certified:
        best, unc_mask = _certified_fold(config, beats, bundle)
    else:
        ok = candidates(fmt, beats, bundle.tmin, bundle.window_tmax(config), bundle.exclude)
        if bundle.any_hit:
            best = first_answers(config.n_rays, ray, ok)
        else:
            best = first_answers(config.n_rays, ray, ok, _ratio(fmt, beats), beats["tri_id"])
        unc_mask = np.zeros(beats.size, bool)
    rays = np.flatnonzero(best >= 0)
    unc = beats[unc_mask]
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
    if config.mode == "certified":
        ok = certified_classes(config, beats, bundle)[0]
    else:
        ok = candidates(config.fmt, beats, bundle.tmin, bundle.window_tmax(config),
                        bundle.exclude)
    ray = beats["ray_id"].astype(np.int64)
    first = first_answers(config.n_rays, ray, ok)
    pos = np.arange(beats.size)
    f = first[ray]
    return int(np.count_nonzero((f >= 0) & (pos > f)))
