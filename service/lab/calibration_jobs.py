"""Calibration jobs: ``toftwin calibrate rig`` as a background job of the service.

``POST /api/v1/calibrations`` validates the plan (:class:`~service.lab.requests.
CalibrationCreate`: fixtures, sweep, frames; the angles against the stage's limits), claims the
rig (:class:`~service.lab.rig_lease.RigLease`: 409 while a campaign or another job holds it; a
campaign, a manual move or ``POST /poses`` is refused with 409 while the job runs), stores the
job (``queued``) and runs :func:`service.lab.acquisition.run_rig_calibration` in one thread::

    queued --> running --> done | failed | cancelled

Progress (steps done of total, what the sequence is doing) is written to the job's row at
every step, so ``GET /calibrations/{id}`` and its event stream follow it. The result is written
as ``DATA_DIR/calibrations/.partial-<id>/`` (``calibration.yaml``, ``report.json``,
``report.html`` and its plots, :func:`calibration.report.write_report`) and renamed to
``DATA_DIR/calibrations/<id>/`` when complete: a job is ``done`` only with all its files. With
``activate`` the result becomes the active calibration at once; else
``POST /calibrations/{id}/activate`` does it later.

A job cannot be resumed: a service stopped or killed while one runs marks it ``failed`` (at
shutdown, or at the next start) with what to do, and removes its partial output. Cancel
(``POST /calibrations/{id}/cancel``) and the emergency stop take effect before the next capture.

Who swaps what is on the turntable: on the simulated lab the lab itself
(:class:`drivers.sim.operator.SimulatedOperator`); on the real rig the operator, whom the
job asks through its status (``operator_instruction``) and who confirms with
``POST /calibrations/{id}/continue`` once the board (or the test object) is mounted.

The life cycle (the thread, the rig's claim, cancel, the emergency stop, shutdown) is the one
background runner's (:class:`~service.lab.background.BackgroundRunner`, shared with the
campaigns); this module holds the job's work, its row and its output folder.
"""

from __future__ import annotations

import logging
import os
import shutil
import threading
import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sqlalchemy.orm import sessionmaker

from calibration.camera_forms import OPENCV_FILE
from drivers.errors import DeviceError
from service.errors import ConflictError, GoneError, NotFoundError
from service.lab.background import BackgroundRunner, Ending, Kind, Run, Stop, Stopped
from service.lab.calibration import activate
from service.lab.poses import check_angle
from service.lab.requests import CalibrationCreate
from service.lab.scenes import SceneSource
from service.settings import Settings
from service.store import queries
from service.store.disk_space import require_free
from sim_core.errors import InvalidInputError
from sim_core.twin_file import load_calibration, twin_hash

_log = logging.getLogger(__name__)

KIND = "calibration job"
#: what a done job wrote, beside the report's plots (``GET /calibrations/{id}/files/{name}``)
OUTPUT_FILES = ("calibration.yaml", "verdicts.json", "report.json", "report.html")
#: files a done job lists where its folder has them: the camera in OpenCV's form (jobs done
#: before it was written have none)
OPTIONAL_FILES = (OPENCV_FILE,)
_PARTIAL = ".partial-"
#: what a job interrupted by the service's end says
INTERRUPTED = ("the service stopped while the calibration ran; a calibration cannot be resumed: "
               "start a new one (POST /api/v1/calibrations)")


@dataclass
class _Progress:
    """What the running job's worker knows beside its row."""

    #: (instruction, message) while the job waits for the operator (real rig): one value, so
    #: that a reader gets the instruction and the message that goes with it together
    waiting: tuple[str, str] | None = None
    mounted: threading.Event = field(default_factory=threading.Event)
    #: the result's hash, and whether it was activated (for the final row)
    calibration_hash: str | None = None
    activated: bool = False


_Run = Run[_Progress]


class _WaitingOperator:
    """The operator at the real rig, asked through the job's status; ``continue`` confirms."""

    def __init__(self, jobs: CalibrationJobs, run: _Run) -> None:
        self.jobs, self.run = jobs, run

    def mount(self, objects: Sequence | None, instruction: str) -> None:
        run, progress = self.run, self.run.progress
        progress.mounted.clear()
        message = (f"waiting for the operator: {instruction}; then POST "
                   f"/api/v1/calibrations/{run.id}/continue")
        self.jobs._note(run.id, message)
        # Set after the row's message, and read with it (:meth:`CalibrationJobs.live`): a
        # status that shows the instruction shows its message too, whenever the row was read.
        progress.waiting = (instruction, message)
        try:
            while not progress.mounted.wait(0.2):
                run.raise_if_stopped()
        finally:
            progress.waiting = None


