"""The pose loop in three stages: measure (rig), simulate (executor), finish (compare, commit).

1. :func:`measure` - with the rig held only for the moves and the capture: turn the table, set
   the solar simulator, capture one frame; then, rig released, reconstruct and store it. The
   rig state read back, not the one asked for, is what the simulation poses the scene at.
2. :func:`submit` - send the simulation job for that state to the executor.
3. :func:`finish` - wait for the simulated frame, store it, compare, and commit the result and
   both frame rows in one transaction.

A campaign overlaps stage 1 of the next pose with stage 2 of the previous ones; an ad-hoc pose
(``POST /api/v1/poses``) runs them in a row. Timings of every stage go into the result:
``move``, ``capture``, ``store`` (both frames' files), ``simulate`` (the worker's render and
files), ``simulate_files`` (of which writing the files, ``save_frame``), ``simulate_wait`` (how
long the loop waited for it), ``compare``, ``total``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sqlalchemy.orm import sessionmaker

from drivers.camera.wire import get_use_case
from drivers.errors import LimitError
from drivers.rig import Rig, RigState
from service.compute.executors import Executor, JobFuture
from service.compute.jobs import make_job
from service.lab.calibration import Twin, active_twin, effective_twin
from service.lab.comparison import build_mask, compare, explained_difference
from service.lab.requests import MaskSpec, PoseCreate
from service.lab.rig_lease import RigLease
from service.lab.scenes import (
    SceneSource,
    camera_of,
    check_mask,
    for_use_case,
    image_shape,
    require_mounted,
    scene_from_request,
)
from service.lab.settling import settled_moves
from service.settings import Settings
from service.store import queries
from service.store.disk_space import require_free, writing
from service.store.frame_files import FrameStore, new_frame_id
from service.store.recording import Recording
from service.store.tables import FrameRow, PoseResultRow
from sim_core.camera import z_over_range as camera_z_over_range
from sim_core.edges import edge_depth_error
from sim_core.errors import InvalidInputError
from sim_core.frame_io import grey_full_scale
from sim_core.processed_depth import (
    CAMERA_DATA_DEPTH,
    CAMERA_DATA_RAW,
    ProcessedDepthFrame,
    camera_data,
    measured_image,
)
from sim_core.raw import RawFrame
from sim_core.render_request import AccuracyTarget, RenderRequest, request_from_spec
from sim_core.scene_spec import SceneSpec
from sim_core.tof import ToFImage
from sim_core.twin_apply import apply_to_spec


def unit_seed(seed: int, pose_index: int, repeat: int) -> int:
    """The render seed of one pose and repeat: independent streams, reproducible."""
    ss = np.random.SeedSequence([seed, pose_index, repeat])
    return int(ss.generate_state(1, dtype=np.uint32)[0])


@dataclass(frozen=True)
class PosePlan:
    """One pose and repeat to measure and simulate."""

    scene: SceneSource
    turntable_deg: float
    solar_suns: float
    mask: MaskSpec
    seed: int
    spp: int
    campaign_id: str | None = None
    pose_index: int = 0
    repeat: int = 0
    #: the calibration the simulation applies (and whose intrinsics reconstruct the measurement)
    twin: Twin = field(default_factory=Twin)
    #: the fitted twin (calibration and fitted object) of a campaign with an object fit: the
    #: pose is also simulated with it, and captured twice for the noise ceiling
    fitted: Twin | None = None
    #: the effects the simulations render ("auto": the effect planner's choice, or "all")
    effects: str = "auto"
    #: Monte Carlo error target of the simulations, as a fraction of the sensor's noise
    #: (:func:`sim_core.adaptive.noise_fraction`); None: ``spp`` everywhere
    noise_fraction: float | None = None

    def render_request(self, threads: int | None) -> RenderRequest:
        """How this unit's simulations render: the scene's ``render:`` section with the plan's
        samples per pixel, effects and noise-fraction target, the unit's own seed
        (:func:`unit_seed`) and the worker's threads."""
        return request_from_spec(
            self.scene.spec.render, spp=self.spp,
            seed=unit_seed(self.seed, self.pose_index, self.repeat),
            threads=threads, effects=self.effects,
            accuracy=AccuracyTarget(noise_fraction=self.noise_fraction))

    @property
    def target(self) -> RigState:
        """The rig state to drive to (shutter open whenever the lamp is lit)."""
        return RigState(self.turntable_deg, self.solar_suns, shutter_open=self.solar_suns > 0)


