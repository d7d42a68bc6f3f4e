"""``toftwin calibrate rig``: the whole calibration sequence, planned and fitted (issue 13, §4).

The sequence is a plan and a fit: :func:`rig_capture_plan` says what to capture (none of it
depends on what the fits find), the service runs it on the rig
(:func:`service.lab.acquisition.run_rig_calibration`) and :func:`fit_rig_calibration` fits
steps 0-7 from the averaged captures it is handed (:mod:`calibration.capture_plan`).

0. **Warm-up**, first, as on a real rig from power-on: the first fixture's board, nothing
   moves, captures spread over the warm-up by the plan's waits, each frame with its reported
   illumination temperature; the depth drift per degree (:mod:`calibration.rig_warmup`), which
   every depth fit of step 4 removes at its capture's temperature. Then the **settling**: the
   board at rest, one move, and frames at once after it, not waiting for the table
   (:mod:`calibration.rig_settling`; fitted after step 3, at the calibrated intrinsics).
1. **Board sweeps.** For each fixture (tilt) the operator mounts the board (the simulated lab
   mounts it itself); the turntable sweeps the board past the camera with the solar simulator
   off; each view averages several frames (:mod:`calibration.captures`) and OpenCV finds the
   board's corners in its amplitude.
2. **Intrinsics and distortion** from all views (:mod:`calibration.intrinsics`), as the start
   of 3.
3. **Turntable axis and zero**, and the intrinsics again, by one bundle adjustment of the camera
   and the turntable model together (:mod:`calibration.turntable_axis`); then the detector's
   corner bias is measured on the twin's renders of the views (:mod:`calibration.corner_bias`),
   removed, and 2 and 3 run again.
4. **Depth errors**: measured phase on the board against the range its pose predicts
   (:mod:`calibration.board_range`, :mod:`calibration.depth`). Fitted last, from the board
   views with the calibrated warm-up drift and the stray light step 7 measures taken out
   (:func:`calibration.captures.without_stray_light`): left in, the stray light pulls the
   board's phases towards its surroundings' in every view alike, a shared bias the depth model
   absorbs with the error bars of noise (reality 202 of the rig sweep: 1.04 mm at 23 std).
5. **Noise and gain**: a stack of frames of one static view, photon transfer
   (:mod:`calibration.noise_gain`).
6. **Effective source power**: the white squares' amplitude against the twin's prediction at
   the calibrated geometry and gain (:mod:`calibration.photometry`).
7. **Solar simulator scale**: the intensity's response to the lamp's level against the twin's
   prediction (:mod:`calibration.solar`), or a reference-cell reading.

Each step uses only what the frames (and the previous steps) say; the result is a
:class:`sim_core.twin_file.CalibrationFile` with each procedure's residuals in its provenance,
and every key of it judged (:mod:`calibration.rig_verdicts`): the noise model of step 5 is fitted
first, so that every other step's residual is judged against the noise (the corners', the
phases'); a board view the camera and turntable model cannot explain is dropped with its reason
(``results["views"]["unexplained"]``).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from calibration.angles import (
    SWEEP_FIELDS,
    SWEEP_FROM_DEG,
    SWEEP_STEP_DEG,
    SWEEP_TO_DEG,
    sweep_angles,
)
from calibration.capture_plan import (
    CapturePlan,
    Captures,
    CaptureStep,
    MountStep,
    Step,
    WaitStep,
    mount,
)
from calibration.captures import AveragedCapture, Progress, no_progress
from calibration.fixtures import BoardFixture, board_object, world_from_board
from calibration.photometry import fit_source_power
from calibration.rig_evidence import (
    corner_radius,
    corner_std_px,
    depth_evidence,
    depth_through_drift,
    drift_carried_std_rad,
    free_stage_chi2,
    other_verdicts,
    reprojection_stage,
)
from calibration.rig_verdicts import (
    CameraTurntableEvidence,
    StageEvidence,
    calibration_keys,
    jackknife_std,
    rig_verdicts,
    unexplained_views,
)
from calibration.solar import (
    SolarScaleResult,
    check_reference_suns,
    fit_solar_scale,
    response_pixels,
)
from calibration.solar_stray_light import SolarStrayLightFit, fit_solar_stray_light
from calibration.twin_prediction import CameraUseCase, mounted_spec, predict_view
from calibration.verdicts import Verdict, Verdicts
from sim_core.errors import InvalidInputError
from sim_core.lights import SUNS_RANGE
from sim_core.scene import build_camera
from sim_core.scene_spec import ObjectSpec, SceneSpec
from sim_core.twin_file import (
    CalibrationFile,
    CameraParameters,
    IlluminationParameters,
    Provenance,
    SolarParameters,
    TurntableParameters,
    TwinParameters,
)

#: the board the sequence uses unless told otherwise (see docs/calibration.md for the choice):
#: 500 mm square, so that it stands clear of the table in every fixture (a taller board's lower
#: rows are hidden by the table, which takes its corners, and the image's lower part, away)
DEFAULT_BOARD: dict[str, Any] = {
    "kind": "charuco_board", "squares_x": 5, "squares_y": 5, "square_m": 0.10,
    "marker_m": 0.06, "dictionary": "DICT_4X4_50",
}
#: the fixtures: three tilts (together they determine the principal point,
#: CALIBRATION-NOTES.md), each at two distances off the axis towards the camera, so that the
#: board sweeps across the image and reaches its edges and lower part (docs/calibration.md)
DEFAULT_FIXTURES = tuple(
    BoardFixture(f"{tilt_name}@{off_mm}mm", tilt, centre_height_m=0.26,
                 towards_camera_m=off_mm * 1e-3)
    for off_mm in (200, 400) for tilt_name, tilt in (("tilt+30", 30.0), ("tilt-30", -30.0),
                                                      ("tilt0", 0.0)))
#: frames averaged per board view
FRAMES_PER_VIEW_RANGE = (1, 64)
#: frames of the noise stack: two for a variance, 16 or more for a gain within 1-2 %
NOISE_FRAMES_RANGE = (2, 256)
#: how many set levels of the solar simulator, each in sim_core.lights.SUNS_RANGE
SOLAR_LEVELS_COUNT = (1, 8)
#: frames averaged per solar level
SOLAR_FRAMES_RANGE = (1, 64)
#: captures of the warm-up stage (besides 0: none), and frames per capture
WARMUP_CAPTURES_RANGE = (3, 64)
WARMUP_FRAMES_RANGE = (1, 64)
#: the wait between two warm-up captures [s]
WARMUP_INTERVAL_RANGE_S = (0.0, 3600.0)
#: frames after the settling stage's move (besides 0: none) and at rest; its move [deg]
SETTLING_FRAMES_RANGE = (12, 1024)
SETTLING_REST_FRAMES_RANGE = (2, 1024)
SETTLING_MOVE_RANGE_DEG = (1.0, 90.0)
#: rounds of the corner-bias synthesis (each renders every view at the poses the turntable
#: model places it, with the calibrated camera)
DEBIAS_ROUNDS = 1

@dataclass(frozen=True)
class RigCalibrationPlan:
    """What the sequence captures.

    Attributes
    ----------
    board : dict
        The board's mesh spec (``charuco_board`` or ``checkerboard``, see scene-format.md).
    fixtures : tuple of BoardFixture
    sweep_deg : tuple of float
        Reported turntable angles of the board sweep (each fixture).
    frames_per_view : int
        Frames averaged per view.
    noise_frames : int
        Frames of the noise stack (at least 2; 16 or more give a gain within 1-2 %).
    solar_levels_suns : tuple of float
        Set levels of the solar simulator for its scale (besides the shutter closed).
    solar_frames : int
        Frames averaged per solar level.
    solar_reference_suns : float or None
        A reference cell's reading at a set level of 1 sun, used if the frames do not
        determine the scale.
    warmup_captures : int
        Captures of the warm-up stage (0: none; else at least 3), the first right after
        power-on (:mod:`calibration.rig_warmup`).
    warmup_interval_s : float
        The wait between two of them [s] (the rig sleeps, the simulated lab's clock runs).
    warmup_frames : int
        Frames per warm-up capture, each kept with its reported temperature.
    settling_frames : int
        Frames captured at once after the settling stage's move, not waiting for the table to
        settle (0: no settling stage; :mod:`calibration.rig_settling`).
    settling_rest_frames : int
        Frames of the board at rest before the move (the yaw's noise).
    settling_move_deg : float
        The settling stage's move, from the warm-up's angle [deg].
    """

    board: dict[str, Any] = field(default_factory=lambda: dict(DEFAULT_BOARD))
    fixtures: tuple[BoardFixture, ...] = DEFAULT_FIXTURES
    sweep_deg: tuple[float, ...] = sweep_angles()
    frames_per_view: int = 4
    noise_frames: int = 24
    solar_levels_suns: tuple[float, ...] = (0.8, 1.0, 1.2)
    solar_frames: int = 8
    solar_reference_suns: float | None = None
    warmup_captures: int = 10
    warmup_interval_s: float = 120.0
    warmup_frames: int = 4
    settling_frames: int = 90
    settling_rest_frames: int = 16
    settling_move_deg: float = 20.0

    def __post_init__(self) -> None:
        if len(self.fixtures) < 1:
            raise InvalidInputError("fixtures", "at least one board fixture is needed")
        names = [f.name for f in self.fixtures]
        if len(set(names)) != len(names):
            raise InvalidInputError("fixtures", f"{names} names a fixture twice; each once")
        if len(self.sweep_deg) < 3:
            raise InvalidInputError("sweep_deg", f"{len(self.sweep_deg)} angles; at least 3 "
                                    "distinct angles are needed to determine the axis")
        _count("frames_per_view", self.frames_per_view, *FRAMES_PER_VIEW_RANGE,
               "frames averaged per view")
        _count("noise_frames", self.noise_frames, *NOISE_FRAMES_RANGE,
               "frames: two for a variance, 16 or more for the gain within 1-2 %")
        _count("solar_levels_suns", len(self.solar_levels_suns), *SOLAR_LEVELS_COUNT, "levels")
        lo, hi = SUNS_RANGE
        for i, level in enumerate(self.solar_levels_suns):
            if not (np.isfinite(level) and lo <= level <= hi):
                raise InvalidInputError(f"solar_levels_suns[{i}]", f"got {level!r} sun; "
                                        f"allowed: {lo:g} to {hi:g} sun")
        _count("solar_frames", self.solar_frames, *SOLAR_FRAMES_RANGE, "frames per level")
        if self.solar_reference_suns is not None:
            check_reference_suns(self.solar_reference_suns)
        if self.warmup_captures != 0:
            _count("warmup_captures", self.warmup_captures, *WARMUP_CAPTURES_RANGE,
                   "captures (or 0: no warm-up stage)")
        lo_s, hi_s = WARMUP_INTERVAL_RANGE_S
        if not (np.isfinite(self.warmup_interval_s) and lo_s <= self.warmup_interval_s <= hi_s):
            raise InvalidInputError("warmup_interval_s", f"got {self.warmup_interval_s!r} s; "
                                    f"allowed: {lo_s:g} to {hi_s:g} s")
        _count("warmup_frames", self.warmup_frames, *WARMUP_FRAMES_RANGE, "frames per capture")
        if self.settling_frames != 0:
            _count("settling_frames", self.settling_frames, *SETTLING_FRAMES_RANGE,
                   "frames after the move (or 0: no settling stage)")
            _count("settling_rest_frames", self.settling_rest_frames,
                   *SETTLING_REST_FRAMES_RANGE, "frames at rest (a yaw noise needs 2)")
        lo_d, hi_d = SETTLING_MOVE_RANGE_DEG
        if not (np.isfinite(self.settling_move_deg)
                and lo_d <= abs(self.settling_move_deg) <= hi_d):
            raise InvalidInputError("settling_move_deg", f"got {self.settling_move_deg!r} deg; "
                                    f"allowed: {lo_d:g} to {hi_d:g} deg either way")

    def summary(self) -> dict[str, Any]:
        """The plan as JSON values: the fixtures by name, the rest as given (what
        ``toftwin calibrate rig --print-plan`` prints)."""
        return {"board": dict(self.board), "fixtures": [f.name for f in self.fixtures],
                "sweep_deg": list(self.sweep_deg), "frames_per_view": self.frames_per_view,
                "noise_frames": self.noise_frames,
                "solar_levels_suns": list(self.solar_levels_suns),
                "solar_frames": self.solar_frames,
                "solar_reference_suns": self.solar_reference_suns,
                "warmup_captures": self.warmup_captures,
                "warmup_interval_s": self.warmup_interval_s,
                "warmup_frames": self.warmup_frames,
                "settling_frames": self.settling_frames,
                "settling_rest_frames": self.settling_rest_frames,
                "settling_move_deg": self.settling_move_deg}

    @property
    def warmup_times_s(self) -> tuple[float, ...]:
        """Each warm-up capture's start after the first's, as planned [s] (the waits only: a
        capture's own frames take a second or less)."""
        return tuple(i * self.warmup_interval_s for i in range(self.warmup_captures))


def stage_counts(*, warmup: bool = True, settling: bool = True) -> dict[str, int]:
    """The plan's counts of the two optional stages: the default's, or 0 for a stage left out
    (a camera already warm needs no warm-up stage; a turntable whose ringing is known, no
    settling stage). The effect keys of a stage left out stay unmeasured, each named in the
    verdicts as not determined.

    >>> stage_counts(warmup=False)
    {'warmup_captures': 0, 'settling_frames': 90}
    """
    return {"warmup_captures": RigCalibrationPlan.warmup_captures if warmup else 0,
            "settling_frames": RigCalibrationPlan.settling_frames if settling else 0}


def build_rig_plan(
    *,
    fixtures: Sequence[str] | None = None,
    sweep_from_deg: float = SWEEP_FROM_DEG,
    sweep_to_deg: float = SWEEP_TO_DEG,
    sweep_step_deg: float = SWEEP_STEP_DEG,
    frames_per_view: int = RigCalibrationPlan.frames_per_view,
    noise_frames: int = RigCalibrationPlan.noise_frames,
    solar_levels_suns: Sequence[float] = RigCalibrationPlan.solar_levels_suns,
    solar_frames: int = RigCalibrationPlan.solar_frames,
    solar_reference_suns: float | None = None,
    fields: Mapping[str, str] = SWEEP_FIELDS,
    warmup_captures: int = RigCalibrationPlan.warmup_captures,
    warmup_interval_s: float = RigCalibrationPlan.warmup_interval_s,
    warmup_frames: int = RigCalibrationPlan.warmup_frames,
    settling_frames: int = RigCalibrationPlan.settling_frames,
    settling_rest_frames: int = RigCalibrationPlan.settling_rest_frames,
    settling_move_deg: float = RigCalibrationPlan.settling_move_deg,
) -> RigCalibrationPlan:
    """The calibration sequence's plan from its inputs: the one builder of the command line
    (``toftwin calibrate rig``) and the service (``POST /calibrations``).

    ``fixtures`` names board fixtures of :data:`DEFAULT_FIXTURES` (None: all of them); the sweep
    is :func:`calibration.angles.sweep_angles` (its rule, and ``fields``: how the caller names
    the sweep's inputs in the errors); the rest goes to :class:`RigCalibrationPlan` as given.
    """
    by_name = {f.name: f for f in DEFAULT_FIXTURES}
    unknown = [n for n in fixtures or () if n not in by_name]
    if unknown:
        raise InvalidInputError("fixtures", f"'{unknown[0]}' is not a fixture; allowed: "
                                f"{', '.join(by_name)}")
    chosen = DEFAULT_FIXTURES if fixtures is None else tuple(by_name[n] for n in fixtures)
    angles = sweep_angles(sweep_from_deg, sweep_to_deg, sweep_step_deg, fields=fields)
    try:
        return RigCalibrationPlan(
            fixtures=chosen, sweep_deg=angles, frames_per_view=frames_per_view,
            noise_frames=noise_frames, solar_levels_suns=tuple(solar_levels_suns),
            solar_frames=solar_frames, solar_reference_suns=solar_reference_suns,
            warmup_captures=warmup_captures, warmup_interval_s=warmup_interval_s,
            warmup_frames=warmup_frames, settling_frames=settling_frames,
            settling_rest_frames=settling_rest_frames, settling_move_deg=settling_move_deg)
    except InvalidInputError as exc:  # the plan's own checks, named as the caller names them
        raise InvalidInputError(exc.field.replace("sweep_deg", fields["sweep"]),
                                exc.message) from None

def _count(field_name: str, n: int, lo: int, hi: int, what: str) -> None:
    if not lo <= n <= hi:
        raise InvalidInputError(field_name, f"got {n}; allowed: {lo} to {hi} {what}")


@dataclass
class RigCalibration:
    """The sequence's outcome: the calibration file, every procedure's result, the captures,
    and the verdict of every key the file holds (:mod:`calibration.rig_verdicts`)."""

    calibration: CalibrationFile
    results: dict[str, Any]
    views: list[Any]
    frames_used: int
    verdicts: Verdicts = field(default_factory=Verdicts)


def _board_step(fixture: BoardFixture, index: int) -> str:
    return f"board/{fixture.name}/{index}"


#: the noise stacks' steps: the solar simulator off, and on at the plan's highest level
NOISE_STEPS = ("noise/dark", "noise/solar")


#: the warm-up stage's turntable angle: the first fixture's board facing the camera, as for
#: the noise stacks [deg]
WARMUP_ANGLE_DEG = 0.0


#: the stray light's keys on a rig without a solar simulator: the stray light is measured from
#: the solar stage's frames (:mod:`calibration.solar_stray_light`)
STRAY_LIGHT_NOT_MEASURED = {
    key: Verdict("not determined", None, "the stray light is measured from the solar stage's "
                 "frames, and this rig has no solar simulator: no key written")
    for key in ("camera.stray_light.fraction", "camera.stray_light.kernel_radius_px")}
#: the settling stage's captures: at rest (taken last, at the moved angle), right after the move
SETTLING_STEPS = ("settling/rest", "settling/moved")
#: the wait between the frames right after the move and the frames at rest [s]: a ringing of
#: 1 Hz damped at 0.02 falls from 1 deg to a hundredth of it in 37 s
SETTLING_REST_WAIT_S = 120.0
#: the calibration's key for the rest after every move when the table was seen ringing but how
#: is not known (:func:`_rest_after_move`)
REST_AFTER_MOVE_KEY = "turntable.rest_after_move_s"


def _warmup_step(index: int) -> str:
    return f"warmup/{index}"


def _solar_step(index: int) -> str:
    return f"solar/{index}"


def rig_capture_plan(plan: RigCalibrationPlan, spec: SceneSpec) -> CapturePlan:
    """What the sequence captures on ``spec``'s rig, in order (steps 0, 1, 5 and 7 of the
    module docstring): none of it depends on what the fits find."""
    steps: list[Step] = _warmup_steps(plan, spec) + _settling_steps(plan, spec)
    for k, fixture in enumerate(plan.fixtures):
        if k > 0 or not steps:  # the warm-up stage has mounted the first fixture already
            steps.append(_mount_board(plan, fixture, spec))
        steps += [CaptureStep(_board_step(fixture, i), angle, 0.0, False, plan.frames_per_view,
                              message=f"board {fixture.name} at {angle:+.0f} deg")
                  for i, angle in enumerate(plan.sweep_deg)]
    steps.append(_mount_board(plan, plan.fixtures[0], spec))
    steps.append(CaptureStep(NOISE_STEPS[0], 0.0, 0.0, False, plan.noise_frames,
                             keep_frames=True, message="noise stack"))
    if spec.ambient.solar_simulator is not None:
        # The solar simulator lights the whole view: many more bright pixels for the curve.
        level = max(plan.solar_levels_suns)
        steps.append(CaptureStep(NOISE_STEPS[1], 0.0, level, True, plan.noise_frames,
                                 keep_frames=True, message="noise stack, solar simulator on"))
        steps += [CaptureStep(_solar_step(i), 0.0, s, s > 0.0, plan.solar_frames,
                              message=f"solar simulator at {s:g} sun")
                  for i, s in enumerate(_solar_levels(plan))]
    steps.append(mount(None, "mount the test object again"))
    return CapturePlan(tuple(steps))


def split_after_settling(plan: CapturePlan) -> tuple[CapturePlan, CapturePlan]:
    """``plan`` up to its settling stage's frames at rest, and the rest (with the plan's
    ``restore`` mount): the service fits the table's ringing in between and waits it out after
    every later move (:func:`service.lab.acquisition.run_rig_calibration`). A plan without a
    settling stage: nothing, then all of it."""
    names = [getattr(s, "name", None) for s in plan.steps]
    if SETTLING_STEPS[0] not in names:
        return CapturePlan(()), plan
    cut = names.index(SETTLING_STEPS[0]) + 1
    return CapturePlan(plan.steps[:cut]), CapturePlan(plan.steps[cut:], plan.restore)


def _warmup_steps(plan: RigCalibrationPlan, spec: SceneSpec) -> list[Step]:
    """Step 0: the first fixture mounted, nothing moves, captures from power-on with the plan's
    waits between them (:mod:`calibration.rig_warmup`); none with ``warmup_captures`` 0."""
    if plan.warmup_captures == 0:
        return []
    steps: list[Step] = [_mount_board(plan, plan.fixtures[0], spec)]
    for i in range(plan.warmup_captures):
        if i > 0:
            steps.append(WaitStep(plan.warmup_interval_s,
                                  f"warm-up: waiting {plan.warmup_interval_s:g} s"))
        # The first capture follows the move to the warm-up's angle, before the settling
        # stage has measured how the table rings: it waits as the settling stage's frames at
        # rest do (a board still swinging moves the patch's range: the rig sweep's reality 204,
        # 0.7 deg at 4 Hz, put its first capture 4-7 std off the drift's line).
        steps.append(CaptureStep(_warmup_step(i), WARMUP_ANGLE_DEG, 0.0, False,
                                 plan.warmup_frames, keep_frames=True,
                                 message=f"warm-up capture {i + 1} of {plan.warmup_captures}",
                                 rest_s=SETTLING_REST_WAIT_S if i == 0 else 0.0))
    return steps


def _settling_steps(plan: RigCalibrationPlan, spec: SceneSpec) -> list[Step]:
    """The settling stage (:mod:`calibration.rig_settling`): the first fixture's board (mounted
    here unless the warm-up has mounted it), one move and frames at once after it, NOT waiting
    for the table to settle; then, after :data:`SETTLING_REST_WAIT_S`, frames of the board at
    rest at the same angle (the board's pixels and its yaw noise where the ringing was seen);
    none with ``settling_frames`` 0."""
    if plan.settling_frames == 0:
        return []
    steps: list[Step] = [] if plan.warmup_captures else [
        _mount_board(plan, plan.fixtures[0], spec)]
    angle = WARMUP_ANGLE_DEG + plan.settling_move_deg
    return [*steps,
            CaptureStep(SETTLING_STEPS[1], angle, 0.0, False, plan.settling_frames,
                        keep_frames=True, settle=False,
                        message="settling: frames right after a move, the table not waited "
                                "for"),
            WaitStep(SETTLING_REST_WAIT_S, f"settling: waiting {SETTLING_REST_WAIT_S:g} s for "
                     "the table to come to rest"),
            CaptureStep(SETTLING_STEPS[0], angle, 0.0, False, plan.settling_rest_frames,
                        keep_frames=True, message="settling: the board at rest")]


def _mount_board(plan: RigCalibrationPlan, fixture: BoardFixture, spec: SceneSpec) -> MountStep:
    return mount([board_object(plan.board, fixture, spec)],
                 f"mount the calibration board in {fixture.instruction}")


def _solar_levels(plan: RigCalibrationPlan) -> list[float]:
    """The solar simulator's levels of step 7: the shutter closed, then the plan's levels."""
    return [0.0, *plan.solar_levels_suns]


def fit_rig_calibration(
    captures: Captures,
    spec: SceneSpec,
    base_dir: str | Path,
    plan: RigCalibrationPlan,
    use_case: CameraUseCase,
    progress: Progress = no_progress,
    rig_name: str = "rig",
) -> RigCalibration:
    """Steps 0-7 of the module docstring from the captures of :func:`rig_capture_plan`.

    ``spec`` is the nominal scene (camera pose, turntable, solar simulator); ``use_case`` the
    camera's use case the frames were taken in. Progress is reported with every capture done.
    """
    from calibration.board_detection import detect_board
    from calibration.board_views import BoardView

    base = Path(base_dir)
    camera = build_camera(spec)
    done = total = len(captures)
    frames_used = sum(c.n_frames for c in captures.values())

    # 1. board views ---------------------------------------------------------------------
    views: list[tuple[BoardView, AveragedCapture, BoardFixture]] = []
    missed: list[dict[str, str]] = []
    for fixture in plan.fixtures:
        board = board_object(plan.board, fixture, spec)
        for i, angle in enumerate(plan.sweep_deg):
            cap = captures[_board_step(fixture, i)]
            det = detect_board(cap.amplitude, board.mesh)
            name = f"{fixture.name}@{angle:+.0f}"
            if det is None:
                missed.append({"name": name, "reason": "board not detected"})
                continue
            views.append((BoardView(name=name, turntable_angle_deg=cap.turntable_angle_deg,
                                    mounting=fixture.name, object_points_m=det.object_points_m,
                                    image_points_px=det.image_points_px,
                                    corner_ids=det.corner_ids, image_shape=cap.shape),
                          cap, fixture))
    results: dict[str, Any] = {"views": {"used": len(views), "not_detected": missed}}

    # 5 first: the noise model every other step's residual is judged against ---------------
    progress(done, total, "noise and gain")
    stacks = [captures[n] for n in NOISE_STEPS if n in captures]
    stack = stacks[0]
    noise = _noise(stacks)
    results["noise"] = noise
    # The peer paper's mean-variance fit on the same stacks, reported as a cross-check.
    results["noise_mean_variance"] = _noise_mean_variance(stacks)

    # 2. intrinsics, 3. turntable axis (camera and turntable adjusted together) -------------
    progress(done, total, "intrinsics and turntable")
    free, intr, axis = _camera_and_turntable(views, plan, spec, camera)
    # The detector's own bias, measured on the twin's renders of the same views, removed.
    measured_views = views
    for round_ in range(DEBIAS_ROUNDS):
        progress(done, total, f"corner bias by synthesis, round {round_ + 1}")
        views, corner_bias_px = _debias(measured_views, intr, spec, base, plan, camera)
        free, intr, axis = _camera_and_turntable(views, plan, spec, camera)
    # Views the model cannot explain against the corners' noise: dropped when they are few.
    corner_std = {v.name: corner_std_px(v, cap, noise) for v, cap, _ in views}
    stage = reprojection_stage(axis, corner_std)
    bad, droppable = unexplained_views(stage["per_view"])
    results["views"]["unexplained"] = [
        {"name": n, "reason": f"reprojection reduced chi-square {stage['per_view'][n]:.3g} "
                              "against the corners' noise: the model does not explain it"}
        for n in bad]
    if bad and droppable:
        progress(done, total, "intrinsics and turntable without the views not explained")
        views = [t for t in views if t[0].name not in set(bad)]
        free, intr, axis = _camera_and_turntable(views, plan, spec, camera)
        stage = reprojection_stage(axis, corner_std)
        results["views"]["used"] = len(views)
    results["intrinsics"] = intr
    results["views"]["corner_bias_rms_px"] = corner_bias_px
    progress(done, total, "turntable settling")
    settle = _settling(captures, plan, intr.intrinsics)
    rest_after_move = _rest_after_move(settle)
    rest_after_move_s = None if rest_after_move is None else SETTLING_REST_WAIT_S
    results["settling"] = {**settle.summary, "rest_after_move_s": rest_after_move_s}
    results["turntable"] = axis
    progress(done, total, "spread over the fixtures")
    spread = _fixture_jackknife(views, plan, spec, camera, intr, axis)
    results["reprojection"] = {
        "free_pose_reduced_chi2": free_stage_chi2(free, corner_std),
        "joint_reduced_chi2": stage["chi2"],
        "corner_std_median_px": _finite_median(corner_std.values()),
        "per_view_reduced_chi2": stage["per_view"], "fixture_spread": spread}
    # 0. the warm-up drift, removed from the depth fit's phases at each capture's temperature
    progress(done, total, "warm-up drift")
    warm = _warmup(captures, plan)
    results["warmup"] = warm.summary

    partial = TwinParameters(
        camera=CameraParameters(**_camera_keys(intr), sensor=noise.to_sensor_overrides()),
        turntable=_turntable_keys(axis),
    )
    first = plan.fixtures[0]
    board0 = board_object(plan.board, first, spec)
    twin_spec = mounted_spec(spec, [board0], use_case)
    # 6. effective source power ------------------------------------------------------------
    progress(done, total, "source power")
    nominal_power = spec.illumination.power_w
    pred = predict_view(twin_spec, base, partial, stack.turntable_angle_deg)
    shifted = _image_shifted_predictions(twin_spec, base, partial, stack.turntable_angle_deg)
    amplitude, modes = _power_prediction(pred, shifted)
    power = fit_source_power(stack.amplitude, amplitude, nominal_power, image_shift_modes=modes)
    results["photometry"] = power
    # 7. solar simulator, and the camera's stray light from the same frames ------------------
    solar, stray = None, None
    stray_verdicts = STRAY_LIGHT_NOT_MEASURED
    if spec.ambient.solar_simulator is not None:
        progress(done, total, "solar simulator scale")
        caps = [captures[_solar_step(i)] for i in range(len(_solar_levels(plan)))]
        sun1 = _solar_prediction(caps, twin_spec, base, partial, power.power_w)
        solar = fit_solar_scale(*_solar_inputs(plan, caps), _intensity_at(sun1),
                                reference_cell_suns=plan.solar_reference_suns)
        if solar.method == "frames":
            progress(done, total, "stray light")
            stray = _solar_stray_light(plan, caps, sun1, solar)
            if stray.significant:
                # The source power's white squares lose the stray light's share too: the power
                # again, through the optics as fitted.
                optics = stray.stray_light()
                amplitude, modes = _power_prediction(
                    pred.with_stray_light(optics), [p.with_stray_light(optics) for p in shifted])
                power = fit_source_power(stack.amplitude, amplitude, nominal_power,
                                         image_shift_modes=modes)
                results["photometry"] = power
            results["stray_light"] = stray
            stray_verdicts = dict(stray.verdicts().items())
            if stray.significant:
                solar = stray.solar_result()
        else:
            stray_verdicts = {key: Verdict(
                "not determined", None, "the stray light is measured from the solar stage's "
                "frames, which do not determine the solar scale here: no key written")
                for key in STRAY_LIGHT_NOT_MEASURED}
        results["solar"] = solar
    # 4. depth errors, last: from the board views with the warm-up drift and the stray light,
    # as calibrated, taken out (the stray light pulls the board's depth towards its
    # surroundings', a bias shared by every view that the depth model would otherwise absorb)
    progress(done, total, "depth errors")
    depth = _depth(views, intr, plan, use_case.frequencies_hz, noise, warm.temperature,
                   stray.stray_light() if stray is not None and stray.significant else None)
    results["depth"] = depth
    progress(total, total, "done")

    cal = CalibrationFile(
        camera=CameraParameters(**_camera_keys(intr), depth=depth.depth_errors,
                                sensor=noise.to_sensor_overrides(),
                                temperature=warm.temperature,
                                stray_light=stray.stray_light_key()
                                if stray is not None and stray.significant else None),
        illumination=IlluminationParameters(power_w=power.power_w),
        turntable=_turntable_keys(axis, settle.settling, rest_after_move_s),
        solar_simulator=SolarParameters(irradiance_scale=solar.irradiance_scale)
        if solar is not None else SolarParameters(),
        provenance=Provenance(
            created_utc=dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            rig=rig_name, software=f"toftwin {_version()}", frames_used=frames_used,
            procedures=procedure_summaries(results),
        ),
    )
    evidence = CameraTurntableEvidence(
        stage=StageEvidence(stage["chi2"], "the joint adjustment of camera and turntable "
                            "(corner reprojection)",
                            tuple(bad) if bad and not droppable else ()),
        std=stage["std"], spread=spread, basis=axis.basis, fx_px=intr.intrinsics.fx_px,
        fy_px=intr.intrinsics.fy_px, corner_radius=corner_radius(views, intr))
    keys = calibration_keys(cal)
    effects = {**warm.verdicts, **settle.verdicts, **stray_verdicts,
               **({} if rest_after_move is None else {REST_AFTER_MOVE_KEY: rest_after_move})}
    verdicts = rig_verdicts(keys, evidence,
                            depth_evidence(depth, use_case.frequencies_hz,
                                           _drift_carried(warm, views, use_case.frequencies_hz)),
                            {**other_verdicts(noise, power, solar), **effects})
    # the effects' keys not written (not determined), judged all the same: verdicts.json says
    # why the file has no such key
    verdicts.update_from({k: v for k, v in effects.items() if k not in keys})
    verdicts = depth_through_drift(verdicts)
    return RigCalibration(cal, results, [v for v, _, _ in views], frames_used, verdicts)


#: the principal point's step for the source power's image-shift modes [px]: a few times the
#: calibration's error, small enough for the amplitude to change linearly
SHIFT_MODE_STEP_PX = 0.25


def _image_shifted_predictions(twin_spec, base, partial: TwinParameters, angle_deg: float):
    """The power view predicted with the image moved by :data:`SHIFT_MODE_STEP_PX` along x and
    along y (the principal point moved; the same render seed, so the render noise cancels in
    the difference): :func:`calibration.photometry.fit_source_power`'s image-shift modes."""
    cam = partial.camera
    return [predict_view(twin_spec, base, partial.model_copy(update={"camera": cam.model_copy(
        update={name: getattr(cam, name) + SHIFT_MODE_STEP_PX})}), angle_deg)
        for name in ("cx_px", "cy_px")]


def _power_prediction(pred, shifted) -> tuple[np.ndarray, list[np.ndarray]]:
    """The power view's predicted amplitude [DN] and its change for each image shift (each
    prediction exposed once)."""
    a = pred.frame().image.amplitude
    return a, [p.frame().image.amplitude - a for p in shifted]


def _solar_prediction(caps, twin_spec, base, partial: TwinParameters, power_w: float):
    """The twin's view of the solar stage at 1 sun, with the calibrated camera, turntable and
    ``power_w``, without stray light."""
    lit = TwinParameters(camera=partial.camera, turntable=partial.turntable,
                         illumination=IlluminationParameters(power_w=power_w))
    return predict_view(twin_spec, base, lit, caps[0].turntable_angle_deg, solar_suns=1.0)


def _solar_inputs(plan, caps):
    """The solar stage's levels, mean intensities and their standard errors."""
    return (_solar_levels(plan), [c.intensity for c in caps],
            [c.intensity_std / np.sqrt(c.n_frames) for c in caps])


def _solar_stray_light(plan, caps, sun1, solar: SolarScaleResult) -> SolarStrayLightFit:
    """The solar scale, the camera's own light and the stray light together
    (:mod:`calibration.solar_stray_light`) against ``sun1`` (the scale's own prediction), on
    the pixels the scale alone used, from its scale."""
    levels, meas, std = _solar_inputs(plan, caps)
    meas, std, use = response_pixels(levels, meas, std, _intensity_at(sun1))
    return fit_solar_stray_light(levels, meas, std, use, sun1, solar.irradiance_scale)


def _intensity_at(prediction):
    """``true_suns -> `` the prediction's noise-free intensity [DN]."""
    return lambda true_suns: prediction.frame(ambient_scale=true_suns).raw.intensity.astype(float)


def _finite_median(arrays) -> float | None:
    """The median of the arrays' finite values; None when there is none."""
    values = np.concatenate([np.ravel(a) for a in arrays]) if arrays else np.zeros(0)
    values = values[np.isfinite(values)]
    return float(np.median(values)) if values.size else None


def _version() -> str:
    try:
        return metadata.version("toftwin")
    except metadata.PackageNotFoundError:  # pragma: no cover - running from a checkout
        return "unknown"

# -- the procedures' adapters (one place that knows each procedure's API) ---------------------
def _intrinsics(views, camera):
    from calibration.intrinsics import calibrate_intrinsics

    return calibrate_intrinsics([v for v, _, _ in views], camera.intrinsics.shape)

def _debias(views, intr, spec, base, plan, camera):
    from calibration.corner_bias import debias_views

    fixed, rms = debias_views([v for v, _, _ in views], intr, spec, base, plan.board,
                              camera.world_from_camera)
    by_name = {v.name: v for v in fixed}
    return [(by_name[v.name], cap, f) for v, cap, f in views if v.name in by_name], rms


def _camera_keys(intr) -> dict[str, Any]:
    k = intr.intrinsics
    d = k.distortion
    return {"fx_px": k.fx_px, "fy_px": k.fy_px, "cx_px": k.cx_px, "cy_px": k.cy_px,
            "distortion": {"k1": d[0], "k2": d[1], "p1": d[2], "p2": d[3], "k3": d[4]}}

def _camera_and_turntable(views, plan, spec, camera):
    """OpenCV's free-pose calibration as the start, then one bundle adjustment of the camera
    and the turntable model together (:func:`calibration.turntable_axis.fit_turntable_axis`):
    the free-pose result, and the intrinsics result carrying the adjusted intrinsics and the
    model's poses, and the adjustment's."""
    import dataclasses

    free = _intrinsics(views, camera)
    axis = _joint_adjustment(views, plan, spec, camera, free.poses, free.intrinsics)
    intr = dataclasses.replace(free, intrinsics=axis.intrinsics, poses=axis.poses,
                               rms_px=axis.reprojection_rms_px, refined_with_turntable=True)
    return free, intr, axis


def _joint_adjustment(views, plan, spec, camera, poses, intrinsics):
    from calibration.turntable_axis import fit_turntable_axis

    known = {f.name: world_from_board(plan.board, f, spec) for f in plan.fixtures}
    tt = spec.turntable
    return fit_turntable_axis([v for v, _, _ in views], poses, camera.world_from_camera,
                              known, tt.axis_point_m if tt else (0.0, 0.0, 0.0),
                              tt.axis_direction if tt else (0.0, 0.0, 1.0),
                              intrinsics=intrinsics, refine_intrinsics=True)


def _fixture_jackknife(views, plan, spec, camera, intr, axis) -> dict[str, float]:
    """The joint adjustment's parameters' spread over the fixtures: each fixture's views left
    out in turn (started at the full solution), the delete-one-group jackknife's standard
    deviation by parameter name (:func:`calibration.rig_verdicts.jackknife_std`); empty with a
    single fixture (no spread to measure)."""
    from calibration.turntable_axis import CAMERA_PARAMETERS

    fixtures = sorted({f.name for _, _, f in views})
    if len(fixtures) < 2:
        return {}
    basis = np.asarray(axis.basis)
    rows = []
    for name in fixtures:
        rest = [t for t in views if t[2].name != name]
        try:
            ax = _joint_adjustment(rest, plan, spec, camera, intr.poses, intr.intrinsics)
        except InvalidInputError:  # too few angles without it: no spread from this one
            continue
        k = ax.intrinsics
        cam = [k.fx_px, k.fy_px, k.cx_px, k.cy_px, *k.distortion[:4]]
        da = ax.axis_direction - axis.axis_direction
        dc = ax.axis_point_m - axis.axis_point_m
        rows.append([*(basis @ da), *(basis @ dc), ax.zero_offset_deg, *cam])
    if len(rows) < 2:
        return {}
    names = ["axis_u", "axis_v", "point_u", "point_v", "zero_offset_deg", *CAMERA_PARAMETERS]
    return {n: float(s) for n, s in zip(names, jackknife_std(rows), strict=True)}


def _turntable_keys(axis, settling=None, rest_after_move_s=None) -> TurntableParameters:
    return TurntableParameters(axis_point_m=tuple(float(v) for v in axis.axis_point_m),
                               axis_direction=tuple(float(v) for v in axis.axis_direction),
                               zero_offset_deg=float(axis.zero_offset_deg), settling=settling,
                               rest_after_move_s=rest_after_move_s)


def _rest_after_move(settle) -> Verdict | None:
    """``turntable.rest_after_move_s``'s verdict when the settling stage saw the table ring
    without determining how (:func:`calibration.rig_settling.unknown_ringing`): every later
    capture after a move, the calibration's own and every campaign's, rests
    :data:`SETTLING_REST_WAIT_S`; None otherwise (no key)."""
    from calibration.rig_settling import unknown_ringing

    why = unknown_ringing(settle)
    if why is None:
        return None
    return Verdict("determined", None, (
        f"a wait, not a fit: {why}; every capture after a move rests as long as the settling "
        f"stage's frames at rest did ({SETTLING_REST_WAIT_S:g} s), by which its board's yaw "
        "was at its noise"))


def _settling(captures: Captures, plan: RigCalibrationPlan, intrinsics):
    """The settling stage (:func:`calibration.rig_settling.fit_rig_settling`) at the calibrated
    intrinsics; a plan without it determines no settling."""
    from calibration.rig_settling import fit_rig_settling, no_settling

    if plan.settling_frames == 0 or not all(n in captures for n in SETTLING_STEPS):
        return no_settling("the plan has no settling stage (settling_frames 0)")
    return fit_rig_settling(captures[SETTLING_STEPS[0]], captures[SETTLING_STEPS[1]],
                            intrinsics)

def _depth(views, intr, plan, frequencies_hz, noise=None, temperature=None, stray=None):
    from calibration.captures import without_stray_light
    from calibration.depth import depth_views_from_captures, fit_depth_errors

    board = ObjectSpec.model_validate({"name": "b", "mesh": plan.board}).mesh
    caps = [(v, cap if stray is None else without_stray_light(cap, stray)) for v, cap, _ in views]
    dviews = depth_views_from_captures(intr, caps, board, noise, temperature)
    return fit_depth_errors(dviews, frequencies_hz)


def _drift_carried(warm, views, frequencies_hz) -> list[float] | None:
    """The drift coefficient's error carried into the depth model
    (:func:`calibration.rig_evidence.drift_carried_std_rad`) over the board views' reported
    temperatures; None when no drift was removed from them."""
    temps = [cap.illumination_temperature_c for _, cap, _ in views
             if cap.illumination_temperature_c is not None]
    if warm.temperature is None or warm.fit is None or not temps:
        return None
    rise = float(np.mean(temps)) - warm.temperature.illumination_start_c
    return drift_carried_std_rad(frequencies_hz, warm.fit.drift_std_mm_per_c, rise)


def _warmup(captures: Captures, plan: RigCalibrationPlan):
    """Step 0 (:func:`calibration.rig_warmup.fit_rig_warmup`) from the warm-up captures; a plan
    without them determines no drift."""
    from calibration.rig_warmup import fit_rig_warmup, no_warmup

    caps = [captures[_warmup_step(i)] for i in range(plan.warmup_captures)
            if _warmup_step(i) in captures]
    if len(caps) < plan.warmup_captures or not caps:
        return no_warmup("the plan has no warm-up stage (warmup_captures 0)" if not caps else
                         f"{len(caps)} of the plan's {plan.warmup_captures} warm-up captures")
    return fit_rig_warmup(caps, plan.warmup_times_s)


def _noise(stacks: list[AveragedCapture]):
    from calibration.noise_gain import calibrate_noise

    return calibrate_noise([list(s.frames) for s in stacks])

def _noise_mean_variance(stacks: list[AveragedCapture]) -> dict[str, Any]:
    """The mean-variance fit's summary, or why the stacks do not determine it."""
    from calibration.mean_variance import calibrate_mean_variance

    try:
        return calibrate_mean_variance([list(s.frames) for s in stacks]).summary()
    except InvalidInputError as exc:
        return {"determined": False, "reason": str(exc)}


def procedure_summaries(results: dict[str, Any]) -> dict[str, dict]:
    """Each procedure's result as plain JSON (the calibration file's provenance)."""
    out: dict[str, dict] = {}
    for name, r in results.items():
        if hasattr(r, "summary"):
            out[name] = _plain(r.summary())
        elif hasattr(r, "to_dict"):
            out[name] = _plain(r.to_dict())
        elif isinstance(r, dict):
            out[name] = _plain(r)
    return out

def _plain(x: Any) -> Any:
    """Plain, finite JSON values (arrays to lists, NaN/inf to None)."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if np.isfinite(v) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (str, int, bool)) or x is None:
        return x
    return str(x)