class CalibrationJobs:
    """Creates, runs, cancels and activates calibration jobs; one at a time.

    Parameters
    ----------
    sessions : sessionmaker
    background : BackgroundRunner
        The one runner of the service's background jobs: a job claims the rig (its ``lease``)
        as ``"calibration job"``, and the runner stops it and records how it ended.
    scene : SceneSource
        The service's scene: camera pose, turntable and solar simulator of the rig.
    settings : Settings
    root : Path
        Where job outputs go (``DATA_DIR/calibrations``).
    world : SimulatedWorld or None
        The simulated lab (mounts the board itself); None on the real rig.
    """

    def __init__(self, sessions: sessionmaker, background: BackgroundRunner, scene: SceneSource,
                 settings: Settings, root: str | Path, world: Any = None) -> None:
        self.sessions = sessions
        self.background = background
        self.lease = background.lease
        self.scene = scene
        self.settings = settings
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.world = world
        self.kind: Kind[_Progress] = Kind(
            name=KIND, busy="calibration job {id} is running; one at a time",
            emergency=Stop("cancelled", "emergency stop"), shutdown=Stop("failed", INTERRUPTED),
            shutdown_overrides=True, live=self._live, finish=self._finished,
            abandoned=self._abandoned, thread="calibration")

    # -- start-up ------------------------------------------------------------------------------
    def recover(self) -> list[str]:
        """At start-up: jobs a stopped service left unfinished become ``failed``; partial outputs
        go. Returns the failed jobs' ids."""
        with self.sessions() as s:
            failed = queries.fail_unfinished_calibration_jobs(s, INTERRUPTED)
        for p in self.root.iterdir():
            if p.name.startswith(_PARTIAL):
                shutil.rmtree(p, ignore_errors=True)
        return failed

    # -- queries -------------------------------------------------------------------------------
    def out_dir(self, job_id: str) -> Path:
        return self.root / job_id

    def live(self, job_id: str) -> dict[str, Any] | None:
        """What only the running job knows: the operator's instruction and its message (both
        None unless it waits for the operator)."""
        return self.background.live(self.kind, job_id)

    def wait(self, timeout_s: float | None = None) -> None:
        """Block until the running job's thread ends (tests)."""
        self.background.wait(timeout_s, self.kind)

    # -- commands ------------------------------------------------------------------------------
    def create(self, req: CalibrationCreate) -> str:
        """Validate ``req``, claim the rig, store the job and start it; returns its id."""
        from calibration.rig_sequence import rig_capture_plan

        plan = req.plan()  # the command line's builder: the same plan for the same inputs
        rig = self.lease.require()
        check_angle(rig, plan.sweep_deg[0], "sweep.from_deg")
        check_angle(rig, plan.sweep_deg[-1], "sweep.to_deg")
        require_free(self.root, self.settings.min_free_bytes)  # 507 before anything moves
        job_id = uuid.uuid4().hex

        def prepare() -> None:  # with the rig claimed: 409 while a campaign holds it
            with self.sessions() as s:
                queries.create_calibration_job(
                    s, job_id=job_id, plan=req.model_dump(mode="json"),
                    activate=req.activate, out_dir=str(self.out_dir(job_id)),
                    steps_total=rig_capture_plan(plan, self.scene.spec).n_captures)

        self.background.start(self.kind, job_id,
                              lambda run: self._work(run, plan, req.activate), _Progress(),
                              prepare)
        return job_id

    def cancel(self, job_id: str) -> None:
        """Stop a queued or running job before its next capture (409 for a finished one)."""
        if self.background.stop(self.kind, job_id, Stop("cancelled")):
            return
        with self.sessions() as s:
            row = queries.require_calibration_job(s, job_id)
        raise ConflictError(f"cannot cancel calibration job {job_id} in state '{row.state}'; "
                            "allowed while queued or running")

    def confirm_mounted(self, job_id: str) -> None:
        """The operator has mounted what the job asked for (409 if it asks for nothing)."""
        run = self.background.find(self.kind, job_id)
        if run is None or run.progress.waiting is None:
            with self.sessions() as s:
                queries.require_calibration_job(s, job_id)
            raise ConflictError(f"calibration job {job_id} is not waiting for the operator")
        run.progress.mounted.set()

    def activate(self, job_id: str) -> dict[str, Any]:
        """Make a ``done`` job's result the active calibration; returns its public form."""
        with self.sessions() as s:
            row = queries.require_calibration_job(s, job_id)
        if row.state != "done":
            raise ConflictError(f"calibration job {job_id} is '{row.state}'; only a 'done' job "
                                "has a calibration to activate")
        cal = load_calibration(_output_file(row, "calibration.yaml"))
        out = activate(self.sessions, cal, f"calibration job {job_id}")
        with self.sessions() as s:
            queries.update_calibration_job(s, job_id, activated=True)
        return out

    # -- the worker thread ---------------------------------------------------------------------
    def _note(self, job_id: str, message: str, done: int | None = None,
              total: int | None = None) -> None:
        values: dict[str, Any] = {"message": message}
        if done is not None:
            values["steps_done"] = done
        if total is not None:
            values["steps_total"] = total
        with self.sessions() as s:
            queries.update_calibration_job(s, job_id, allowed_from=("running",), **values)

    def _live(self, run: _Run) -> dict[str, Any]:
        instruction, message = run.progress.waiting or (None, None)
        return {"operator_instruction": instruction, "message": message}

    def _finished(self, run: _Run, to: str, error: str | None) -> None:
        """The final row (in the runner's critical section, the rig already given back)."""
        with self.sessions() as s:
            queries.update_calibration_job(
                s, run.id, allowed_from=("queued", "running"), state=to, error=error,
                calibration_hash=run.progress.calibration_hash,
                activated=run.progress.activated, finished_at=time.time(),
                message="done" if to == "done" else to)

    def _abandoned(self, run: _Run) -> None:
        """Shutdown, the job still computing (the procedures do not look at the stop): recorded
        now; the thread is a daemon and its late writes are refused by the state check."""
        with self.sessions() as s:
            queries.update_calibration_job(s, run.id, allowed_from=("queued", "running"),
                                           state="failed", error=INTERRUPTED,
                                           finished_at=time.time())

    def _work(self, run: _Run, plan: Any, activate_result: bool) -> Ending:
        from calibration.report import write_report
        from drivers.sim.operator import SimulatedOperator
        from service.lab.acquisition import run_rig_calibration

        job_id = run.id
        partial = self.root / f"{_PARTIAL}{job_id}"
        to, error, cal_hash, activated = "done", None, None, False
        operator: Any = None
        try:
            with self.sessions() as s:
                queries.update_calibration_job(s, job_id, allowed_from=("queued",),
                                               state="running", started_at=time.time(),
                                               message="starting")
            rig = self.lease.require()
            if self.world is not None:
                operator, rig_name = SimulatedOperator(self.world), "simulated"
            else:
                operator, rig_name = _WaitingOperator(self, run), "lab"

            def progress(done: int, total: int, message: str) -> None:
                run.raise_if_stopped()
                self._note(job_id, message, done, total)

            result = run_rig_calibration(rig, operator, self.scene.spec, self.scene.base_dir,
                                         plan, progress, rig_name=rig_name)
            run.raise_if_stopped()
            self._note(job_id, "writing the report")
            write_report(partial, result)
            os.replace(partial, self.out_dir(job_id))
            cal_hash = twin_hash(result.calibration)
            if activate_result:
                activate(self.sessions, result.calibration, f"calibration job {job_id}")
                activated = True
        except Stopped:
            to, error = run.stopping
        except InvalidInputError as exc:  # the sequence refused what it measured
            to, error = "failed", (f"{exc}. The rig's data could not give a trustworthy "
                                   "calibration: check the board, the fixtures and the plan "
                                   "(docs/calibration.md), then start a new job")
        except DeviceError as exc:
            to, error = "failed", (f"device fault ({type(exc).__name__}): {exc}. Fix the rig "
                                   "(GET /api/v1/devices), then start a new job")
        except Exception as exc:  # a bug: recorded, never a lost thread
            _log.exception("calibration job %s failed", job_id)
            to, error = "failed", (f"{type(exc).__name__}: {exc} (an unexpected error; the "
                                   "service's log has the traceback)")
        finally:
            if to != "done":
                shutil.rmtree(partial, ignore_errors=True)
            if self.world is not None and to != "done":  # the test object back on the table
                try:
                    self.world.mount(None)
                except Exception:  # pragma: no cover - never mask the job's own outcome
                    _log.exception("could not mount the test object again")
        run.progress.calibration_hash, run.progress.activated = cal_hash, activated
        return to, error


