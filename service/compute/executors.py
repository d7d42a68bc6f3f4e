"""Where simulation jobs run: one small interface, three implementations.

- :class:`LocalExecutor` (the default): a pool of worker processes on this machine, started with
  ``spawn`` (the service process has device threads that must not be forked), each limited to
  ``threads`` Embree/numba threads so that the workers share the cores instead of fighting.
- :class:`ThreadExecutor`: the same in threads of the service process (tests, debugging).
- :class:`DaskExecutor`: ``dask://HOST:PORT``, an existing Dask scheduler; the job carries the
  scene and its meshes, the frame comes back as arrays. Workers need ``toftwin`` installed at
  the same version. Dask's ``distributed`` is not a dependency: it comes with the ``dask`` extra
  (``pip install -e ".[dask]"``), and is imported only here.

``submit`` returns a future with ``result(timeout)``; the caller never blocks the event loop on it
(the service waits in worker threads).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Protocol

from service.compute.jobs import SimulationJob, run_job, warm_up
from service.settings import DASK_MISSING


class JobFuture(Protocol):
    """What ``submit`` returns (a ``concurrent.futures.Future`` or a Dask future)."""

    def result(self, timeout: float | None = None) -> Any: ...

    def done(self) -> bool: ...


class Executor(Protocol):
    """Runs :class:`SimulationJob` s somewhere."""

    name: str

    @property
    def workers(self) -> int:
        """How many jobs may run at once."""
        ...

    def submit(self, job: SimulationJob) -> JobFuture:
        """Start ``job``; the future's result is a ``SimulatedFrame``."""
        ...

    def warm_up(self, wait: bool = False) -> None:
        """Load the renderer on every worker (in the background unless ``wait``)."""
        ...

    def close(self) -> None:
        """Stop accepting jobs and release the workers."""
        ...


def _init_worker(threads: int, parent_pid: int) -> None:
    """Set up a pool process: ``threads`` numba threads (before numba is imported), and exit
    when the service process dies.

    A service killed with SIGKILL cannot shut its pool down; without this its workers (a
    renderer each, ~200 MB) would live on, reparented, and pile up across crashes. Linux is
    asked to kill the worker with its parent (``PR_SET_PDEATHSIG``); everywhere a daemon thread
    also checks every second that the parent is still the one that started the worker.
    """
    os.environ["NUMBA_NUM_THREADS"] = str(threads)
    _die_with_parent(parent_pid)


def _die_with_parent(parent_pid: int, poll_s: float = 1.0) -> None:
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(poll_s)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


#: prctl option: the signal this process gets when its parent dies (linux/prctl.h)
_PR_SET_PDEATHSIG = 1


class LocalExecutor:
    """A pool of ``workers`` processes on this machine."""

    name = "local"

    def __init__(self, workers: int = 1, threads: int = 1) -> None:
        self._workers = workers
        self._threads = threads
        self._pool = self._new_pool()

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        return cf.ProcessPoolExecutor(
            max_workers=self._workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker,
            initargs=(self._threads, os.getpid()),
        )

    @property
    def workers(self) -> int:
        return self._workers

    def submit(self, job: SimulationJob) -> cf.Future:
        try:
            return self._pool.submit(run_job, job)
        except BrokenProcessPool:
            # a worker died (killed, out of memory): the jobs it had failed with the same
            # error; later jobs get a fresh pool instead of failing forever
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = self._new_pool()
            return self._pool.submit(run_job, job)

    def warm_up(self, wait: bool = False) -> None:
        futures = [self._pool.submit(warm_up) for _ in range(self._workers)]
        if wait:
            cf.wait(futures)

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)


class ThreadExecutor:
    """Jobs in threads of this process (no isolation; for tests and debugging)."""

    name = "thread"

    def __init__(self, workers: int = 1) -> None:
        self._workers = workers
        self._pool = cf.ThreadPoolExecutor(max_workers=workers, thread_name_prefix="sim-job")

    @property
    def workers(self) -> int:
        return self._workers

    def submit(self, job: SimulationJob) -> cf.Future:
        return self._pool.submit(run_job, job)

    def warm_up(self, wait: bool = False) -> None:
        future = self._pool.submit(warm_up)
        if wait:
            future.result()

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)


class DaskExecutor:
    """Jobs on an existing Dask cluster, through its scheduler at ``address``."""

    name = "dask"

    def __init__(self, address: str, timeout_s: float = 10.0) -> None:
        try:
            from distributed import Client
        except ImportError as exc:
            raise ImportError(f"{DASK_MISSING} ({exc})") from exc

        self.address = address
        self._client = Client(address, timeout=timeout_s, set_as_default=False)

    @property
    def workers(self) -> int:
        n = len(self._client.scheduler_info().get("workers", {}))
        return max(1, n)

    def submit(self, job: SimulationJob) -> JobFuture:
        # pure=False: two identical jobs are two frames (a repeat), not one cached result
        return self._client.submit(run_job, job, pure=False)

    def warm_up(self, wait: bool = False) -> None:
        workers = list(self._client.scheduler_info().get("workers", {}))
        # kept referenced: a released future's task may be cancelled
        self._warm = [self._client.submit(warm_up, pure=False, workers=[w],
                                          allow_other_workers=False) for w in workers]
        if wait:
            self._client.gather(self._warm)

    def close(self) -> None:
        self._client.close()


def make_executor(
    kind: str, workers: int = 1, threads: int = 1, dask_address: str | None = None
) -> Executor:
    """The executor for a settings value (``local``, ``thread`` or ``dask://...``)."""
    if dask_address is not None:
        return DaskExecutor(dask_address)
    if kind == "thread":
        return ThreadExecutor(workers)
    return LocalExecutor(workers, threads)