@dataclass
class Measurement:
    """Stage 1's result: the stored measured frame (row not yet committed) and the rig state."""

    row: FrameRow
    image: ToFImage
    rig: RigState
    #: the plan's scene with the camera as the rig's is set up (:func:`for_use_case`), nominal
    #: intrinsics: what the simulations render
    spec: SceneSpec
    timings_s: dict[str, float] = field(default_factory=dict)
    started: float = 0.0
    grey_full_scale: float = 0.0
    #: a second capture of the same state (the noise ceiling; plans with a fitted twin)
    second: ToFImage | None = None
    #: the table's speed during the exposure [deg/s] (0: at rest; a capture while turning):
    #: ``rig`` holds its angle at the frame's start; the simulations render each sub-frame at
    #: its angle
    turning_deg_s: float = 0.0
    #: the illumination temperature the camera reported with the frame [degC], if any: the
    #: simulations apply a calibrated warm-up drift at it
    illumination_temperature_c: float | None = None
    #: the raw frame(s) as captured (a campaign that records them writes these), and the use
    #: case they were taken in
    raws: list[RawFrame | ProcessedDepthFrame] = field(default_factory=list)
    use_case: str = ""

    @property
    def camera_data(self) -> str:
        """What the measurement is: the camera's raw frames, reconstructed by us, or royale's
        processed depth (:func:`sim_core.processed_depth.camera_data`)."""
        return camera_data(self.raws[0]) if self.raws else CAMERA_DATA_RAW


@dataclass(frozen=True)
class Submitted:
    """Stage 2's jobs: each is (frame id, future); ``fitted`` only with a fitted twin."""

    nominal: tuple[str, JobFuture]
    fitted: tuple[str, JobFuture] | None = None

    @property
    def frame_ids(self) -> list[str]:
        return [self.nominal[0]] + ([] if self.fitted is None else [self.fitted[0]])


@dataclass(frozen=True)
class Outcome:
    """Stage 3's result: the committed row, the stage timings and the commit's duration."""

    row: PoseResultRow
    timings_s: dict[str, float]
    commit_s: float


def check_angle(rig: Rig, angle_deg: float, field_name: str) -> None:
    """Raise a 422-mapped :class:`LimitError` if the stage may not go to ``angle_deg``."""
    low, high = rig.turntable.limits_deg
    if not low <= angle_deg <= high:
        raise LimitError(field_name, angle_deg, low, high, "deg", "turntable software limits")


def check_spp(spp: int | None, settings: Settings) -> int:
    """The samples per pixel to render: the request's (at most ``max_spp``) or the default."""
    if spp is None:
        return min(settings.sim_spp, settings.max_spp)
    if spp > settings.max_spp:
        raise InvalidInputError("spp", f"got {spp}; allowed: 1 to {settings.max_spp} (max_spp)")
    return spp


def measure(
    rig: Rig, store: FrameStore, plan: PosePlan, stable_timeout_s: float | None
) -> Measurement:
    """Stage 1. Holds the rig for the moves and the capture; device faults propagate.

    The rig state is checked against the plan's target after the moves and before and after
    the exposure (:meth:`Rig.apply`, :meth:`Rig.capture`): a device that was not in its target
    state for the whole exposure raises a :class:`~drivers.errors.DeviceError` naming it
    before anything is stored.
    """
    t0 = time.perf_counter()
    with rig.hold(), settled_moves(rig, plan.twin.calibration):
        wait = stable_timeout_s if plan.solar_suns > 0 else None
        state = rig.apply(plan.target, wait_stable_s=wait)
        t1 = time.perf_counter()
        # read back before and after the exposure: a device off its target raises, nothing
        # is stored (a lamp that went out, a shutter that closed, a stage that crept away)
        raws = rig.capture(1 if plan.fitted is None else 2, target=plan.target)
        use_case = rig.camera.use_case
    return store_measurement(store, plan, state, raws, use_case, t0, t1)


def store_measurement(
    store: FrameStore, plan: PosePlan, state: RigState, raws: list[Any], use_case: Any,
    t0: float, t1: float, turning_deg_s: float = 0.0,
) -> Measurement:
    """Stage 1's second half: store the captured frame(s) of ``plan`` taken at ``state`` (moves
    from ``t0`` to ``t1``, the capture until now, :func:`time.perf_counter`)."""
    raw = raws[0]
    t2 = time.perf_counter()
    sim_spec = for_use_case(plan.scene.spec, use_case)
    spec = sim_spec
    if plan.twin.calibration is not None:  # the calibrated intrinsics turn range into depth
        spec = apply_to_spec(spec, plan.twin.calibration)
    camera = camera_of(spec)
    extra = {
        "rig": state.to_dict(), "scene_name": plan.scene.name, "campaign_id": plan.campaign_id,
        "pose_index": plan.pose_index, "repeat": plan.repeat, "use_case": use_case.name,
        "calibration_hash": plan.twin.hash,
    }
    frame_id, image, grey_full_scale = store.save_measured(raw, camera, extra)
    second = None if len(raws) < 2 else measured_image(raws[1], camera_z_over_range(
        camera.intrinsics))
    t3 = time.perf_counter()
    row = queries.frame_row(
        frame_id, "measured", campaign_id=plan.campaign_id, scene_name=plan.scene.name,
        rig=state.to_dict(), summary=_summary(image), calibration_hash=plan.twin.hash,
    )
    return Measurement(row, image, state, sim_spec,
                       {"move": t1 - t0, "capture": t2 - t1, "store": t3 - t2}, t0,
                       grey_full_scale, second, turning_deg_s, raw.illumination_temperature_c,
                       list(raws), use_case.name)


