"""The simulated lab's world: the scene as it really is, rendered for the rig's state.

The simulated pico flexx (:mod:`drivers.sim.usb_camera`) asks a frame source for every frame
it streams. :class:`SimulatedWorld` is that source for the simulated lab: it renders the scene
for the rig's current turntable angle, solar level and shutter, through the full imaging chain,
as a *reality* says the world differs from the nominal scene (:class:`sim_core.twin_file.
RealityFile`: the camera's true intrinsics, depth errors, gain and noise, the source's power,
the turntable's true axis and zero, the solar simulator's scale, the mount's pose, the objects'
reflectance). Code that estimates parameters sees only the frames; nothing here is reachable
through the service's API.

Repeated frames of one rig state are exposures of the *same* rendered light field with new
sensor noise (the render is cached), as repeated frames of a static scene are: their
differences are the camera's noise alone, which the noise calibration relies on.

The reality's camera effects of issue 27 act on every frame: its stray light
(``camera.stray_light``) spreads the rendered light, and its warm-up (``camera.temperature``)
drifts each frame's depth at the illumination's temperature on the lab's clock
(:class:`drivers.sim.lab_clock.LabClock`: frames and moves since the service's start), which the
frame reports (``RawFrame.illumination_temperature_c``, as royale's
``RawData.illuminationTemperature``).

The operator's swap of what stands on the turntable is :meth:`SimulatedWorld.mount`: the
scene's own mounted objects, or other objects (a calibration board in its fixture).

A table that moves during a frame (turning, or still ringing after a move: the rig state's
``table_angle_after_deg``, :class:`drivers.sim.rig.SimulatedRigState`) is rendered at its
physical angle at each phase step's time (:mod:`sim_core.subframes`), so the frame smears as a
camera's does; a table that moves less than the tolerance during the frame is rendered once.
An instant stage has no time to ring in: a world made with ``rings_on_lab_clock`` rings its
table on the lab's clock instead, from the end of every move the clock saw, and stamps each
frame with the lab's time (the settling stage of a calibration times the ringing by them).
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from drivers.sim.lab_clock import LabClock
from drivers.sim.usb_camera import CameraRequest
from sim_core.pipeline import RenderedLight, SensorLight, expose_light, render_light, sensor_light
from sim_core.raw import RawFrame
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import Scene, build_scene
from sim_core.scene_spec import ObjectPose, ObjectSpec, SceneSpec
from sim_core.settling import envelope_deg, ringing_of_moves_deg
from sim_core.subframes import MOTION_TOLERANCE_DEG, moves_during_frame, phase_step_angles_deg
from sim_core.twin_file import MountParameters, ObjectParameters, RealityFile, TurntableParameters
from sim_core.warmup import illumination_temperature_c

#: rendered light fields kept per world (one per rig state and use case, most recent first)
CACHE_STATES = 4
#: how a world renders unless told otherwise: few samples, two bounces, every effect
DEFAULT_RENDER = RenderRequest(RenderSettings(integrator="path", spp=8, max_bounces=2),
                               effects="all")


@dataclasses.dataclass
class _Rendered:
    """One rig state's render, kept for the frames that follow: the scene, its light field and
    the light on the sensor (the optics' fixed part, :func:`sim_core.pipeline.sensor_light`,
    computed at the first frame that exposes it whole)."""

    scene: Scene
    light: RenderedLight
    on_sensor: SensorLight | None = None


@dataclasses.dataclass(frozen=True)
class WorldState:
    """The physical state a frame is rendered for (what :class:`drivers.rig.RigState` holds)."""

    turntable_angle_deg: float
    solar_suns: float
    shutter_open: bool


def default_reality(spec: SceneSpec) -> RealityFile:
    """The simulated lab's world when no reality file is given: small differences everywhere.

    The mounted objects sit 4 mm / -3 mm / 2 mm off their nominal place, the turntable's zero is
    0.5 deg off, and every object reflects 8 % less than its nominal material says. Comparing a
    measured frame with a simulation of the nominal scene is then never trivially perfect.
    """
    return RealityFile(
        turntable=TurntableParameters(zero_offset_deg=0.5),
        mount=MountParameters(pose_offset=ObjectPose(position_m=(0.004, -0.003, 0.002))),
        objects={o.name: ObjectParameters(reflectance_scale=0.92) for o in spec.objects},
    )


class SimulatedWorld:
    """``CameraRequest -> RawFrame`` by rendering the rig's current state in the reality.

    Parameters
    ----------
    spec : SceneSpec
        The nominal scene.
    base_dir : path
        Folder relative mesh paths resolve against.
    render : RenderRequest, optional
        How the simulated camera renders the world (few spp keep it fast; default
        :data:`DEFAULT_RENDER`). Its seed is replaced per frame request. Its ``effects``: a world
        has every effect (``"all"``, the default): the effect planner's ``"auto"`` leaves out
        what it judges below a frame's noise, and its judgement on a marginal effect (the
        satellite's interreflections, a few per cent of a panel's light) flips with the
        reality's reflectances, so a twin fitted to averaged frames would see a world that lacks
        light any real one has. ``"auto"`` is for speed where that cannot matter. Its accuracy
        target's ``noise_fraction``: render at least ``spp`` samples and more where the Monte
        Carlo error is above this fraction of the sensor's noise
        (:func:`sim_core.adaptive.noise_fraction`): a real scene has no render noise, and what a
        render leaves in the world's light is frozen into every capture of it (a twin can never
        match it).
    reality : RealityFile, optional
        How the world differs from ``spec``; :func:`default_reality` if not given.
    rings_on_lab_clock : bool
        The reality's ``turntable.settling`` rings the table on the lab's clock (and each frame
        is stamped with the lab's time, ``RawFrame.timestamp_s``): the simulated lab of an
        instant stage, whose own clock has no time for a ringing (a stage that runs in time
        rings on its own clock, :mod:`drivers.sim.smc100`, and the world then leaves it to
        it). Off by default, and an instant stage's table then stops dead: on, every frame of
        a ringing table is a render of its own, so a run that never waits for the table (a
        campaign without the settling calibrated) renders each of its frames anew.
    """

    def __init__(
        self,
        spec: SceneSpec,
        base_dir: str | Path,
        render: RenderRequest = DEFAULT_RENDER,
        reality: RealityFile | None = None,
        rings_on_lab_clock: bool = False,
    ) -> None:
        if render.effects not in ("all", "auto"):
            raise ValueError(f"effects must be 'all' or 'auto', got {render.effects!r}")
        self.render = render
        self.spec = spec
        self.base_dir = Path(base_dir)
        self.reality = reality if reality is not None else default_reality(spec)
        self._mounted: tuple[ObjectSpec, ...] | None = None
        self._generation = 0
        self._cache: OrderedDict[tuple, _Rendered] = OrderedDict()
        self._lock = threading.Lock()
        #: whether the last frame was rendered per phase step (the table moved during it);
        #: for tests and diagnostics: a frame's own metadata says only what a camera reports
        self.last_rendered_per_step = False
        #: the simulated lab's time since the service's start (the illumination's warm-up)
        self.clock = LabClock()
        self.rings_on_lab_clock = rings_on_lab_clock
        #: the wall time the lab's clock started at: frames stamped on the lab's clock read as
        #: times since the epoch, as a camera's do
        self._epoch_s = time.time()
        # Fail now, not at the first frame, if the reality does not fit the scene.
        build_scene(spec, self.base_dir, twin=self.reality)

    # -- the operator's swap ---------------------------------------------------------------
    def mount(self, objects: Sequence[ObjectSpec] | None = None) -> None:
        """Put ``objects`` on the turntable instead of the scene's mounted objects.

        ``objects`` are given in the world frame at the turntable's zero and are mounted exactly
        (a fixture: the reality's mount offset and reflectance scales do not apply to them);
        they are marked ``on_turntable``. ``None`` puts the scene's own objects back.
        """
        with self._lock:
            self._mounted = None if objects is None else tuple(
                o.model_copy(update={"on_turntable": True}) for o in objects)
            self._generation += 1
            self._cache.clear()

    @property
    def mounted(self) -> str:
        """``"scene"`` or the names of the objects mounted instead, comma-separated."""
        m = self._mounted
        return "scene" if m is None else ",".join(o.name for o in m)

    def _world(self) -> tuple[SceneSpec, RealityFile]:
        if self._mounted is None:
            return self.spec, self.reality
        fixed = [o for o in self.spec.objects if not o.on_turntable]
        spec = self.spec.model_copy(update={"objects": fixed + list(self._mounted)})
        reality = self.reality.model_copy(update={
            "mount": MountParameters(),
            "objects": {k: v for k, v in self.reality.objects.items()
                        if k in {o.name for o in fixed}},
        })
        return spec, reality

    # -- frames ----------------------------------------------------------------------------
    def _state(self, request: CameraRequest) -> WorldState:
        state = request.rig_state
        if state is not None:  # a drivers.rig.RigState (the rig imports this module: no import)
            return WorldState(float(state.turntable_angle_deg), float(state.solar_suns),
                              bool(state.shutter_open))
        # A camera simulator without a rig: the nominal state.
        angle = self.spec.turntable.angle_deg if self.spec.turntable else 0.0
        sim = self.spec.ambient.solar_simulator
        return WorldState(angle, sim.irradiance_suns if sim else 0.0, sim is not None)

    def _table_angle_after_deg(self, request: CameraRequest, state: WorldState,
                               t_s: float) -> Callable[[float], float] | None:
        """The table's angle ``dt`` seconds after this frame's start, or None for a table at
        rest: the stage's own motion (``table_angle_after_deg`` of the rig state), plus the
        ringing on the lab's clock when the world keeps it (``rings_on_lab_clock``) and it is
        above :data:`sim_core.subframes.MOTION_TOLERANCE_DEG` (below it, the table is at
        rest: one render, "simulate only the effects a scene calls for")."""
        stage = getattr(request.rig_state, "table_angle_after_deg", None)
        settling = self.reality.turntable.settling
        if (not self.rings_on_lab_clock or settling is None
                or getattr(request.rig_state, "stage_rings", False)):
            return stage
        ends_s, signs = self.clock.moves()
        if float(np.sum(envelope_deg(settling, t_s - ends_s))) < MOTION_TOLERANCE_DEG:
            return stage
        commanded_deg = state.turntable_angle_deg

        def angle_after_deg(dt_s: float) -> float:
            base = commanded_deg if stage is None else float(stage(dt_s))
            return base + ringing_of_moves_deg(settling, t_s + dt_s, ends_s, signs)

        return angle_after_deg

    @staticmethod
    def _step_angles_deg(request: CameraRequest,
                         angle_after_deg: Callable[[float], float] | None) -> np.ndarray | None:
        """The table's angle at each phase step, (n_f, 4), when it moves during the frame by
        more than the tolerance; None when it holds still (one render)."""
        if angle_after_deg is None:
            return None
        uc = request.use_case
        angles = phase_step_angles_deg(angle_after_deg, uc.n_frequencies, uc.exposure_s)
        return angles if moves_during_frame(angles) else None

    def _rendered(self, request: CameraRequest, state: WorldState) -> _Rendered:
        uc = request.use_case
        suns = state.solar_suns if state.shutter_open and state.solar_suns > 0.0 else 0.0
        key = (self._generation, round(state.turntable_angle_deg, 9), round(suns, 6), uc.name,
               tuple(uc.frequencies_hz), uc.exposure_s, uc.shape, request.seed)
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit
        spec, reality = self._world()
        spec = spec.model_copy(update={"camera": spec.camera.model_copy(update={
            "modulation_frequencies_hz": list(uc.frequencies_hz),
            "exposure_s": uc.exposure_s,
            "width_px": uc.shape[1],
            "height_px": uc.shape[0],
        })})
        scene = build_scene(spec, self.base_dir, turntable_deg=state.turntable_angle_deg,
                            solar_suns=suns, twin=reality)
        render = self.render.with_seed(request.seed * 1_000_003 + self._generation)
        entry = _Rendered(scene, render_light(scene, render))
        self._cache[key] = entry
        while len(self._cache) > CACHE_STATES:
            self._cache.popitem(last=False)
        return entry

    def __call__(self, request: CameraRequest) -> RawFrame:
        state = self._state(request)
        with self._lock:  # one render at a time; the camera thread and tests may both ask
            t_s = self.clock.frame_time_s(state.turntable_angle_deg,
                                          request.use_case.frame_rate_hz)
            angle_after_deg = self._table_angle_after_deg(request, state, t_s)
            step_angles = self._step_angles_deg(request, angle_after_deg)
            if angle_after_deg is not None and step_angles is None:
                # still during the frame, where it is at the frame's start (its ringing too)
                state = dataclasses.replace(state,
                                            turntable_angle_deg=float(angle_after_deg(0.0)))
            self.last_rendered_per_step = step_angles is not None
            warm = self.reality.camera.temperature
            temperature_c = None if warm is None else illumination_temperature_c(t_s, warm)
            on_sensor = steps = None
            if step_angles is None:
                entry = self._rendered(request, state)
                if entry.on_sensor is None:  # the optics' fixed part, once per render
                    entry.on_sensor = sensor_light(entry.scene, entry.light.plan,
                                                   entry.light.light_field, ideal=False)
                on_sensor = entry.on_sensor
            else:
                entries = [self._rendered(request, dataclasses.replace(
                    state, turntable_angle_deg=float(a))) for a in step_angles.ravel()]
                entry = entries[0]
                steps = [e.light for e in entries]
            scene = dataclasses.replace(entry.scene, illumination_temperature_c=temperature_c)
            frame = expose_light(scene, entry.light, noise_rng=request.rng(), steps=steps,
                                 light=on_sensor)
        raw = frame.raw
        # Nothing about the reality goes into the frame: only what a camera would report.
        meta = {"source": "rendered", "frame_index": request.frame_index,
                "rig": dataclasses.asdict(state)}
        stamp_s = self._epoch_s + t_s if self.rings_on_lab_clock else request.timestamp_s
        return dataclasses.replace(raw, timestamp_s=stamp_s, meta=meta,
                                   illumination_temperature_c=temperature_c)
