"""The campaign runner: one background thread works through a campaign's poses.

Life cycle (states stored in the database)::

    created --start--> running --(all done)--> completed
                       running --pause / device fault / emergency stop--> paused
                       running --cancel--> cancelled       running --(bug)--> failed
                       running --(service stopped or killed)--> interrupted
    paused | interrupted | failed --resume--> running      created | paused | interrupted --cancel

The unit of work is one pose and repeat. Its result and both frame rows are committed in one
transaction the moment it is finished, and always in order; ``UNIQUE(campaign, pose, repeat)``
forbids a second one. ``resume`` (and a start after a crash) recomputes the units still missing
from the database, so no unit is repeated and none is skipped, whatever happened before.

Up to ``settings.depth`` units are in flight: the rig stage (move, capture) of the next unit
overlaps the simulation of the previous ones. With depth 1 (``TOFTWIN_PIPELINE_DEPTH=1``) a unit
is committed before the next one begins. Work in flight when the process dies has no row and is
simply done again on resume; its frame folders are swept at the next start.

One campaign runs at a time and holds the rig for each unit's rig stage; manual device calls are
refused with 409 while it runs (:class:`~service.lab.rig_lease.RigLease`). A device fault pauses the
campaign with the device's message; the operator fixes the rig and resumes. A lost camera (or
camera bridge) is the exception: the campaign resumes by itself once the camera delivers frames
again (:mod:`service.lab.camera_return`, ``camera_return_s``).

The life cycle (the thread, the rig's claim, stop, the emergency stop, shutdown) is the one
background runner's (:class:`~service.lab.background.BackgroundRunner`, shared with the
calibration jobs); this module holds the campaign's work and rows.
"""

from __future__ import annotations

import collections
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy.orm import sessionmaker

from calibration.object_twin.plan import captures_in_order, object_fit_capture_plan
from drivers.camera.protocol import CameraLostError
from drivers.errors import DeviceError
from service.compute.executors import Executor
from service.errors import ConflictError
from service.lab.acquisition import NO_MOUNTS, acquire
from service.lab.background import BackgroundRunner, Ending, Kind, Run, Stop, Stopped, failed
from service.lab.calibration import Twin, calibration_from_json
from service.lab.camera_return import CameraReturnWatch
from service.lab.object_fit import fit_poses, fitted_twin, run_fit
from service.lab.poses import (
    Measurement,
    Outcome,
    PosePlan,
    finish,
    measure,
    replay_measure,
    submit,
)
from service.lab.requests import MaskSpec, ObjectFitIn
from service.lab.scenes import SceneSource, require_mounted
from service.lab.turning import capture_turning
from service.settings import Settings
from service.store import queries
from service.store.disk_space import free_bytes, is_disk_full, low_space_message
from service.store.frame_files import FrameStore
from service.store.recording import (
    RecordedCampaign,
    RecordedUnit,
    Recording,
    RecordingWriter,
    resolve_stored_path,
)
from sim_core.errors import InvalidInputError
from sim_core.twin_file import twin_hash

_log = logging.getLogger(__name__)


@dataclass
class _Progress:
    """What the running campaign's worker knows: the pose worked on, the units done."""

    current: dict[str, Any] | None = None
    done: int = 0
    outcomes: list[Outcome] = field(default_factory=list)
    #: the run was paused by a lost camera (:meth:`CampaignRunner._device_fault`)
    camera_lost: bool = False
    #: what is done with each unit's captured frames before they are simulated: written to
    #: the campaign's recording, if it records (:mod:`service.store.recording`)
    record: Callable[[PosePlan, Measurement], None] = lambda _plan, _m: None


_Run = Run[_Progress]


