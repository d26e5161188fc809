"""Where the shards of a campaign or a bench run: one small interface over three executors.

``serial``
    In this process, one shard after the other (``--jobs 1``).
``pool``
    A local :class:`concurrent.futures.ProcessPoolExecutor` (``spawn`` start method, the
    default of ``stress campaign``).
``dask``
    Dask distributed (``pip install 'raplas-hdl[cluster]'``): an existing cluster given by
    its scheduler's address (``--scheduler tcp://host:8786``) or a ``LocalCluster`` of N
    worker processes started here (``--dask-workers N``; one thread per worker, no
    dashboard, on the loopback interface).

Every executor runs a module-level function on picklable items and yields ``(item,
result)`` pairs as they finish (:meth:`Executor.run`). The caller writes what comes back:
results travel to the client, so the workers of a cluster need no file system in common
with it. Each task starts with :func:`worker_init` (numba's threads set to 1), in every
executor, so that a shard computes the same bits wherever it runs.

A Dask cluster's workers must run the same versions as the client: on connecting, each
worker reports the versions of raplas-hdl, numpy, numba and llvmlite (:func:`versions`,
or what the caller's ``worker_versions`` adds to them, as the stress campaign adds its
shard format, :func:`raplas_hdl.verify.campaign.worker_versions`); any difference, or a
worker that cannot import raplas_hdl, is an error before any shard runs.

Nothing here imports Amaranth.
"""

from __future__ import annotations

import argparse
import logging
import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator

__all__ = ["INSTALL_HINT", "DaskUnavailable", "Executor", "SerialExecutor", "PoolExecutor",
           "DaskExecutor", "have_dask", "require_dask", "make_executor", "versions",
           "worker_init", "add_options", "check_options", "executor_from_args",
           "command_options"]

#: How to install what the Dask executor needs.
INSTALL_HINT = "pip install 'raplas-hdl[cluster]'"
#: Seconds to wait for a scheduler to answer, and for its first worker.
CONNECT_TIMEOUT = 20


class DaskUnavailable(ValueError):
    """Dask distributed is not installed (the ``cluster`` extra)."""


def have_dask() -> bool:
    """Is Dask distributed importable?"""
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def require_dask(option: str = "the Dask executor") -> None:
    """Raise :class:`DaskUnavailable` (one line, how to install it) when Dask is missing."""
    if not have_dask():
        raise DaskUnavailable(f"{option} needs Dask distributed, which is not installed: "
                              f"{INSTALL_HINT}")


def worker_init() -> None:
    """Run before every task: one numba thread per worker process, as the process pool's
    workers (numba's setting is per thread, so it is set in the thread that runs the task).
    Results do not depend on it; the timings of a shard then mean one core."""
    try:
        import numba
        numba.set_num_threads(1)
    except Exception:       # noqa: BLE001 - a missing numba only costs threads
        pass


def _call(fn, item):
    worker_init()
    return fn(item)


def versions() -> dict:
    """The package versions a worker must share with the client for bit-identical shards."""
    import importlib.metadata as md

    out = {}
    for pkg in ("raplas-hdl", "numpy", "numba", "llvmlite"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = None
    return out


class Executor:
    """Runs ``fn(item)`` for every item; subclasses say where.

    Attributes
    ----------
    kind : str
        ``serial``, ``pool`` or ``dask``.
    workers : int
        Tasks that run at once (for a Dask cluster: its workers' threads when it connected).
    local : bool
        The workers share this machine's numba cache (the caller compiles once first).
    """

    kind = "serial"
    local = True

    def __init__(self):
        self.workers = 1

    def run(self, fn: Callable, items: Iterable) -> Iterator[tuple]:
        """Yield ``(item, fn(item))`` as the tasks finish (in no set order). An exception of
        a task is raised here, after the tasks not yet started are cancelled."""
        raise NotImplementedError

    def describe(self) -> str:
        return "this process"

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class SerialExecutor(Executor):
    """In this process, in order."""

    def run(self, fn, items):
        for item in items:
            yield item, _call(fn, item)


class PoolExecutor(Executor):
    """A local process pool of ``jobs`` workers (``spawn``: a fork after numba has started
    its thread pool gives children that crash)."""

    kind = "pool"

    def __init__(self, jobs: int):
        super().__init__()
        if jobs < 1:
            raise ValueError(f"jobs must be at least 1, not {jobs}")
        self.workers = int(jobs)
        self._pool = None

    def describe(self) -> str:
        return f"process pool of {self.workers}"

    def run(self, fn, items):
        from concurrent.futures import ProcessPoolExecutor, as_completed

        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers,
                                             mp_context=multiprocessing.get_context("spawn"))
        futures = {self._pool.submit(_call, fn, item): item for item in items}
        try:
            for fut in as_completed(futures):
                yield futures[fut], fut.result()
        except BaseException:
            for f in futures:
                f.cancel()
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
            raise

    def close(self):
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


