"""Does a calibration help? The twin against the rig, with and without it, and the ceiling.

For a set of poses of the test object, each measured twice: the nominal twin (the scene as
designed) and the calibrated twin (the scene with the calibration applied) are compared with the
first capture (seed Table 5 metrics, :func:`sim_core.metrics.compare_images`), and the two
captures with each other: the *ceiling*, what no twin can beat because the camera's own noise
differs between two captures of the same scene. A good calibration brings the calibrated twin's
depth RMSE close to the ceiling's.

:func:`comparison_capture_plan` plans the captures (two frames per pose, kept), the service runs
it on the rig (:func:`service.lab.acquisition.run_twin_comparison`) and :func:`compare_twins`
compares what it is handed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibration.capture_plan import CapturePlan, Captures, CaptureStep
from calibration.captures import Progress, no_progress
from sim_core.camera import z_over_range
from sim_core.metrics import ComparisonReport, compare_images, mask_from_objects
from sim_core.pipeline import simulate
from sim_core.raw import reconstruct_raw
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import SceneSpec
from sim_core.twin_file import TwinParameters

#: the compared quantities: (name, attribute of ComparisonReport's rows)
METRICS = ("depth_rmse_mm", "depth_psnr_db", "grey_psnr_db", "grey_ssim")


@dataclass(frozen=True)
class TwinComparison:
    """Median metrics over the poses for the nominal twin, the calibrated twin and the ceiling.

    Attributes
    ----------
    poses : int
    nominal, calibrated, ceiling : dict
        ``depth_rmse_mm``, ``depth_psnr_db``, ``grey_psnr_db``, ``grey_ssim`` (medians).
    per_pose : list of dict
    """

    poses: int
    nominal: dict[str, float]
    calibrated: dict[str, float]
    ceiling: dict[str, float]
    per_pose: list[dict]

    @property
    def calibrated_over_ceiling(self) -> float:
        """Calibrated twin's depth RMSE over the ceiling's (1 = as good as a second capture)."""
        return self.calibrated["depth_rmse_mm"] / self.ceiling["depth_rmse_mm"]

    def to_dict(self) -> dict:
        return {"poses": self.poses, "nominal": self.nominal, "calibrated": self.calibrated,
                "ceiling": self.ceiling,
                "calibrated_over_ceiling": self.calibrated_over_ceiling}


def _metrics(report: ComparisonReport) -> dict[str, float]:
    d, g = report.depth, report.grey
    return {"depth_rmse_mm": float(np.sqrt(d.mse)), "depth_psnr_db": float(d.psnr_db),
            "grey_psnr_db": float(g.psnr_db), "grey_ssim": float(g.ssim)}


def _pose_step(index: int) -> str:
    return f"pose/{index}"


def comparison_capture_plan(angles_deg: Sequence[float], solar_suns: float = 1.0) -> CapturePlan:
    """Each pose captured twice (two frames, kept): the first against the twins, both for the
    ceiling."""
    return CapturePlan(tuple(
        CaptureStep(_pose_step(k), float(angle), solar_suns, solar_suns > 0.0, 2,
                    keep_frames=True, message=f"pose {k + 1} at {angle:+.0f} deg")
        for k, angle in enumerate(angles_deg)))


def compare_twins(
    captures: Captures,
    spec: SceneSpec,
    base_dir: str | Path,
    calibration: TwinParameters,
    angles_deg: Sequence[float],
    settings: RenderSettings | None = None,
    progress: Progress = no_progress,
) -> TwinComparison:
    """Compare each pose's captures of :func:`comparison_capture_plan` (module docstring).

    The comparison mask is the pixels the calibrated twin sees on the turntable's objects,
    inside both frames' valid pixels. The calibrated twin is simulated at the illumination
    temperature the first frame reports (its warm-up drift, issue 27).
    """
    settings = settings or RenderSettings(integrator="path", spp=spec.render.spp,
                                          max_bounces=spec.render.max_bounces)
    rows = []
    turntable_ids = [i for i, o in enumerate(spec.objects) if o.on_turntable]
    for k, angle in enumerate(angles_deg):
        progress(k, len(angles_deg), f"twins at pose {k + 1}")
        cap = captures[_pose_step(k)]  # the state the rig reported for its exposure
        first, second = cap.frames
        twins = {}
        for name, twin in (("nominal", None), ("calibrated", calibration)):
            # the calibrated twin drifts as the camera reported itself warm for this frame
            # (its ``camera.temperature``, if any); the nominal twin knows of no drift
            scene = build_scene(spec, base_dir, turntable_deg=cap.turntable_angle_deg,
                                solar_suns=cap.solar_suns if cap.shutter_open else 0.0,
                                twin=twin, illumination_temperature_c=(
                                    None if twin is None else first.illumination_temperature_c))
            frame = simulate(scene, RenderRequest(dataclasses.replace(settings, seed=1000 + k)))
            twins[name] = (scene, frame)
        scene, frame = twins["calibrated"]
        zr = z_over_range(scene.camera.intrinsics)
        a = reconstruct_raw(first, zr)
        b = reconstruct_raw(second, zr)
        mask = mask_from_objects(frame.light_field.object_id, turntable_ids)
        full = 2.0 ** (scene.sensor.adc_bits - 1)
        row = {"angle_deg": float(angle)}
        for name, (_, f) in twins.items():
            row[name] = _metrics(compare_images(a, f.image, mask, grey_full_scale=full))
        row["ceiling"] = _metrics(compare_images(a, b, mask, grey_full_scale=full))
        rows.append(row)
    progress(len(angles_deg), len(angles_deg), "done")

    def median(which: str) -> dict[str, float]:
        return {m: float(np.median([r[which][m] for r in rows])) for m in METRICS}

    return TwinComparison(len(rows), median("nominal"), median("calibrated"), median("ceiling"),
                          rows)