def replay_measure(recording: Recording, store: FrameStore, plan: PosePlan) -> Measurement:
    """Stage 1 of a replay: the unit's recorded frame(s) (two for a plan with a fitted twin)
    stored as :func:`measure` stores a captured one, at the rig state, use case and turning
    speed recorded with them. Raises :class:`~service.store.recording.RecordingError` for a
    unit the recording does not hold."""
    t0 = time.perf_counter()
    unit = recording.unit(plan.pose_index, plan.repeat, 1 if plan.fitted is None else 2)
    return store_measurement(store, plan, unit.state, unit.raws, get_use_case(unit.use_case),
                             t0, t0, unit.turning_deg_s)


def submit(
    executor: Executor, plan: PosePlan, m: Measurement, threads: int | None
) -> Submitted:
    """Stage 2: simulate the scene at the measured rig state, with the plan's twin and (if the
    plan has one) with the fitted twin."""
    nominal = _submit_one(executor, plan, m, threads, plan.twin, "nominal")
    if plan.fitted is None:
        return Submitted(nominal)
    return Submitted(nominal, _submit_one(executor, plan, m, threads, plan.fitted, "fitted"))


def _submit_one(
    executor: Executor, plan: PosePlan, m: Measurement, threads: int | None, twin: Twin,
    label: str,
) -> tuple[str, JobFuture]:
    frame_id = new_frame_id()
    job = make_job(
        m.spec, plan.scene.base_dir,
        turntable_deg=m.rig.turntable_angle_deg,
        solar_suns=m.rig.irradiance_suns,
        request=plan.render_request(threads),
        scene_name=plan.scene.name,
        extra={
            "frame_id": frame_id, "rig": m.rig.to_dict(), "campaign_id": plan.campaign_id,
            "pose_index": plan.pose_index, "repeat": plan.repeat,
            "object_names": [o.name for o in plan.scene.spec.objects],
            "turntable_object_ids": plan.scene.turntable_object_ids,
            "measured_frame_id": m.row.id, "twin": label,
            "illumination_temperature_c": m.illumination_temperature_c,
        },
        twin=twin.to_json(),
        turntable_speed_deg_s=m.turning_deg_s,
        illumination_temperature_c=m.illumination_temperature_c,
    )
    return frame_id, executor.submit(job)


def finish(
    sessions: sessionmaker, store: FrameStore, plan: PosePlan, m: Measurement,
    jobs: Submitted, timeout_s: float,
) -> Outcome:
    """Stage 3: store the simulated frame(s), compare, commit the result and its frame rows.

    If anything fails on the way (a simulation, its files, the comparison, the commit), all of
    the unit's frame folders are removed at once: no frame is left without a row.
    """
    try:
        return _finish(sessions, store, plan, m, jobs, timeout_s)
    except BaseException:
        store.delete([m.row.id, *jobs.frame_ids])
        raise


