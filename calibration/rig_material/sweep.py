"""The material sweep on the rig: averaged captures of the sample at every planned angle.

The rig turns the sample to each angle and captures ``frames_per_state`` frames with the solar
simulator's shutter closed (the camera's light alone: the retro-reflection slice) and, when the
plan has a solar level, with it open (the solar slice, from the intensity's difference). The
frames' spread gives each pixel's standard error.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calibration.captures import AveragedCapture, Progress, average_frames, no_progress
from calibration.rig_material.plan import MaterialSweepPlan
from drivers.rig import Rig, RigState


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


def capture_sweep(rig: Rig, plan: MaterialSweepPlan, progress: Progress = no_progress,
                  done: int = 0, total: int | None = None) -> list[SampleCaptures]:
    """Capture the plan's states (the sample must be mounted); one entry per angle."""
    total = plan.n_captures if total is None else total
    out = []
    for angle in plan.angles_deg:
        caps: list[AveragedCapture] = []
        for state in plan.states(angle):
            progress(done, total, f"sample at {angle:+.0f} deg"
                     + (f", solar simulator {state.solar_suns:g} sun" if state.shutter_open
                        else ""))
            caps.append(_capture(rig, state, plan.frames_per_state))
            done += 1
        lamp = caps[0]
        out.append(SampleCaptures(lamp.turntable_angle_deg, _drop_frames(lamp),
                                  amplitude_sem(lamp),
                                  _drop_frames(caps[1]) if len(caps) > 1 else None))
    return out


def _capture(rig: Rig, state: RigState, n: int) -> AveragedCapture:
    rig.apply(state)
    return average_frames(rig.capture(n, target=state), keep_frames=True)


def _drop_frames(capture: AveragedCapture) -> AveragedCapture:
    import dataclasses

    return dataclasses.replace(capture, frames=())
