"""The lab: everything a running service holds, assembled in one place.

:func:`open_lab` builds it (the app's lifespan and the campaign benchmark call it), in this
order: the data directory's lock (:mod:`service.store.data_lock`: a second service on the same
directory is refused before it touches anything), the disk reserve given back for the while the
database opens (:class:`service.store.disk_space.SpaceReserve`: on a full disk its room lets the
service start, serve reads and delete; it is made again afterwards if there is room), the
database (migrated to the newest schema,
and every campaign a crash left ``running`` becomes ``interrupted``), the
frame store (frames no row names are swept away), the executor, the rig (simulated or real,
:func:`service.lab.rig_builder.open_rig`; a real rig that cannot be opened leaves the service
up with the devices reporting 503), the
background runner (:class:`~service.lab.background.BackgroundRunner`: one job at a time, of
either kind, holds the rig), and on it the campaign runner and the calibration jobs (a job a
crash left running becomes ``failed``). Each part gets what it uses, not the lab: the campaign
runner its sessions, background runner, store, executor and settings; the routes ask for the
one part they need.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from drivers.errors import DeviceError
from service.compute.executors import Executor, make_executor
from service.errors import UnavailableError
from service.lab.background import BackgroundRunner
from service.lab.calibration_jobs import CalibrationJobs
from service.lab.rig_builder import open_rig
from service.lab.rig_lease import RigLease
from service.lab.runner import CampaignRunner
from service.lab.scenes import SceneSource, resolve_scene
from service.settings import Settings
from service.store import queries
from service.store.data_lock import DataDirLock
from service.store.database import init_db, make_engine
from service.store.disk_space import SpaceReserve, is_disk_full
from service.store.frame_files import FrameStore

#: the disk reserve's file in the data directory (:class:`SpaceReserve`)
RESERVE_NAME = ".space-reserve"

_log = logging.getLogger(__name__)


@dataclass
class Lab:
    """The state of one running service (``app.state.lab``)."""

    settings: Settings
    engine: Engine
    sessions: sessionmaker
    store: FrameStore
    executor: Executor
    default_scene: SceneSource
    lease: RigLease
    runner: CampaignRunner
    calibrations: CalibrationJobs
    #: the one runner of background jobs (campaigns, calibration jobs): e-stop, shutdown
    background: BackgroundRunner
    #: what startup recovered after a crash: campaigns marked interrupted, frames swept
    recovered: dict[str, list[str]] = field(default_factory=dict)
    lock: DataDirLock | None = None

    @contextlib.contextmanager
    def session(self) -> Iterator[Session]:
        """A database session."""
        with self.sessions() as s:
            yield s

    def close(self) -> None:
        """Stop the running job, the executor and the rig; dispose of the engine; unlock the
        data."""
        try:
            self.runner.close()  # no campaign resumes itself from now on
            self.background.shutdown()
            with contextlib.suppress(Exception):
                self.executor.close()
            self.lease.close()
            self.engine.dispose()
        finally:
            if self.lock is not None:
                self.lock.release()


def open_lab(settings: Settings) -> Lab:
    """Build the service state; see the module docstring for the order.

    Raises :class:`service.store.data_lock.DataDirInUseError` if another process holds the data
    directory; the lock is released by :meth:`Lab.close` (or if opening fails).
    """
    lock = DataDirLock.acquire(settings.data_dir, port=settings.port)
    try:
        return _open_locked(settings, lock)
    except BaseException:
        lock.release()
        raise


def _recover_campaigns(sessions: sessionmaker) -> list[str]:
    """Mark the campaigns a crash left ``running`` as ``interrupted``; on a full disk (the
    service starts to serve reads and deletes) they stay as they are, with a warning, until a
    start with room."""
    try:
        with sessions() as s:
            return queries.mark_interrupted(s)
    except Exception as exc:
        if not is_disk_full(exc):
            raise
        _log.warning("disk full: campaigns left running by a crash are not marked interrupted "
                     "until the service starts with room (%s)", exc)
        return []


def _open_locked(settings: Settings, lock: DataDirLock) -> Lab:
    data = Path(settings.data_dir)
    reserve = SpaceReserve(data / RESERVE_NAME)
    # On a full disk the reserve's room lets SQLite open (its shared-memory index and log need
    # a few pages); it is made again afterwards if the room is there, else left free.
    with reserve.released():
        engine = make_engine(settings.database)
        sessions = init_db(engine)
        interrupted = _recover_campaigns(sessions)
        with sessions() as s:
            known = queries.all_frame_ids(s)
        store = FrameStore(data / "frames", reserve=reserve)
        swept = store.sweep(known)
    if interrupted or swept:
        _log.warning("recovered after a crash: interrupted campaigns %s, %d orphan frame(s)",
                     interrupted, len(swept))
    scene = resolve_scene(settings.scene, settings.examples_dir, settings.max_scene_objects)
    executor = make_executor(settings.executor, settings.workers, settings.threads_per_job,
                             settings.dask_address)
    executor.warm_up(wait=False)  # start the workers and load the renderer now, not at pose 1
    world = None
    try:
        (rig, world), rig_error = open_rig(settings, scene), None
    except (DeviceError, UnavailableError, OSError) as exc:
        rig, rig_error = None, str(exc)
        _log.error("rig not available: %s", exc)
    lease = RigLease(rig, rig_error, settings.rig_wait_s)
    background = BackgroundRunner(lease, settings.stop_wait_s)
    runner = CampaignRunner(sessions, background, store, executor, settings, mounted=scene)
    calibrations = CalibrationJobs(sessions, background, scene, settings, data / "calibrations",
                                   world)
    failed_jobs = calibrations.recover()
    if failed_jobs:
        _log.warning("calibration jobs interrupted by the service's end, now failed: %s",
                     failed_jobs)
    return Lab(settings, engine, sessions, store, executor, scene, lease, runner, calibrations,
               background,
               recovered={"interrupted": interrupted, "swept_frames": swept,
                          "failed_calibrations": failed_jobs}, lock=lock)