def _finish(
    sessions: sessionmaker, store: FrameStore, plan: PosePlan, m: Measurement,
    jobs: Submitted, timeout_s: float,
) -> Outcome:
    sim_id, future = jobs.nominal
    t0 = time.perf_counter()
    result = future.result(timeout=timeout_s)
    fitted = None if jobs.fitted is None else jobs.fitted[1].result(timeout=timeout_s)
    t1 = time.perf_counter()
    store.save_files(sim_id, result.files)
    if fitted is not None:
        store.save_files(jobs.fitted[0], fitted.files)
    t2 = time.perf_counter()
    names = [o.name for o in plan.scene.spec.objects]
    depth_data = m.camera_data == CAMERA_DATA_DEPTH
    # royale's grey has no known ADC scale: both greys are then scaled by their own 99.5th
    # percentile (the twin's as the measured frame's is)
    sim_full_scale = (grey_full_scale(result.image.amplitude, result.image.valid, None)
                      if depth_data else result.grey_full_scale)
    try:
        mask = build_mask(plan.mask, m.image, result.object_id, names,
                          plan.scene.turntable_object_ids)
        report = compare(m.image, result.image, mask, (m.grey_full_scale, sim_full_scale))
        metrics: dict[str, Any] = report.to_dict()
        metrics["table"] = [list(r) for r in report.table_rows()]
        if m.turning_deg_s:  # captured while turning: how much of the error sits at edges
            metrics["edges"] = edge_depth_error(m.image.range_m, result.image.range_m, mask,
                                                result.image.valid).to_dict()
    except InvalidInputError as exc:  # e.g. no pixel valid in both frames: recorded, not fatal
        report, metrics = None, {"error": str(exc), "table": []}
    metrics["camera_data"] = m.camera_data  # every result says what the camera gave
    if fitted is not None:
        metrics["explained"] = explained_difference(
            plan.mask, m.image, m.second, m.grey_full_scale, report, fitted.image,
            fitted.object_id, fitted.grey_full_scale, names, plan.scene.turntable_object_ids)
    t3 = time.perf_counter()
    sim_row = queries.frame_row(
        sim_id, "simulated", campaign_id=plan.campaign_id, scene_name=plan.scene.name,
        scene_hash=result.scene_hash, rig=m.rig.to_dict(), summary=_summary(result.image),
        calibration_hash=plan.twin.hash,
    )
    fitted_row = None
    if fitted is not None:
        fitted_row = queries.frame_row(
            jobs.fitted[0], "simulated", campaign_id=plan.campaign_id,
            scene_name=plan.scene.name, scene_hash=fitted.scene_hash, rig=m.rig.to_dict(),
            summary=_summary(fitted.image), calibration_hash=plan.fitted.hash,
        )
    timings = {
        **m.timings_s,
        "simulate": sum(r.timings_s.get("total", 0.0) + r.timings_s.get("save", 0.0)
                        for r in (result, fitted) if r is not None),
        "simulate_files": sum(r.timings_s.get("save", 0.0) for r in (result, fitted)
                              if r is not None),
        "simulate_wait": t1 - t0,
        "compare": t3 - t2,
    }
    timings["store"] += t2 - t1
    timings["total"] = t3 - m.started  # the commit below is not included
    with sessions() as session:
        row = queries.add_result(
            session, campaign_id=plan.campaign_id, pose_index=plan.pose_index,
            repeat=plan.repeat, turntable_deg=plan.turntable_deg,
            solar_suns=plan.solar_suns, measured=m.row, simulated=sim_row,
            metrics=metrics, rig=m.rig.to_dict(), timings_s=timings,
            calibration_hash=plan.twin.hash, fitted=fitted_row,
        )
    return Outcome(row, timings, time.perf_counter() - t3)


def run_single_pose(
    req: PoseCreate, *, lease: RigLease, sessions: sessionmaker, store: FrameStore,
    executor: Executor, settings: Settings, mounted: SceneSource,
) -> Outcome:
    """``POST /poses``: the three stages in a row for one pose (of the ``mounted`` scene).

    A disk that fills up on the way is a 507 naming what was being written; the frames written
    so far are removed (:func:`finish` removes its own, this the measured one)."""
    scene = scene_from_request(settings, req.scene)
    spp = check_spp(req.spp, settings)
    rig = lease.require()
    check_angle(rig, req.turntable_deg, "turntable_deg")
    check_mask(req.mask, scene, image_shape(scene, rig.camera.use_case))
    require_mounted(scene, mounted, inline=isinstance(req.scene, dict))
    require_free(store.root, settings.min_free_bytes)  # 507 before anything moves
    plan = PosePlan(scene, req.turntable_deg, req.solar_suns, req.mask, req.seed, spp,
                    twin=effective_twin(active_twin(sessions), scene))
    floor = settings.min_free_bytes
    with writing("the pose's measured frame", store.root, floor), lease.manual() as rig:
        m = measure(rig, store, plan, settings.solar_stable_timeout_s)
    try:
        jobs = submit(executor, plan, m, settings.threads_per_job)
        with writing("the pose's simulated frame and its result", store.root, floor):
            return finish(sessions, store, plan, m, jobs, settings.job_timeout_s)
    except BaseException:
        store.delete([m.row.id])
        raise


def _summary(image: ToFImage) -> dict[str, Any]:
    valid = np.asarray(image.valid)
    rng = image.range_m[valid]
    return {
        "shape": list(valid.shape),
        "valid_pixels": int(valid.sum()),
        "median_range_m": float(np.median(rng)) if rng.size else None,
    }
