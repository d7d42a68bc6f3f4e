"""The one background runner (:mod:`service.lab.background`) on its own: a job kind made here
(its work a loop that watches the stop), a real rig lease without a rig. Start and the rig's
claim, stop into the asked state, a worker's exception ``failed`` with its message, shutdown
that joins (or records a worker it gave up on), the emergency stop of whatever runs, and one
job at a time of either kind."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any

import pytest

from service.errors import ConflictError
from service.lab.background import BackgroundRunner, Ending, Kind, Run, Stop
from service.lab.rig_lease import RigLease

pytestmark = pytest.mark.timeout(30)


@dataclass
class Steps:
    """A test job's progress: the steps done, and a gate the work waits on to end."""

    done: int = 0
    go: threading.Event = field(default_factory=threading.Event)


@dataclass
class Book:
    """What a test kind records: each final state (as ``finish`` got it), abandoned runs."""

    finished: list[tuple[str, str, str | None]] = field(default_factory=list)
    abandoned: list[str] = field(default_factory=list)
    rig_free_at_finish: list[bool] = field(default_factory=list)


def make_kind(name: str, book: Book, lease: RigLease, **overrides: Any) -> Kind[Steps]:
    def finish(run: Run[Steps], to: str, error: str | None) -> None:
        book.rig_free_at_finish.append(lease.campaign_id is None and lease.calibration_id is None)
        book.finished.append((run.id, to, error))

    values: dict[str, Any] = {
        "name": name, "busy": name + " {id} is running; one at a time",
        "emergency": Stop("paused", "emergency stop"),
        "shutdown": Stop("interrupted", "the service was shut down"),
        "live": lambda run: {"done": run.progress.done},
        "finish": finish, "abandoned": lambda run: book.abandoned.append(run.id),
        "thread": name.split()[0], **overrides}
    return Kind(**values)


def until_stopped(run: Run[Steps]) -> Ending:
    """Steps until asked to stop (or let go), then the state the stop asked for."""
    while not run.stop.wait(0.01):
        run.progress.done += 1
        if run.progress.go.is_set():
            return "completed", None
    return run.stopping


@pytest.fixture
def lease() -> RigLease:
    return RigLease(None, "no rig in this test", wait_s=0.1)


@pytest.fixture
def runner(lease: RigLease) -> BackgroundRunner:
    return BackgroundRunner(lease, stop_wait_s=5.0)


def test_a_started_job_holds_the_rig_shows_its_progress_and_ends_with_its_state(runner, lease):
    book = Book()
    kind = make_kind("campaign", book, lease)
    run = runner.start(kind, "a1", until_stopped, Steps())
    assert lease.campaign_id == "a1" and runner.find(kind, "a1") is run
    assert run.thread is not None and run.thread.name == "campaign-a1"
    while run.progress.done < 2:
        run.thread.join(0.01)
    assert runner.live(kind, "a1")["done"] >= 2
    assert runner.live(kind, "other") is None
    run.progress.go.set()
    runner.wait(5.0)
    assert book.finished == [("a1", "completed", None)]
    assert book.rig_free_at_finish == [True]  # given back before the final state is written
    assert lease.campaign_id is None and runner.live(kind, "a1") is None


def test_stop_ends_the_job_in_the_state_asked_for_and_only_the_running_one(runner, lease):
    book = Book()
    kind = make_kind("campaign", book, lease)
    other = make_kind("calibration job", Book(), lease)
    runner.start(kind, "a1", until_stopped, Steps())
    assert runner.stop(kind, "b2", Stop("paused")) is False
    assert runner.stop(other, "a1", Stop("cancelled")) is False  # the id, but another kind
    assert runner.stop(kind, "a1", Stop("cancelled", "by the test")) is True  # waits
    assert book.finished == [("a1", "cancelled", "by the test")]
    assert runner.find(kind, "a1") is None and lease.campaign_id is None
    assert runner.stop(kind, "a1", Stop("paused")) is False  # nothing runs


def test_a_worker_exception_is_failed_with_its_message_and_the_rig_given_back(runner, lease):
    book = Book()
    kind = make_kind("calibration job", book, lease)

    def broken(run: Run[Steps]) -> Ending:
        raise ValueError("the fixture is upside down")

    runner.start(kind, "c3", broken, Steps())
    runner.wait(5.0)
    assert book.finished == [("c3", "failed", "ValueError: the fixture is upside down")]
    assert lease.calibration_id is None
    # the next job starts
    runner.start(kind, "c4", until_stopped, Steps())
    assert runner.stop(kind, "c4", Stop("cancelled"))


def test_a_kind_reads_its_workers_exceptions_its_own_way(runner, lease):
    book = Book()
    kind = make_kind("campaign", book, lease,
                     failed=lambda run, exc: ("paused", f"fix it: {exc}"))

    def full(run: Run[Steps]) -> Ending:
        raise OSError("no space left")

    runner.start(kind, "a1", full, Steps())
    runner.wait(5.0)
    assert book.finished == [("a1", "paused", "fix it: no space left")]


