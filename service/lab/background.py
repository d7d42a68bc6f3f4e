"""The one background runner: the life cycle of every job that holds the rig in a thread.

Campaigns (:class:`~service.lab.runner.CampaignRunner`) and calibration jobs
(:class:`~service.lab.calibration_jobs.CalibrationJobs`) are kinds of one thing: a unit of work
that claims the rig (:class:`~service.lab.rig_lease.RigLease`), runs in a daemon thread, can be
asked to stop before its next step, is stopped by the emergency stop and by the service's end,
and records a final state. :class:`BackgroundRunner` owns that life cycle; a kind
(:class:`Kind`) says only what differs: its name, the state each stop leads to, how a worker's
exception reads, and how the final state is recorded. The domain classes keep their units of
work, their rows and their files.

One runner serves every kind, one run at a time, as the rig has one holder at a time: the run
claims the rig when it starts and gives it back when its thread ends, in one critical section
with the final state (whoever sees that state sees the rig free, and nothing else starts in
between). The emergency stop and the service's shutdown stop whatever runs.

A run's life (``stop`` takes effect at the worker's next check of ``run.stop``)::

    start --prepare (the kind's row; 409/404 raised here, rig given back)--> thread running
    thread running --work returns (state, error)--------------------------> finish(state)
    thread running --work raises------------------> failed(exc) -> (state, error) -> finish
    thread running --stop(to) / emergency stop / shutdown--> work sees run.stop -> finish(to)

The kinds of today::

    campaign:         created --start--> running --(all done)--> completed
                      running --pause / device fault / emergency stop--> paused
                      running --cancel--> cancelled       running --(worker exception)--> failed
                      running --(service shut down)--> interrupted
                      paused | interrupted | failed --resume--> running
    calibration job:  queued --> running --> done | failed | cancelled
                      running --cancel / emergency stop--> cancelled
                      running --(service shut down, or a crash found at the next start)--> failed
                      (its partial output removed; a job cannot be resumed)
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

from service.errors import ConflictError
from service.lab.rig_lease import RigLease

_log = logging.getLogger(__name__)

#: what a kind's worker keeps for :meth:`BackgroundRunner.live` (its progress)
P = TypeVar("P")
#: how a run ends: its final state and error (None when there is none)
Ending = tuple[str, str | None]


class Stopped(Exception):  # noqa: N818 - a stop asked for, not an error
    """A worker saw its stop (:meth:`Run.raise_if_stopped`); it ends in :attr:`Run.stopping`."""


@dataclass(frozen=True)
class Stop:
    """Where a stop leads: the state to record and its error (None: no error)."""

    to: str
    error: str | None = None


@dataclass
class Run(Generic[P]):
    """The record of the job being run: who it is, its thread, how to stop it, its progress."""

    id: str
    kind: Kind[P]
    #: what the worker knows and the status shows while it runs (the kind's own object)
    progress: P
    thread: threading.Thread | None = None
    stop: threading.Event = field(default_factory=threading.Event)
    #: the state the worker ends in once it sees ``stop`` (set with it), and its error
    stop_to: str = "cancelled"
    stop_error: str | None = None
    started: float = field(default_factory=time.monotonic)

    @property
    def stopping(self) -> Ending:
        """The state (and error) a stop asked for."""
        return self.stop_to, self.stop_error

    def raise_if_stopped(self) -> None:
        """Raise :class:`Stopped` once a stop was asked for: what a worker's progress calls
        between its steps (an acquisition's captures, a fit's stages)."""
        if self.stop.is_set():
            raise Stopped(self.id)

    def request_stop(self, stop: Stop, override: bool = False) -> None:
        """Ask the worker to stop into ``stop``; a stop already asked for stands unless
        ``override``."""
        if override or not self.stop.is_set():
            self.stop_to, self.stop_error = stop.to, stop.error
            self.stop.set()


def failed(run: Run[Any], exc: Exception) -> Ending:
    """A worker's exception by default: logged with its traceback, ``failed`` with its
    message."""
    _log.exception("%s %s failed", run.kind.name, run.id)
    return "failed", f"{type(exc).__name__}: {exc}"


@dataclass(frozen=True)
class Kind(Generic[P]):
    """What one kind of job (campaign, calibration job, ...) tells the runner.

    ``finish`` records the final state; it runs in the runner's critical section, after the
    run has left the runner and given the rig back. ``abandoned`` (optional) records a final
    state at shutdown for a worker still busy after ``stop_wait_s`` (a daemon thread whose
    late writes the kind must refuse); without it the row is left for the next start's
    recovery.
    """

    #: the rig lease's name of the holder (``"campaign"``, ``"calibration job"``)
    name: str
    #: the 409 while a job of this kind runs; ``{id}`` is the running one's id
    busy: str
    emergency: Stop
    shutdown: Stop
    live: Callable[[Run[P]], dict[str, Any]]
    finish: Callable[[Run[P], str, str | None], None]
    failed: Callable[[Run[P], Exception], Ending] = failed
    abandoned: Callable[[Run[P]], None] | None = None
    #: the shutdown's stop replaces one already asked for (a cancel becomes ``shutdown``)
    shutdown_overrides: bool = False
    #: the worker thread's name: ``<thread>-<first 8 characters of the id>``
    thread: str = "job"


class BackgroundRunner:
    """Runs one job at a time, of any kind, in a daemon thread holding the rig.

    Parameters
    ----------
    lease : RigLease
        The rig: a run claims it as its kind's holder when it starts.
    stop_wait_s : float
        How long :meth:`stop` and :meth:`shutdown` wait for the worker to end.
    """

    def __init__(self, lease: RigLease, stop_wait_s: float) -> None:
        self.lease = lease
        self.stop_wait_s = stop_wait_s
        # Re-entrant: stop() looks its run up (find) while holding it. find() takes it too, so
        # a reader that no longer finds the run reads a final state already written.
        self._lock = threading.RLock()
        self._run: Run[Any] | None = None

    # -- queries --------------------------------------------------------------------------------
    def find(self, kind: Kind[P], run_id: str) -> Run[P] | None:
        """The run of ``run_id`` if it is the one running, else None.

        None only once the run's final state is written (:meth:`_main` clears the run and
        records the state in one critical section, which this waits for): a status read after
        this call that finds no run reads the final state, never a stale ``running``.
        """
        with self._lock:
            run = self._run
        if run is None or run.kind.name != kind.name or run.id != run_id:
            return None
        return run

    def live(self, kind: Kind[P], run_id: str) -> dict[str, Any] | None:
        """What only the running job knows (its kind's :attr:`Kind.live`), None for any other
        job."""
        run = self.find(kind, run_id)
        return None if run is None else kind.live(run)

    def wait(self, timeout_s: float | None = None, kind: Kind[Any] | None = None) -> None:
        """Block until the running job's thread ends (of ``kind`` only, if given)."""
        run = self._run
        if run is None or run.thread is None or (kind is not None and run.kind.name != kind.name):
            return
        run.thread.join(timeout_s)

    # -- commands -------------------------------------------------------------------------------
    def start(self, kind: Kind[P], run_id: str, work: Callable[[Run[P]], Ending],
              progress: P, prepare: Callable[[], None] | None = None) -> Run[P]:
        """Claim the rig for ``run_id``, ``prepare`` (store the row or its transition: it may
        raise, and then the rig is given back), and run ``work(run)`` in a thread.

        409 with the kind's :attr:`Kind.busy` while a job of the same kind runs, and the
        lease's message while a job of another kind holds the rig.
        """
        with self._lock:
            if self._run is not None and self._run.kind.name == kind.name:
                raise ConflictError(kind.busy.format(id=self._run.id))
            self.lease.claim(run_id, kind.name)
            try:
                if prepare is not None:
                    prepare()
            except BaseException:
                self.lease.release(run_id)
                raise
            run = Run(run_id, kind, progress)
            run.thread = threading.Thread(target=self._main, args=(run, work),
                                          name=f"{kind.thread}-{run_id[:8]}", daemon=True)
            self._run = run
            run.thread.start()
        return run

    def stop(self, kind: Kind[Any], run_id: str, stop: Stop) -> bool:
        """Ask ``run_id`` to stop into ``stop`` before its next step and wait up to
        ``stop_wait_s`` for it (not from its own thread). False if it is not running."""
        with self._lock:
            run = self.find(kind, run_id)
            if run is None:
                return False
            run.request_stop(stop)
            thread = run.thread
        self._join(thread)
        return True

    def emergency_stop(self) -> tuple[str, str] | None:
        """Stop whatever runs into its kind's :attr:`Kind.emergency`, without waiting; returns
        its (kind's name, id), or None when nothing runs."""
        with self._lock:
            run = self._run
            if run is None:
                return None
            run.request_stop(run.kind.emergency)
        return run.kind.name, run.id

    def shutdown(self) -> None:
        """The service's end: stop whatever runs into its kind's :attr:`Kind.shutdown` and wait
        up to ``stop_wait_s``; a worker still busy then is the kind's :attr:`Kind.abandoned`."""
        with self._lock:
            run = self._run
            if run is None:
                return
            run.request_stop(run.kind.shutdown, override=run.kind.shutdown_overrides)
            thread = run.thread
        self._join(thread)
        if run.kind.abandoned is not None and thread is not None and thread.is_alive():
            run.kind.abandoned(run)

    # -- the worker thread ----------------------------------------------------------------------
    def _join(self, thread: threading.Thread | None) -> None:
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=self.stop_wait_s)

    def _main(self, run: Run[Any], work: Callable[[Run[Any]], Ending]) -> None:
        to, error = "failed", "the job ended without a result"
        try:
            to, error = work(run)
        except Exception as exc:  # a bug or a broken part: recorded, never a lost thread
            to, error = run.kind.failed(run, exc)
        finally:
            # One critical section with start(): whoever sees the final state also sees the rig
            # free, and the next job cannot start before it is written.
            with self._lock:
                self._run = None
                self.lease.release(run.id)
                run.kind.finish(run, to, error)
