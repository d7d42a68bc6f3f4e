"""Acquisition: the one way a calibration's captures are taken on the rig.

Calibration procedures are a plan and a fit (:mod:`calibration.capture_plan`): the plan says
what to mount and which rig states to capture, the fit takes the averaged captures. This module
runs any plan on the rig (:func:`acquire`: the operator mounts, the rig moves, checks where it
is and captures, the frames are averaged by :func:`calibration.captures.average_frames`), with
progress and the stop check in one place; and, for each procedure, the plan -> acquire -> fit in
one call, for the command line (``toftwin calibrate ...``) and the service's calibration jobs
alike (and the object fit's captures, for ``toftwin fit-object`` and a campaign's object fit).
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from calibration.capture_plan import CapturePlan, Captures, CaptureStep, Operator, WaitStep
from calibration.captures import AveragedCapture, Progress, average_frames, no_progress
from calibration.rig_material import (
    DEFAULT_MODEL,
    MaterialCalibration,
    MaterialSweepPlan,
    fit_material_sweep,
    material_capture_plan,
)
from calibration.rig_sequence import (
    SETTLING_REST_WAIT_S,
    SETTLING_STEPS,
    RigCalibration,
    RigCalibrationPlan,
    fit_rig_calibration,
    rig_capture_plan,
    split_after_settling,
)
from calibration.rig_settling import fit_rig_settling, unknown_ringing
from calibration.verification import TwinComparison, compare_twins, comparison_capture_plan
from drivers.errors import DeviceInputError
from drivers.rig import Rig, RigState
from service.lab.settling import settled_moves, unsettled_moves
from sim_core.materials import Material
from sim_core.processed_depth import ProcessedDepthFrame
from sim_core.render import RenderSettings
from sim_core.scene import build_camera
from sim_core.scene_spec import SceneSpec
from sim_core.twin_file import TurntableParameters, TwinParameters

_log = logging.getLogger(__name__)

def acquire(
    rig: Rig,
    operator: Operator,
    plan: CapturePlan,
    progress: Progress = no_progress,
    *,
    total: int | None = None,
    settle_for: TwinParameters | None = None,
) -> dict[str, AveragedCapture]:
    """Run ``plan`` on ``rig``: its mounts by ``operator``, its waits by the rig
    (:meth:`drivers.rig.Rig.wait`: a real rig sleeps, the simulated lab advances its clock), its
    captures in order, every move waited out for ``settle_for``'s turntable settling
    (:func:`service.lab.settling.settled_moves`; None: the driver's own wait).

    Before each capture and each wait ``progress(done, total, step.message)`` is called
    (``done`` captures so far; ``total`` defaults to the plan's captures: a procedure whose
    fit reports further steps passes its own). That call is where a run stops: a callback
    that raises (a job's cancel or emergency stop, as the fits' progress does too) stops the
    acquisition before the next capture or wait. The plan's ``restore`` mount is done at the
    end, and also when a step fails or stops.

    Returns
    -------
    dict of str to AveragedCapture
        Each capture step's frames, averaged, keyed by the step's name, in the plan's order.

    Raises
    ------
    DeviceError
        The rig failed or was not in the planned state for an exposure (:meth:`Rig.apply`,
        :meth:`Rig.capture`).
    """
    total = plan.n_captures if total is None else total
    captures: dict[str, AveragedCapture] = {}
    try:
        with settled_moves(rig, settle_for):
            for step in plan.steps:
                if isinstance(step, CaptureStep):
                    progress(len(captures), total, step.message)
                    captures[step.name] = _capture(rig, step)
                elif isinstance(step, WaitStep):
                    progress(len(captures), total, step.message)
                    rig.wait(step.seconds)
                else:
                    operator.mount(step.objects, step.instruction)
    finally:
        if plan.restore is not None:
            operator.mount(plan.restore.objects, plan.restore.instruction)
    return captures


def _capture(rig: Rig, step: CaptureStep) -> AveragedCapture:
    target = RigState(step.turntable_angle_deg, step.solar_suns, step.shutter_open)
    with rig.hold():  # nobody moves the rig between the move and the exposure
        with contextlib.nullcontext() if step.settle else unsettled_moves(rig):
            rig.apply(target)
        if step.rest_s > 0.0:
            rig.wait(step.rest_s)
        # checked against the target for the whole exposure (Rig.capture)
        frames = rig.capture(step.frames, target=target)
    if any(isinstance(f, ProcessedDepthFrame) for f in frames):
        raise DeviceInputError(
            "camera_mode", "the camera streams royale's processed depth (camera mode 'depth'); "
            "calibrations and object fits measure its raw frames: run them with the camera in "
            "raw mode (TOFTWIN_CAMERA_MODE=raw, serve --camera-mode raw)")
    return average_frames(frames, keep_frames=step.keep_frames)


def run_rig_calibration(
    rig: Rig,
    operator: Operator,
    spec: SceneSpec,
    base_dir: str | Path,
    plan: RigCalibrationPlan | None = None,
    progress: Progress = no_progress,
    rig_name: str = "rig",
) -> RigCalibration:
    """``toftwin calibrate rig``: :func:`calibration.rig_sequence.rig_capture_plan`, acquired
    on ``rig``, fitted by :func:`calibration.rig_sequence.fit_rig_calibration`.

    ``spec`` is the nominal scene (camera pose, turntable, solar simulator); its mounted objects
    are swapped for the board during the sequence and mounted again at the end. The table's
    ringing, measured by the settling stage, is fitted as soon as its frames are in and waited
    out after every later move (:func:`calibration.rig_settling.unknown_ringing`): a lab
    that knows how its table rings does not capture the board sweep while it still does, and
    one that saw it ring without learning how rests after every later move as long as the
    settling stage's frames at rest did (:data:`calibration.rig_sequence.SETTLING_REST_WAIT_S`).
    """
    plan = plan or RigCalibrationPlan()
    capture_plan = rig_capture_plan(plan, spec)
    first, rest = split_after_settling(capture_plan)
    captures = acquire(rig, operator, first, progress, total=capture_plan.n_captures)
    fit = (fit_rig_settling(captures[SETTLING_STEPS[0]], captures[SETTLING_STEPS[1]],
                            build_camera(spec).intrinsics)
           if all(name in captures for name in SETTLING_STEPS) else None)
    # a determined ringing is waited out (service.lab.settling.settle_wait_s)
    settle_for = None if fit is None or fit.settling is None else TwinParameters(
        turntable=TurntableParameters(settling=fit.settling))
    why_rest = None if fit is None else unknown_ringing(fit)
    if why_rest is not None:  # rest as long as the settling stage's frames at rest did
        _log.warning("rig calibration: %s; every later move rests %g s", why_rest,
                     SETTLING_REST_WAIT_S)
        rest = rest.rested_after_moves(SETTLING_REST_WAIT_S,
                                       captures[SETTLING_STEPS[0]].turntable_angle_deg)
    done = len(captures)
    captures |= acquire(rig, operator, rest,
                        lambda k, n, text: progress(done + k, n, text),
                        total=capture_plan.n_captures, settle_for=settle_for)
    return fit_rig_calibration(captures, spec, base_dir, plan, rig.camera.use_case, progress,
                               rig_name)


def run_material_calibration(
    rig: Rig,
    operator: Operator,
    spec: SceneSpec,
    base_dir: str | Path,
    calibration: TwinParameters | None,
    plan: MaterialSweepPlan | None = None,
    model: str = DEFAULT_MODEL,
    prior: str | Mapping[str, Any] | Material | None = None,
    progress: Progress = no_progress,
    seed: int = 0,
) -> MaterialCalibration:
    """``toftwin calibrate material``: :func:`calibration.rig_material.material_capture_plan`
    (a bad model or prior fails before the rig moves), acquired on ``rig`` (the sample mounted
    by ``operator``, the test object mounted again even if a capture fails), fitted by
    :func:`calibration.rig_material.fit_material_sweep`; the parameters are theirs."""
    plan = plan or MaterialSweepPlan()
    capture_plan = material_capture_plan(spec, plan, model, prior)
    t0 = time.perf_counter()
    captures = acquire(rig, operator, capture_plan, progress, total=plan.n_steps,
                       settle_for=calibration)
    sweep_s = time.perf_counter() - t0
    result = fit_material_sweep(captures, spec, base_dir, calibration, plan,
                                rig.camera.use_case, model, prior, progress, seed)
    result.seconds = {"sweep": sweep_s, **result.seconds}
    return result


def run_twin_comparison(
    rig: Rig,
    spec: SceneSpec,
    base_dir: str | Path,
    calibration: TwinParameters,
    angles_deg: Sequence[float],
    solar_suns: float = 1.0,
    settings: RenderSettings | None = None,
    progress: Progress = no_progress,
) -> TwinComparison:
    """Does a calibration help? :func:`calibration.verification.comparison_capture_plan`
    acquired on ``rig`` (with what is mounted: no operator needed), compared by
    :func:`calibration.verification.compare_twins`."""
    plan = comparison_capture_plan(angles_deg, solar_suns)
    captures = acquire(rig, NO_MOUNTS, plan, progress, settle_for=calibration)
    return compare_twins(captures, spec, base_dir, calibration, angles_deg, settings, progress)


class NoMounts:
    """The operator of plans without mounts (what stands on the turntable stays)."""

    def mount(self, objects: Sequence[Any] | None, instruction: str) -> None:
        raise AssertionError(f"this plan mounts nothing, yet asked: {instruction}")


#: the operator of plans without mounts
NO_MOUNTS = NoMounts()

__all__ = ["NO_MOUNTS", "Captures", "acquire", "run_material_calibration", "run_rig_calibration",
           "run_twin_comparison"]