class DaskExecutor(Executor):
    """Dask distributed: ``scheduler`` (an address) or ``n_workers`` (a ``LocalCluster`` of
    that many single-threaded worker processes). Connects on first use.

    ``processes=True`` for the local cluster: every worker is a process of its own, as in the
    pool (numba's default threading layer is not safe for kernels launched from several
    threads of one process, and the shards' Python parts would share one GIL).
    """

    kind = "dask"

    def __init__(self, scheduler: str | None = None, n_workers: int | None = None,
                 timeout: float = CONNECT_TIMEOUT,
                 worker_versions: Callable[[], dict] = versions):
        super().__init__()
        self.worker_versions = worker_versions
        require_dask("--scheduler" if scheduler else "--dask-workers")
        if (scheduler is None) == (n_workers is None):
            raise ValueError("give either a scheduler address or a number of workers")
        if n_workers is not None and n_workers < 1:
            raise ValueError(f"the number of Dask workers must be at least 1, not {n_workers}")
        self.scheduler, self.n_workers, self.timeout = scheduler, n_workers, timeout
        self.local = scheduler is None
        self.workers = n_workers or 1
        self.client = self._cluster = None

    def describe(self) -> str:
        if self.scheduler:
            return f"Dask cluster at {self.scheduler} ({self.workers} worker threads)"
        return f"Dask LocalCluster of {self.n_workers} worker processes"

    def connect(self):
        """Start (or reach) the cluster and check the workers' versions; returns the
        client."""
        if self.client is not None:
            return self.client
        from distributed import Client, LocalCluster

        if self.scheduler is None:
            self._cluster = LocalCluster(n_workers=self.n_workers, threads_per_worker=1,
                                         processes=True, host="127.0.0.1",
                                         # no dashboard; the scheduler's HTTP routes on a
                                         # free port (not 8787, which may be taken)
                                         dashboard_address=":0",
                                         scheduler_kwargs={"dashboard": False},
                                         silence_logs=logging.WARNING)
            self.client = Client(self._cluster)
        else:
            try:
                self.client = Client(self.scheduler, timeout=self.timeout)
            except (OSError, TimeoutError) as exc:
                raise ValueError(f"cannot reach the Dask scheduler at {self.scheduler!r} "
                                 f"within {self.timeout:g} s ({type(exc).__name__})") from None
            try:
                self.client.wait_for_workers(1, timeout=self.timeout)
            except (OSError, TimeoutError):
                self.close()
                raise ValueError(f"the Dask scheduler at {self.scheduler!r} has no worker "
                                 f"after {self.timeout:g} s") from None
        try:
            self._check_versions()
        except BaseException:
            self.close()
            raise
        self.workers = max(1, sum(self.client.nthreads().values()))
        return self.client

    def _check_versions(self, mine: dict | None = None):
        """Every worker reports ``worker_versions()`` equal to ``mine`` (default this
        process's)."""
        mine = self.worker_versions() if mine is None else mine
        try:
            theirs = self.client.run(self.worker_versions)
        except (ImportError, ModuleNotFoundError) as exc:
            raise ValueError(f"a Dask worker cannot import raplas_hdl ({exc}): install the "
                             f"same raplas-hdl on every worker") from None
        for worker, v in sorted(theirs.items()):
            diff = [f"{k} {v.get(k)} (here {mine[k]})" for k in mine if v.get(k) != mine[k]]
            if diff:
                raise ValueError(f"Dask worker {worker} runs other versions: "
                                 f"{', '.join(diff)}; every worker needs the client's")

    def run(self, fn, items):
        from distributed import as_completed

        items = list(items)
        if not items:           # nothing to run: no cluster to start
            return
        client = self.connect()
        futures = {}
        for item in items:
            futures[client.submit(_call, fn, item, pure=False)] = item
        try:
            for fut, result in as_completed(futures, with_results=True):
                yield futures[fut], result
        except BaseException:
            client.cancel(list(futures))
            raise

    def close(self):
        if self.client is not None:
            self.client.close()
            self.client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None


