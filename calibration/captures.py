"""Averaged captures on the rig: the raw material of every calibration procedure.

A calibration view is several frames of one static rig state, averaged: the mean of the phase
images (averaging the phasors, not the amplitudes, so noise adds no bias), the amplitude and
phases of that mean, the mean intensity and the frames' temporal standard deviation. Averaging
``n`` frames divides the noise of corners and depth by sqrt(n) (CALIBRATION-NOTES.md: what brings
the principal point under half a pixel). The individual frames are kept only where a procedure
needs them (the noise stacks).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from sim_core.errors import InvalidInputError
from sim_core.optics import StrayLight
from sim_core.raw import RawFrame, reconstruct_raw
from sim_core.tof import phase_from_phasor
from sim_core.twin_file import CameraTemperature
from sim_core.warmup import TemperatureDrift


@dataclass(frozen=True)
class AveragedCapture:
    """The mean of ``n_frames`` frames of one rig state.

    Attributes
    ----------
    turntable_angle_deg, solar_suns : float
        The state the rig reported.
    shutter_open : bool
    n_frames : int
    phase_images : (n_f, 4, H, W) float64
        Mean C_i per frequency and phase step [DN].
    intensity : (H, W) float64
        Mean intensity [DN].
    intensity_std : (H, W) float64
        Temporal standard deviation of the intensity over the frames [DN] (ddof 1).
    amplitude : (H, W) float64
        Amplitude of the mean phasor [DN] (seed eq. 5).
    phase_rad : (n_f, H, W) float64
        Phase of the mean phasor in [0, 2 pi) (seed eq. 4).
    valid : (H, W) bool
        Valid in every frame (not saturated, not in the SBI limit, enough amplitude).
    frequencies_hz : (n_f,) float64
    exposure_s : float
    frames : tuple of RawFrame
        The frames themselves, when kept (noise stacks).
    illumination_temperature_c : float or None
        The mean of the frames' reported illumination temperatures [degC] (None unless every
        frame reports one): the warm-up drift is linear in it (:mod:`sim_core.warmup`), so the
        mean phasor carries the drift at the mean temperature, to first order in its spread.
    """

    turntable_angle_deg: float
    solar_suns: float
    shutter_open: bool
    n_frames: int
    phase_images: np.ndarray = field(repr=False)
    intensity: np.ndarray = field(repr=False)
    intensity_std: np.ndarray = field(repr=False)
    amplitude: np.ndarray = field(repr=False)
    phase_rad: np.ndarray = field(repr=False)
    valid: np.ndarray = field(repr=False)
    frequencies_hz: np.ndarray = field(repr=False)
    exposure_s: float = 0.0
    frames: tuple[RawFrame, ...] = field(default=(), repr=False)
    illumination_temperature_c: float | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.intensity.shape


def average_frames(frames: list[RawFrame], keep_frames: bool = False) -> AveragedCapture:
    """Average frames of one rig state (see :class:`AveragedCapture`).

    Raises
    ------
    InvalidInputError
        No frames, or frames of different shapes, frequencies or exposures.
    """
    if not frames:
        raise InvalidInputError("frames", "no frames to average")
    first = frames[0]
    for i, f in enumerate(frames[1:], start=1):
        if (f.phase_images.shape != first.phase_images.shape
                or not np.allclose(f.frequencies_hz, first.frequencies_hz)
                or not np.isclose(f.exposure_s, first.exposure_s)):
            raise InvalidInputError(f"frames[{i}]", "differs from frame 0 in shape, modulation "
                                    "frequencies or exposure: one capture is one use case")
    c = np.mean([f.phase_images.astype(np.float64) for f in frames], axis=0)
    grey = np.stack([f.intensity.astype(np.float64) for f in frames])
    rig = first.meta.get("rig", {})
    mean = RawFrame(
        phase_images=c, intensity=grey.mean(axis=0), frequencies_hz=first.frequencies_hz,
        saturated=np.any([f.saturated for f in frames], axis=0),
        sbi_limit=np.any([f.sbi_limit for f in frames], axis=0), exposure_s=first.exposure_s,
    )
    # z/range does not matter here: only amplitude and phase are kept.
    img = reconstruct_raw(mean, np.ones(mean.shape))
    phasor = mean.phasor()
    return AveragedCapture(
        turntable_angle_deg=float(rig.get("turntable_angle_deg", np.nan)),
        solar_suns=float(rig.get("solar_suns", np.nan)),
        shutter_open=bool(rig.get("shutter_open", False)),
        n_frames=len(frames),
        phase_images=c,
        intensity=grey.mean(axis=0),
        intensity_std=grey.std(axis=0, ddof=1) if len(frames) > 1 else np.zeros(mean.shape),
        amplitude=img.amplitude,
        phase_rad=phase_from_phasor(phasor),
        valid=img.valid,
        frequencies_hz=np.asarray(first.frequencies_hz, dtype=np.float64),
        exposure_s=float(first.exposure_s),
        frames=tuple(frames) if keep_frames else (),
        illumination_temperature_c=_mean_temperature_c(frames),
    )


def without_stray_light(capture: AveragedCapture, stray: StrayLight) -> AveragedCapture:
    """The capture with the calibrated stray light taken out of its phasors
    (:meth:`sim_core.optics.StrayLight.remove` on each frequency's ``C0 - C2`` and ``C3 - C1``,
    each pair's sum kept), its amplitude and phase again from them (seed eqs. 4-5).

    The pixels' DN are proportional to the irradiance on the sensor, where the light scatters,
    so the images are unweighted. The camera's own phase errors act after the stray light
    (:func:`sim_core.pipeline.sensor_light`); a phase common to all pixels (offset, warm-up drift)
    commutes with it, the rest (wiggling, fixed pattern) only as far as it varies over the
    kernel: the stray light's share is removed to first order in that variation. The intensity,
    the noise's own measure, stays as measured."""
    c = np.asarray(capture.phase_images, dtype=np.float64)  # (n_f, 4, H, W)
    real = stray.remove(c[:, 0] - c[:, 2])
    imag = stray.remove(c[:, 3] - c[:, 1])
    mean02, mean13 = 0.5 * (c[:, 0] + c[:, 2]), 0.5 * (c[:, 3] + c[:, 1])
    cleaned = np.stack([mean02 + 0.5 * real, mean13 - 0.5 * imag, mean02 - 0.5 * real,
                        mean13 + 0.5 * imag], axis=1)
    phasor = real - 1j * imag
    return replace(capture, phase_images=cleaned, amplitude=0.5 * np.abs(phasor[0]),
                   phase_rad=phase_from_phasor(phasor))


def _mean_temperature_c(frames: list[RawFrame]) -> float | None:
    """The frames' mean illumination temperature [degC], None unless every frame reports a
    finite one."""
    temps = [f.illumination_temperature_c for f in frames]
    if any(t is None or not np.isfinite(t) for t in temps):
        return None
    return float(np.mean(temps))


def drift_free_phase_rad(capture: AveragedCapture,
                         temperature: CameraTemperature | None) -> np.ndarray:
    """(n_f, H, W) the capture's phases with the calibrated warm-up drift at its reported
    temperature removed (:meth:`sim_core.warmup.TemperatureDrift.remove_from_phase_rad`); the
    phases as measured without a calibrated drift or a reported temperature."""
    if temperature is None or capture.illumination_temperature_c is None:
        return capture.phase_rad
    drift = TemperatureDrift.from_spec(temperature, capture.frequencies_hz)
    return drift.remove_from_phase_rad(capture.phase_rad, capture.illumination_temperature_c)


#: ``progress(done, total, message)`` callbacks of the procedures
Progress = Callable[[int, int, str], None]


def no_progress(done: int, total: int, message: str) -> None:
    """A progress callback that does nothing."""
