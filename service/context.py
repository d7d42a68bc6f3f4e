"""Everything a running service holds: settings, database, frame store, executor, rig, runner.

:func:`open_context` builds it (the app's lifespan calls it at startup), in this order: the
database (and every campaign a crash left ``running`` becomes ``interrupted``), the frame store
(frames no row names are swept away), the executor, the rig (simulated or real; a real rig that
cannot be opened leaves the service up with the devices reporting 503), the campaign runner.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from drivers.errors import DeviceError, DeviceTimeoutError
from drivers.rig import Rig
from service import crud
from service.config import Settings
from service.db import init_db, make_engine
from service.errors import ConflictError, UnavailableError
from service.executors import Executor, make_executor
from service.frames import FrameStore
from service.scenes import SceneSource, resolve_scene

if TYPE_CHECKING:
    from service.campaigns import CampaignRunner

_log = logging.getLogger(__name__)


@dataclass
class ServiceContext:
    """The state of one running service (``app.state.ctx``)."""

    settings: Settings
    engine: Engine
    sessions: sessionmaker
    store: FrameStore
    executor: Executor
    default_scene: SceneSource
    rig: Rig | None = None
    rig_error: str | None = None
    runner: CampaignRunner | None = None  # set by open_context
    recovered: dict[str, list[str]] = field(default_factory=dict)

    @contextlib.contextmanager
    def session(self) -> Iterator[Session]:
        with self.sessions() as s:
            yield s

    def require_rig(self) -> Rig:
        """The rig, or 503 naming why it is not there."""
        if self.rig is None:
            raise UnavailableError(f"rig not available: {self.rig_error or 'not configured'}")
        return self.rig

    @contextlib.contextmanager
    def manual_rig(self) -> Iterator[Rig]:
        """Hold the rig for a manual call; 409 while a campaign runs (checked under the lock)."""
        rig = self.require_rig()
        self._refuse_if_campaign()
        with contextlib.ExitStack() as stack:
            try:
                stack.enter_context(rig.hold(timeout_s=self.settings.rig_wait_s))
            except DeviceTimeoutError as exc:  # the lock, not a device: another caller has it
                raise ConflictError(str(exc)) from None
            self._refuse_if_campaign()
            yield rig

    def _refuse_if_campaign(self) -> None:
        active = self.runner.active_id if self.runner is not None else None
        if active is not None:
            raise ConflictError(
                f"campaign {active} is running and holds the rig; pause it or wait for it"
            )

    def close(self) -> None:
        """Stop the runner, the executor and the rig; dispose of the engine."""
        if self.runner is not None:
            self.runner.shutdown()
        with contextlib.suppress(Exception):
            self.executor.close()
        if self.rig is not None:
            self.rig.close()
        self.engine.dispose()


def open_rig(settings: Settings, scene: SceneSource) -> Rig:
    """The simulated rig (rendering ``scene``) or the real one on the configured ports."""
    if settings.simulated:
        from service.jobs import RENDER_LOCK
        from service.twin_camera import RenderedFrameSource
        from sim_core.render import RenderSettings

        source = RenderedFrameSource(
            scene.spec, scene.base_dir,
            RenderSettings(integrator=settings.camera_integrator, spp=settings.camera_spp,
                           max_bounces=2),
        )

        def frame_source(request):
            with RENDER_LOCK:  # never two renders at once in this process (see RENDER_LOCK)
                return source(request)

        return Rig.simulated(frame_source=frame_source, seed=settings.camera_seed)
    from drivers.camera import UsbCamera
    from drivers.solar_simulator import SolarSimulator
    from drivers.turntable import Turntable

    missing = [n for n in ("turntable_port", "lamp_port", "shutter_port")
               if getattr(settings, n) is None]
    if missing:
        raise UnavailableError(
            f"no {', '.join('TOFTWIN_' + m.upper() for m in missing)} set (or use --simulated)"
        )
    opened: list = []
    try:
        turntable = Turntable(settings.turntable_port, address=settings.turntable_address)
        turntable.connect()
        opened.append(turntable)
        solar = SolarSimulator(settings.lamp_port, settings.shutter_port)
        solar.connect()
        opened.append(solar)
        camera = UsbCamera(settings.camera_serial)
        camera.connect()
    except BaseException:
        for device in reversed(opened):
            with contextlib.suppress(Exception):
                device.close()
        raise
    return Rig(turntable, solar, camera)


def open_context(settings: Settings) -> ServiceContext:
    """Build the service state; see the module docstring for the order."""
    from service.campaigns import CampaignRunner

    data = Path(settings.data_dir)
    data.mkdir(parents=True, exist_ok=True)
    engine = make_engine(settings.database)
    sessions = init_db(engine)
    with sessions() as s:
        interrupted = crud.mark_interrupted(s)
        known = crud.all_frame_ids(s)
    store = FrameStore(data / "frames")
    swept = store.sweep(known)
    if interrupted or swept:
        _log.warning("recovered after a crash: interrupted campaigns %s, %d orphan frame(s)",
                     interrupted, len(swept))
    scene = resolve_scene(settings.scene, settings.examples_dir, settings.max_scene_objects)
    executor = make_executor(settings.executor, settings.workers, settings.threads_per_job,
                             settings.dask_address)
    executor.warm_up(wait=False)  # start the workers and load the renderer now, not at pose 1
    ctx = ServiceContext(settings, engine, sessions, store, executor, scene,
                         recovered={"interrupted": interrupted, "swept_frames": swept})
    try:
        ctx.rig = open_rig(settings, scene)
    except (DeviceError, UnavailableError, OSError) as exc:
        ctx.rig_error = str(exc)
        _log.error("rig not available: %s", exc)
    ctx.runner = CampaignRunner(ctx)
    return ctx
