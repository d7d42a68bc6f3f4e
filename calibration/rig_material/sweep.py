"""The material sweep: averaged captures of the sample at every planned angle.

The sweep's plan (:func:`sweep_capture_plan`, run on the rig by the service) turns the sample to
each angle and captures ``frames_per_state`` frames with the solar simulator's shutter closed
(the camera's light alone: the retro-reflection slice) and, when the plan has a solar level,
with it open (the solar slice, from the intensity's difference). :func:`sample_captures` groups
the captures by angle; the frames' spread gives each pixel's standard error.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calibration.capture_plan import CapturePlan, Captures, CaptureStep, Step, mount
from calibration.captures import AveragedCapture
from calibration.rig_material.plan import MaterialSweepPlan
from sim_core.scene_spec import ObjectSpec


@dataclass(frozen=True)
class SampleCaptures:
    """The sample at one reported turntable angle.

    Attributes
    ----------
    turntable_angle_deg : float
        The angle the rig reported.
    lamp : AveragedCapture
        The camera's light alone (solar simulator's shutter closed).
    amplitude_sem_dn : (H, W) float64
        Standard error of ``lamp.amplitude`` from the frames' spread [DN].
    solar : AveragedCapture or None
        With the solar simulator's shutter open at the plan's level.
    """

    turntable_angle_deg: float
    lamp: AveragedCapture
    amplitude_sem_dn: np.ndarray = field(repr=False)
    solar: AveragedCapture | None = None

    @property
    def solar_dc_dn(self) -> np.ndarray | None:
        """Intensity with the solar simulator minus without it [DN]."""
        return None if self.solar is None else self.solar.intensity - self.lamp.intensity

    @property
    def solar_dc_sem_dn(self) -> np.ndarray | None:
        """Standard error of :attr:`solar_dc_dn` [DN]."""
        if self.solar is None:
            return None
        return np.hypot(self.solar.intensity_std / np.sqrt(self.solar.n_frames),
                        self.lamp.intensity_std / np.sqrt(self.lamp.n_frames))


def amplitude_sem(capture: AveragedCapture) -> np.ndarray:
    """Standard error of the mean amplitude from the kept frames' amplitudes [DN]."""
    amps = np.stack([0.5 * np.abs(f.phasor()[0]) for f in capture.frames])
    return amps.std(axis=0, ddof=1) / np.sqrt(len(capture.frames))


def sweep_capture_plan(plan: MaterialSweepPlan, sample: ObjectSpec) -> CapturePlan:
    """Mount ``sample``, capture the plan's states at every angle (lamp only, then the solar
    simulator if planned), and mount the test object again (even when a capture fails)."""
    steps: list[Step] = [mount([sample], f"mount the {plan.size_m * 1e3:.0f} mm square sample "
                               "plate upright, centred on the axis at the camera's height, "
                               "facing the camera at the turntable's zero")]
    for i, angle in enumerate(plan.angles_deg):
        steps.append(CaptureStep(_lamp_step(i), angle, 0.0, False, plan.frames_per_state,
                                 keep_frames=True, message=f"sample at {angle:+.0f} deg"))
        if plan.with_solar:
            steps.append(CaptureStep(
                _solar_step(i), angle, plan.solar_suns, True, plan.frames_per_state,
                message=f"sample at {angle:+.0f} deg, solar simulator {plan.solar_suns:g} sun"))
    return CapturePlan(tuple(steps), restore=mount(None, "mount the test object again"))


def sample_captures(captures: Captures, plan: MaterialSweepPlan) -> list[SampleCaptures]:
    """The captures of :func:`sweep_capture_plan`, one entry per angle."""
    out = []
    for i in range(len(plan.angles_deg)):
        lamp = captures[_lamp_step(i)]
        solar = captures[_solar_step(i)] if plan.with_solar else None
        out.append(SampleCaptures(lamp.turntable_angle_deg, _drop_frames(lamp),
                                  amplitude_sem(lamp), solar))
    return out


def _lamp_step(index: int) -> str:
    return f"sample/{index}/lamp"


def _solar_step(index: int) -> str:
    return f"sample/{index}/solar"


def _drop_frames(capture: AveragedCapture) -> AveragedCapture:
    import dataclasses

    return dataclasses.replace(capture, frames=())