def job_public(row: Any, live: dict[str, Any] | None) -> dict[str, Any]:
    """The public form of a job row."""
    import json

    base = f"/api/v1/calibrations/{row.id}"
    files = {}
    if row.state == "done":  # their URLs: where the server keeps them is its own business
        files = {n: f"{base}/files/{n}" for n in OUTPUT_FILES}
        files |= {n: f"{base}/files/{n}" for n in OPTIONAL_FILES  # as the file route serves
                  if (Path(row.out_dir) / n).is_file()
                  and not (Path(row.out_dir) / n).is_symlink()}
    links = {"self": base, "events": f"{base}/events"}
    if row.state == "done":
        links |= {"activate": f"{base}/activate", "report": f"{base}/files/report.html",
                  "calibration": f"{base}/files/calibration.yaml"}
    total = max(int(row.steps_total), 1)
    return {
        "id": row.id, "state": row.state, "plan": json.loads(row.plan_json),
        "activate": bool(row.activate), "steps_done": row.steps_done,
        "steps_total": row.steps_total,
        "progress": 1.0 if row.state == "done" else min(row.steps_done / total, 1.0),
        # the instruction's own message: the row may have been read before it was written
        "message": (live or {}).get("message") or row.message, "error": row.error,
        "calibration_hash": row.calibration_hash, "activated": bool(row.activated),
        "files": files,
        "verdicts": job_verdicts(row),
        "operator_instruction": None if live is None else live.get("operator_instruction"),
        "created_at": row.created_at, "started_at": row.started_at,
        "updated_at": row.updated_at, "finished_at": row.finished_at, "links": links,
    }


