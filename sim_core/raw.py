"""The raw frame: what a PMD camera reads out, measured or simulated (seed eq. 15).

Both the camera driver and the sensor model return this type, and
:func:`reconstruct_raw` turns either into a :class:`~sim_core.tof.ToFImage`, so measured and
simulated frames go through the very same reconstruction. ``raw.npz`` (the file form) is
written and read by :func:`sim_core.frame_io.write_raw` and :func:`sim_core.frame_io.read_raw`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from sim_core.tof import ToFImage, reconstruct

#: the four phase offsets of the reference signal, tau_i = i * pi / 2 (seed eq. 3)
PHASE_OFFSETS_RAD = np.array([0.0, 0.5 * np.pi, np.pi, 1.5 * np.pi])


@dataclass(frozen=True)
class RawFrame:
    """Four-phase correlation images for one or more modulation frequencies.

    Attributes
    ----------
    phase_images : (n_f, 4, H, W) float32
        C_i = C_iA - C_iB per phase step (seed eq. 15) in digital numbers (DN), signed.
    intensity : (H, W) float32
        Offset / grey value in DN: the mean tap sum over the phase steps (seed eq. 6) for a
        simulated frame, the camera's grey image for a measured one.
    frequencies_hz : (n_f,) float64
    saturated : (H, W) bool
        A tap hit full well or the ADC range in some phase step.
    sbi_limit : (H, W) bool
        The SBI circuit ran out of compensation (seed Fig. 7 "SBI limit"): pixel invalid.
    exposure_s : float
        Exposure per phase step.
    timestamp_s : float
        Capture time (seconds since the epoch) or 0 for a simulated frame.
    taps : (n_f, 4, 2, H, W) float32 or None
        Tap charges A and B in DN where the source exposes them (the simulator does).
    meta : dict
        The settings that produced the frame (sensor parameters, seed, device, use case).
    illumination_temperature_c : float or None
        The illumination's temperature the camera reported with the frame [degC] (royale's
        ``RawData.illuminationTemperature``; the simulated lab's warm-up, :mod:`sim_core.
        warmup`); None when the source reports none.
    """

    phase_images: np.ndarray
    intensity: np.ndarray
    frequencies_hz: np.ndarray
    saturated: np.ndarray
    sbi_limit: np.ndarray
    exposure_s: float
    timestamp_s: float = 0.0
    taps: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    illumination_temperature_c: float | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.intensity.shape

    def phasor(self) -> np.ndarray:
        """Complex correlation phasor per frequency, ``(C0 - C2) - 1j (C3 - C1)``, (n_f, H, W).

        For C_i = D a cos(tau_i + phi) this is ``2 D a exp(-1j phi)``: the argument gives the
        phase of seed eq. 4 with the right quadrant, half the magnitude its amplitude (eq. 5).
        """
        c = self.phase_images.astype(np.float64)
        return (c[:, 0] - c[:, 2]) - 1j * (c[:, 3] - c[:, 1])


@dataclass(frozen=True)
class ValidityThresholds:
    """When a reconstructed pixel is reported (the camera's validity mask).

    Attributes
    ----------
    min_amplitude_dn : float
        Pixels whose amplitude (seed eq. 5) is below this are invalid (too little signal for a
        phase). With no signal the amplitude of read noise alone is Rayleigh-distributed with a
        scale of read noise / gain = 2.5 DN for the default sensor (25 e- read noise,
        10 e-/DN), so 15 DN (6 scales) lets a dark pixel through with probability
        exp(-18) ~ 1.5e-8.
    """

    min_amplitude_dn: float = 15.0

    def to_dict(self) -> dict:
        return asdict(self)


def reconstruct_raw(
    raw: RawFrame, z_over_range: np.ndarray, thresholds: ValidityThresholds | None = None
) -> ToFImage:
    """Range, amplitude and intensity of a raw frame (seed eqs. 4-7, 15).

    ``z_over_range`` converts radial range to z-depth per pixel (from the camera intrinsics).
    Amplitude is in DN: half the magnitude of the correlation phasor, a = |C3-C1, C0-C2| / 2.
    """
    th = thresholds or ValidityThresholds()
    phasor = raw.phasor()
    amplitude = 0.5 * np.abs(phasor[0])
    valid = (amplitude >= th.min_amplitude_dn) & ~raw.saturated & ~raw.sbi_limit
    img = reconstruct(
        phasor=phasor,
        intensity=raw.intensity.astype(np.float64),
        frequencies_hz=raw.frequencies_hz,
        z_over_range=z_over_range,
        valid=valid,
    )
    return ToFImage(
        range_m=img.range_m, depth_z_m=img.depth_z_m, amplitude=amplitude,
        intensity=img.intensity, phase_rad=img.phase_rad, valid=img.valid,
        frequencies_hz=img.frequencies_hz,
    )