def make_executor(jobs: int | None = None, scheduler: str | None = None,
                  dask_workers: int | None = None,
                  worker_versions: Callable[[], dict] = versions) -> Executor:
    """The executor asked for: Dask when ``scheduler`` or ``dask_workers`` is given (its
    workers checked with ``worker_versions``, a module-level function), else a process pool
    of ``jobs`` (default ``os.cpu_count()``), or this process when 1."""
    if scheduler is not None or dask_workers is not None:
        if jobs is not None:
            raise ValueError("jobs applies to the process pool, not to a Dask cluster")
        return DaskExecutor(scheduler, dask_workers, worker_versions=worker_versions)
    jobs = (os.cpu_count() or 1) if jobs is None else int(jobs)
    if jobs < 1:
        raise ValueError(f"jobs must be at least 1, not {jobs}")
    return SerialExecutor() if jobs == 1 else PoolExecutor(jobs)


# -- the command-line options of the commands that shard -----------------------------------

#: Upper bound of --dask-workers.
MAX_DASK_WORKERS = 1024


def _workers_type(text):
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--dask-workers: {text!r} is not an integer") \
            from None
    if not 1 <= n <= MAX_DASK_WORKERS:
        raise argparse.ArgumentTypeError(f"--dask-workers: {n} is not in 1 to "
                                         f"{MAX_DASK_WORKERS}")
    return n


def add_options(parser, what: str) -> None:
    """``--scheduler ADDRESS`` and ``--dask-workers N`` (Dask distributed; the ``cluster``
    extra) on a command whose ``what`` (e.g. "shards") they run."""
    grp = parser.add_argument_group(
        "Dask cluster", f"run the {what} on Dask distributed instead ({INSTALL_HINT}); "
                        "the results are the same")
    ex = grp.add_mutually_exclusive_group()
    ex.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="address of a running Dask scheduler (tcp://host:8786); its workers "
                         "need the same raplas-hdl, numpy and numba versions")
    ex.add_argument("--dask-workers", type=_workers_type, default=None, metavar="N",
                    help=f"start a local Dask cluster of N worker processes, 1 to "
                         f"{MAX_DASK_WORKERS}, for this run")


def check_options(args, conflicts=()) -> None:
    """Before any work: Dask installed when asked for; a well-formed address; no option of
    ``conflicts`` (argument dests, e.g. ``jobs``) beside the Dask ones."""
    opt = ("--scheduler" if args.scheduler is not None else
           "--dask-workers" if args.dask_workers is not None else None)
    if opt is None:
        return
    for dest in conflicts:
        if getattr(args, dest, None) is not None:
            raise ValueError(f"--{dest.replace('_', '-')} applies to the local process pool, "
                             f"not with {opt}")
    require_dask(opt)
    if args.scheduler is not None:
        from distributed.comm import parse_address

        addr = args.scheduler.strip()
        try:
            _, loc = parse_address(addr)
        except ValueError as exc:
            raise ValueError(f"--scheduler {args.scheduler!r} is not an address "
                             f"(tcp://host:port): {exc}") from None
        if not loc or loc.startswith(":"):
            raise ValueError(f"--scheduler {args.scheduler!r} names no host (tcp://host:port)")
        args.scheduler = addr


def executor_from_args(args, jobs: int | None = None,
                       worker_versions: Callable[[], dict] = versions) -> Executor:
    """The executor the parsed options ask for (:func:`make_executor`)."""
    return make_executor(jobs, args.scheduler, args.dask_workers, worker_versions)


def command_options(args) -> list[str]:
    """The Dask options of a parsed command line, to quote it."""
    if args.scheduler is not None:
        return ["--scheduler", args.scheduler]
    if args.dask_workers is not None:
        return ["--dask-workers", str(args.dask_workers)]
    return []