def test_shutdown_stops_the_job_into_its_kinds_state_and_joins_it(runner, lease):
    book = Book()
    kind = make_kind("campaign", book, lease)
    run = runner.start(kind, "a1", until_stopped, Steps())
    runner.shutdown()
    assert run.thread is not None and not run.thread.is_alive()
    assert book.finished == [("a1", "interrupted", "the service was shut down")]
    assert book.abandoned == [] and lease.campaign_id is None
    runner.shutdown()  # nothing runs: a no-op


def test_an_earlier_stop_stands_at_shutdown_unless_the_kind_overrides_it(lease):
    for overrides, expected in ((False, ("paused", "emergency stop")),
                                (True, ("interrupted", "the service was shut down"))):
        runner = BackgroundRunner(lease, stop_wait_s=5.0)
        book = Book()
        kind = make_kind("calibration job", book, lease, shutdown_overrides=overrides)
        gate = threading.Event()

        def slow_to_stop(run: Run[Steps], gate: threading.Event = gate) -> Ending:
            run.stop.wait()
            gate.wait()  # the stop is seen, the worker not yet done
            return run.stopping

        run = runner.start(kind, "j1", slow_to_stop, Steps())
        assert runner.emergency_stop() == ("calibration job", "j1")
        run.stop.wait()
        threading.Timer(0.2, gate.set).start()
        runner.shutdown()
        assert book.finished == [("j1", *expected)], overrides


def test_shutdown_records_a_worker_still_busy_as_abandoned(lease):
    runner = BackgroundRunner(lease, stop_wait_s=0.1)
    book = Book()
    kind = make_kind("calibration job", book, lease)
    steps = Steps()

    def deaf(run: Run[Steps]) -> Ending:  # does not look at the stop
        steps.go.wait()
        return run.stopping

    run = runner.start(kind, "j1", deaf, steps)
    runner.shutdown()
    assert book.abandoned == ["j1"] and book.finished == []
    steps.go.set()
    assert run.thread is not None
    run.thread.join(5.0)
    assert book.finished == [("j1", "interrupted", "the service was shut down")]


def test_the_emergency_stop_stops_whatever_runs_and_names_it(runner, lease):
    assert runner.emergency_stop() is None
    for name, job_id in (("campaign", "a1"), ("calibration job", "j2")):
        book = Book()
        kind = make_kind(name, book, lease, emergency=Stop("stopped", "emergency stop"))
        run = runner.start(kind, job_id, until_stopped, Steps())
        assert runner.emergency_stop() == (name, job_id)
        assert run.thread is not None
        run.thread.join(5.0)
        assert book.finished == [(job_id, "stopped", "emergency stop")]
        assert lease.campaign_id is None and lease.calibration_id is None


def test_one_job_at_a_time_of_either_kind(runner, lease):
    campaigns = make_kind("campaign", Book(), lease)
    jobs = make_kind("calibration job", Book(), lease)
    runner.start(campaigns, "a1", until_stopped, Steps())
    with pytest.raises(ConflictError, match=r"^campaign a1 is running; one at a time$"):
        runner.start(campaigns, "a2", until_stopped, Steps())
    with pytest.raises(ConflictError, match="campaign a1 is running and holds the rig"):
        runner.start(jobs, "j1", until_stopped, Steps())
    assert runner.find(campaigns, "a1") is not None and lease.campaign_id == "a1"
    assert runner.stop(campaigns, "a1", Stop("paused"))


def test_a_refused_start_gives_the_rig_back_and_runs_nothing(runner, lease):
    kind = make_kind("campaign", Book(), lease)

    def refuse() -> None:
        raise ConflictError("cannot start campaign a1 in state 'completed'")

    with pytest.raises(ConflictError, match="state 'completed'"):
        runner.start(kind, "a1", until_stopped, Steps(), prepare=refuse)
    assert lease.campaign_id is None and runner.find(kind, "a1") is None
    assert runner.emergency_stop() is None


def test_a_run_is_not_found_gone_before_its_final_state_is_written(runner, lease):
    """A status read (``live``, then the row) never sees the run gone and the row still
    ``running``: ``find`` waits for the critical section that clears the run and writes the
    final state (a campaign's status once read a stale ``running`` there and failed)."""
    book = Book()
    writing, release = threading.Event(), threading.Event()

    def slow_finish(run: Run[Steps], to: str, error: str | None) -> None:
        writing.set()
        release.wait(5.0)  # the final row is being written
        book.finished.append((run.id, to, error))

    kind = make_kind("campaign", book, lease, finish=slow_finish)
    steps = Steps()
    steps.go.set()
    runner.start(kind, "a1", until_stopped, steps)
    assert writing.wait(5.0)
    seen: list[Any] = []
    reader = threading.Thread(target=lambda: seen.append(
        (runner.live(kind, "a1"), list(book.finished))))
    reader.start()
    reader.join(0.3)
    assert reader.is_alive(), "the run read as gone while its final state was being written"
    release.set()
    reader.join(5.0)
    assert seen == [(None, [("a1", "completed", None)])]