class CampaignRunner:
    """Starts, pauses, resumes and cancels campaigns; runs one at a time.

    Parameters
    ----------
    sessions : sessionmaker
        Database sessions (campaign rows, results).
    background : BackgroundRunner
        The one runner of the service's background jobs: it claims the rig (its ``lease``) for
        the campaign it runs, stops it, and records how it ended.
    store : FrameStore
    executor : Executor
        Where the simulations run.
    settings : Settings
        ``depth``, ``threads_per_job``, ``job_timeout_s``, ``solar_stable_timeout_s``.
    mounted : SceneSource, optional
        The scene on the rig's turntable; a campaign of another scene (stored before the
        service was restarted with another one) does not start (409).
    """

    def __init__(self, sessions: sessionmaker, background: BackgroundRunner, store: FrameStore,
                 executor: Executor, settings: Settings,
                 mounted: SceneSource | None = None) -> None:
        self.sessions = sessions
        #: the scene on the rig's turntable: a campaign of another one does not start
        self.mounted = mounted
        self.lease = background.lease
        self.store = store
        self.executor = executor
        self.settings = settings
        self.background = background
        self.kind: Kind[_Progress] = Kind(
            name="campaign", busy="campaign {id} is running; one campaign at a time",
            emergency=Stop("paused", "emergency stop"),
            shutdown=Stop("interrupted", "the service was shut down"),
            live=self._live, finish=self._finished, failed=self._failed, thread="campaign")
        #: per-unit outcomes of the last run (benchmarks read them)
        self.last_outcomes: list[Outcome] = []
        #: resumes a campaign paused by a lost camera once it is back
        self.camera_return = CameraReturnWatch(
            self._still_paused, self._probe_camera, lambda cid: self.start(cid, resume=True),
            settings.camera_return_s, settings.camera_return_poll_s)

    # -- queries --------------------------------------------------------------------------------
    def live(self, campaign_id: str) -> dict[str, Any] | None:
        """Current pose and throughput of ``campaign_id`` if it is the one running."""
        return self.background.live(self.kind, campaign_id)

    def wait(self, timeout_s: float | None = None) -> None:
        """Block until the running campaign's thread ends (benchmarks, tests)."""
        self.background.wait(timeout_s, self.kind)

    # -- commands -------------------------------------------------------------------------------
    def start(self, campaign_id: str, resume: bool = False) -> None:
        """Start (``created``) or resume (``paused``, ``interrupted``, ``failed``) a campaign."""
        allowed = queries.RESUMABLE if resume else ("created",)
        with self.sessions() as s:
            replay = queries.require_campaign(s, campaign_id).replay_path is not None
        if not replay:  # a replay needs no rig (and not the mounted scene)
            self.lease.require()

        def prepare() -> None:  # with the rig claimed: 409 while a calibration job holds it
            with self.sessions() as s:
                row = queries.require_campaign(s, campaign_id)
                if self.mounted is not None and not replay:
                    stored = SceneSource.from_json(row.scene_json, row.scene_base_dir,
                                                   row.scene_name)
                    require_mounted(stored, self.mounted,
                                    inline=stored.name != self.mounted.name)
                if not queries.transition(s, campaign_id, allowed, "running", started=True,
                                          count_run=True):
                    verb = "resume" if resume else "start"
                    raise ConflictError(
                        f"cannot {verb} campaign {campaign_id} in state '{row.state}'; "
                        f"allowed from: {', '.join(allowed)}"
                    )

        self.background.start(self.kind, campaign_id, self._units, _Progress(), prepare)

    def stop(self, campaign_id: str, to: str, error: str | None = None) -> bool:
        """Ask the running campaign to stop after the units in flight (``paused``/``cancelled``).

        Returns False if ``campaign_id`` is not running. Waits up to ``settings.stop_wait_s``.
        """
        return self.background.stop(self.kind, campaign_id, Stop(to, error))

    def pause(self, campaign_id: str) -> None:
        if not self.stop(campaign_id, "paused"):
            self._require_state(campaign_id, ("running",), "pause")

    def cancel(self, campaign_id: str) -> None:
        if self.stop(campaign_id, "cancelled"):
            return
        with self.sessions() as s:
            queries.require_campaign(s, campaign_id)
            if not queries.transition(s, campaign_id, ("created", "paused", "interrupted"),
                                   "cancelled", finished=True):
                self._require_state(campaign_id, ("created", "paused", "interrupted"), "cancel")

    def _require_state(self, campaign_id: str, allowed: tuple[str, ...], verb: str) -> None:
        with self.sessions() as s:
            row = queries.require_campaign(s, campaign_id)
        raise ConflictError(
            f"cannot {verb} campaign {campaign_id} in state '{row.state}'; "
            f"allowed from: {', '.join(allowed)}"
        )

    # -- the worker thread ---------------------------------------------------------------------
    def _live(self, run: _Run) -> dict[str, Any]:
        elapsed = time.monotonic() - run.started
        return {"current": run.progress.current, "done_in_run": run.progress.done,
                "elapsed_s": elapsed}

    def _failed(self, run: _Run, exc: Exception) -> Ending:
        """A bug or a broken executor is ``failed``; a full disk ``paused`` (the operator frees
        space and resumes)."""
        if not is_disk_full(exc):
            return failed(run, exc)
        _log.warning("campaign %s paused: disk full: %s", run.id, exc)
        return "paused", low_space_message(free_bytes(self.store.root),
                                           self.settings.min_free_bytes)

    def _finished(self, run: _Run, to: str, error: str | None) -> None:
        """The final state (in the runner's critical section, the rig already given back)."""
        self.last_outcomes = run.progress.outcomes
        with self.sessions() as s:
            queries.transition(s, run.id, ("running",), to, error=error,
                               finished=to in queries.TERMINAL)
        if to == "paused" and run.progress.camera_lost and error is not None:
            self.camera_return.start(run.id, error)

    def _device_fault(self, run: _Run, exc: DeviceError) -> Ending:
        """How a device fault ends the run: paused with the device's message (the emergency
        stop's own state when one made the device fail); a lost camera is watched for and the
        campaign resumed when it is back (:mod:`service.lab.camera_return`), and says so."""
        _log.warning("campaign %s paused: device fault: %s", run.id, exc)
        if run.stop.is_set():  # an emergency stop made the move fail
            return run.stopping
        error = f"device fault ({type(exc).__name__}): {exc}"
        if isinstance(exc, CameraLostError) and self.settings.camera_return_s > 0.0:
            run.progress.camera_lost = True
            error += (f"; the campaign resumes by itself when the camera delivers frames again "
                      f"(watched for {self.settings.camera_return_s:g} s)")
        return "paused", error

    def _still_paused(self, campaign_id: str, error: str) -> bool:
        """Whether ``campaign_id`` is still paused with ``error`` (nobody acted on it)."""
        with self.sessions() as s:
            row = queries.get_campaign(s, campaign_id)
        return row is not None and row.state == "paused" and row.error == error

    def _probe_camera(self) -> None:
        """One frame through the rig (refused while a job holds it): raises while the camera
        is away."""
        with self.lease.manual() as rig:
            rig.capture(1)

    def close(self) -> None:
        """Stop watching for lost cameras (the service shuts down)."""
        self.camera_return.close()

    def _units(self, run: _Run) -> Ending:
        settings = self.settings
        with self.sessions() as s:
            camp = queries.get_campaign(s, run.id)
            poses = queries.planned_poses(s, run.id)
            done = queries.done_units(s, run.id)
        scene = SceneSource.from_json(camp.scene_json, camp.scene_base_dir, camp.scene_name)
        mask = MaskSpec.model_validate_json(camp.mask_json)
        twin = Twin.of(calibration_from_json(camp.calibration_json))  # pinned at creation
        fitted, effects, noise_fraction = None, "auto", None
        if camp.object_fit_json is not None:
            fit_in = ObjectFitIn.model_validate_json(camp.object_fit_json)
            effects, noise_fraction = fit_in.effects, fit_in.noise_fraction
            object_twin_json = camp.object_twin_json
            if object_twin_json is None:  # not fitted yet (or the last try did not finish)
                object_twin_json, stopped = self._object_fit(run, camp, scene, twin, poses)
                if object_twin_json is None:
                    return stopped
            fitted = fitted_twin(twin, object_twin_json)
        todo = [(p, r) for p in poses for r in range(p.repeats) if (p.pose_index, r) not in done]
        in_flight: collections.deque[tuple[PosePlan, Measurement, Any]] = collections.deque()
        to, error = "completed", None
        data_dir = self.settings.data_dir
        replay = (None if camp.replay_path is None
                  else Recording(resolve_stored_path(data_dir, camp.replay_path)))
        if camp.record_path is not None:
            with self.sessions() as s:  # with the object twin, if it was fitted just now
                recorded = RecordedCampaign.of_row(queries.get_campaign(s, run.id), poses,
                                                   self.settings.examples_dir)
            recorder = RecordingWriter(resolve_stored_path(data_dir, camp.record_path), recorded)
            run.progress.record = lambda plan, m: recorder.append(recorded_unit(plan, m))
        if camp.turning_deg_s is not None and replay is None:
            plans = [PosePlan(scene, p.turntable_deg, p.solar_suns, mask, camp.seed, camp.spp,
                              run.id, p.pose_index, r, twin, fitted, effects, noise_fraction)
                     for p, r in todo]
            return self._turning_units(run, plans, camp.turning_deg_s)
        try:
            for pose, repeat in todo:
                if run.stop.is_set():
                    to, error = run.stopping
                    break
                free = free_bytes(self.store.root)
                if free < settings.min_free_bytes:
                    to, error = "paused", low_space_message(free, settings.min_free_bytes)
                    _log.warning("campaign %s paused: %s", run.id, error)
                    break
                plan = PosePlan(scene, pose.turntable_deg, pose.solar_suns, mask, camp.seed,
                                camp.spp, run.id, pose.pose_index, repeat, twin,
                                fitted, effects, noise_fraction)
                run.progress.current = {"pose_index": pose.pose_index, "repeat": repeat,
                               "turntable_deg": pose.turntable_deg,
                               "solar_suns": pose.solar_suns}
                try:
                    m = (replay_measure(replay, self.store, plan) if replay is not None else
                         measure(self.lease.require(), self.store, plan,
                                 settings.solar_stable_timeout_s))
                except DeviceError as exc:
                    to, error = self._device_fault(run, exc)
                    break
                in_flight.append((plan, m, submit(self.executor, plan, m,
                                                  settings.threads_per_job)))
                run.progress.record(plan, m)  # a failure here removes its frame (in flight)
                while len(in_flight) >= settings.depth:
                    self._finish(run, *in_flight.popleft())
            while in_flight:
                self._finish(run, *in_flight.popleft())
        except BaseException:
            for _plan, m, _job in in_flight:  # frames of unfinished units: not kept
                self.store.delete([m.row.id])
            raise
        return to, error

    def _turning_units(self, run: _Run, plans: list[PosePlan], speed_deg_s: float) -> Ending:
        """A campaign that captures while turning (:mod:`service.lab.turning`): one sweep per
        repeat through its poses, then each frame simulated with its sub-frames and compared."""
        settings = self.settings

        def current(plan: PosePlan) -> None:
            run.progress.current = {"pose_index": plan.pose_index, "repeat": plan.repeat,
                                    "turntable_deg": plan.turntable_deg,
                                    "solar_suns": plan.solar_suns, "turning_deg_s": speed_deg_s}

        for repeat in sorted({p.repeat for p in plans}):
            sweep = [p for p in plans if p.repeat == repeat]
            try:
                measured = capture_turning(self.lease.require(), self.store, sweep, speed_deg_s,
                                           run.stop.is_set, current)
            except DeviceError as exc:
                return self._device_fault(run, exc)
            try:  # the sweep's frames are recorded once it is through
                for plan, m in measured:
                    run.progress.record(plan, m)
            except BaseException:
                self.store.delete([m.row.id for _plan, m in measured])
                raise
            for plan, m in measured:
                self._finish(run, plan, m, submit(self.executor, plan, m,
                                                  settings.threads_per_job))
            if run.stop.is_set():
                return run.stopping
        return "completed", None

    def _object_fit(self, run: _Run, camp: Any, scene: SceneSource, twin: Twin,
                    poses: list[Any]) -> tuple[str | None, tuple[str, str | None]]:
        """The campaign's object fit stage (:mod:`service.lab.object_fit`).

        Returns the fitted object twin as JSON (stored with the campaign), or None and the
        state to stop in: stopped by the operator, a device fault (paused, resumable), or a fit
        the frames cannot determine (failed, with the estimator's message).
        """
        fit = ObjectFitIn.model_validate_json(camp.object_fit_json)
        targets = fit_poses(poses, fit.poses)
        plan = object_fit_capture_plan([p.turntable_deg for p in targets], fit.frames)

        def progress(done: int, _total: int, _message: str) -> None:
            run.raise_if_stopped()
            run.progress.current = {"stage": "object_fit", "pose_index": done, "repeat": 0,
                                    "turntable_deg": targets[done].turntable_deg,
                                    "solar_suns": targets[done].solar_suns}

        rig = self.lease.require()
        try:
            captures = captures_in_order(plan, acquire(rig, NO_MOUNTS, plan, progress,
                                                       settle_for=twin.calibration))
        except Stopped:
            return None, run.stopping
        except DeviceError as exc:
            return None, self._device_fault(run, exc)
        try:
            object_twin, report = run_fit(scene, twin, captures, rig.camera.use_case)
        except InvalidInputError as exc:
            _log.warning("campaign %s: object fit failed: %s", run.id, exc)
            return None, ("failed", f"object fit: {exc}")
        data = object_twin.model_dump(mode="json")
        with self.sessions() as s:
            queries.set_object_twin(s, run.id, data, twin_hash(object_twin), report)
        return queries.dumps(data), ("completed", None)

    def _finish(self, run: _Run, plan: PosePlan, m: Measurement, job: Any) -> None:
        outcome = finish(self.sessions, self.store, plan, m, job, self.settings.job_timeout_s)
        run.progress.done += 1
        run.progress.outcomes.append(outcome)


def recorded_unit(plan: PosePlan, m: Measurement) -> RecordedUnit:
    """A unit's captured frames as a recording keeps them."""
    return RecordedUnit(plan.pose_index, plan.repeat, m.rig, m.use_case, m.turning_deg_s,
                        m.raws)
