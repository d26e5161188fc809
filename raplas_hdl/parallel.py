"""Run a compiled loop over index ranges on the cores, with results independent of the
thread count.

The compiled kernels of the models and the engine take a half-open range ``lo, hi`` of
their independent items (pairs, plane tests, runs) and release the GIL (``nogil=True``).
:func:`run_chunks` splits ``0 .. n`` into contiguous ranges and runs them on a thread pool
of numba's thread count (:func:`numba.get_num_threads`, which :func:`numba.set_num_threads`
and ``NUMBA_NUM_THREADS`` set). Each item writes only its own outputs, so the results are
the same bits whatever the number of threads; counters are summed by the caller per item
or per range in index order.
"""

from __future__ import annotations

import itertools
import os
from concurrent.futures import ThreadPoolExecutor

from numba import get_num_threads

__all__ = ["run_chunks", "thread_count"]

_POOL = [None, None, 0]      # executor, pid, workers (rebuilt after a fork)


def thread_count() -> int:
    """Threads the kernels use now (numba's setting)."""
    return max(1, int(get_num_threads()))


def _pool(workers: int) -> ThreadPoolExecutor:
    ex, pid, size = _POOL
    if ex is None or pid != os.getpid() or size < workers:
        ex = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="raplas-kernel")
        _POOL[:] = [ex, os.getpid(), workers]
    return ex


def run_chunks(n: int, fn, min_chunk: int = 4096, weights=None):
    """Call ``fn(lo, hi)`` over contiguous ranges covering ``0 .. n``.

    Parameters
    ----------
    n : int
        Number of items.
    fn : callable
        ``fn(lo, hi)``: runs items ``lo .. hi-1`` (a nogil compiled kernel); its return
        values are returned in range order.
    min_chunk : int
        Fewer items than twice this run in the calling thread as one range.
    weights : array_like, optional
        Cumulative cost of the items (length ``n + 1``, non-decreasing), to balance the
        ranges by cost instead of by count.

    Returns
    -------
    list
        ``fn``'s results, in range order.
    """
    threads = thread_count()
    if n <= 0:
        return []
    if threads <= 1 or n < 2 * min_chunk:
        return [fn(0, n)]
    parts = min(4 * threads, max(1, n // min_chunk))
    if weights is not None:
        import numpy as np

        w = np.asarray(weights, dtype=np.float64)
        targets = w[-1] * np.arange(1, parts) / parts
        cuts = np.searchsorted(w, targets).tolist()
    else:
        cuts = [n * k // parts for k in range(1, parts)]
    bounds = sorted({0, *[min(max(c, 0), n) for c in cuts], n})
    futs = [_pool(threads).submit(fn, lo, hi) for lo, hi in itertools.pairwise(bounds)
            if hi > lo]
    return [f.result() for f in futs]