def job_verdicts(row: Any) -> dict[str, dict[str, Any]] | None:
    """A done job's verdicts (its ``verdicts.json``: key -> verdict, std, reason), or None
    before it is done or when the file is gone (its ``files`` link then answers 410)."""
    from calibration.verdicts import VERDICTS_FILE, read_verdicts

    if row.state != "done":
        return None
    path = Path(row.out_dir) / VERDICTS_FILE
    if path.is_symlink() or not path.is_file():  # as _output_file: no link is followed
        return None
    try:
        return read_verdicts(path).to_json()
    except (OSError, ValueError, KeyError, TypeError):  # a damaged file is no verdicts
        _log.warning("calibration job %s: verdicts.json could not be read", row.id)
        return None


def job_status(sessions: sessionmaker, jobs: CalibrationJobs, job_id: str) -> dict[str, Any]:
    """``GET /calibrations/{id}`` (404 for an unknown job)."""
    live = jobs.live(job_id)  # first: a job no longer running has its final row written
    with sessions() as s:
        row = queries.require_calibration_job(s, job_id)
    return job_public(row, live)


def job_file(sessions: sessionmaker, job_id: str, name: str) -> Path:
    """One output file of a done job (409 before it is done; see :func:`_output_file`)."""
    with sessions() as s:
        row = queries.require_calibration_job(s, job_id)
    if row.state != "done":
        raise ConflictError(f"calibration job {job_id} is '{row.state}'; its files exist once "
                            "it is 'done'")
    return _output_file(row, name)


def _output_file(row: Any, name: str) -> Path:
    """The file ``name`` in a job's output folder: 410 when the folder or one of the
    :data:`OUTPUT_FILES` (a done job has them all) is gone, 404 for another file it does not
    have, and 404 for a symbolic link (the folder's or the file's): a link could lead anywhere
    on the server, so none is followed. Messages name the job and the file, never the
    server's path."""
    out = Path(row.out_dir)
    if out.is_symlink():
        raise NotFoundError(f"calibration job {row.id}: its folder in the data directory is a "
                            "link, not the folder the job wrote; its files are not served")
    if not out.is_dir():
        raise GoneError(f"calibration job {row.id}: its folder ({out.parent.name}/{out.name}) "
                        "is gone from the data directory")
    path = out / name
    if path.is_symlink():
        raise NotFoundError(f"calibration job {row.id}: {name} is a link, not a file the job "
                            "wrote; it is not served")
    if not path.is_file():
        if name in OUTPUT_FILES:
            raise GoneError(f"calibration job {row.id}: {name} is gone from its folder in the "
                            "data directory")
        raise NotFoundError(f"calibration job {row.id} has no file {name}")
    return path

