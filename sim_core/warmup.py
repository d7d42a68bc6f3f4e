"""The illumination's warm-up and the depth drift it causes (issue 27; the file's
``camera.temperature``, :class:`sim_core.twin_file.CameraTemperature`).

After power-on the camera's illumination warms from ``T_start`` towards ``T_end`` along a first-
order (exponential) curve with time constant ``tau``:

    T(t) = T_end + (T_start - T_end) exp(-t / tau)

and every modulation frequency's phase drifts linearly with the temperature above the start,
TI's calibration model of a ToF camera's temperature dependence (a phase offset linear in the
illumination temperature, per modulation frequency). A range change ``d = k_f (T - T_start)``
[``k_f`` in mm/degC] is the phase offset ``phi = 4 pi f d / c`` (seed eq. 7 inverted:
:func:`sim_core.depth_errors.range_to_phase_rad`), added where the camera's other phase errors
are (:mod:`sim_core.depth_errors`, after the optics, before the sensor).

The simulated lab computes ``T(t)`` on its own clock and reports it with every raw frame, as
royale's ``RawData.illuminationTemperature`` does; the twin applies the drift at each measured
frame's reported temperature.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_core.depth_errors import range_to_phase_rad
from sim_core.errors import InvalidInputError
from sim_core.twin_file import CameraTemperature

__all__ = ["TemperatureDrift", "illumination_temperature_c"]


def illumination_temperature_c(elapsed_s: float, spec: CameraTemperature) -> float:
    """The illumination's temperature ``elapsed_s`` after the service's start [degC].

    ``T_end + (T_start - T_end) exp(-t / tau)``; ``tau > 0`` is the file's rule, so the
    exponent is finite and non-positive for every ``t >= 0`` (it underflows to 0: T_end).

    >>> spec = CameraTemperature(illumination_start_c=25, illumination_end_c=45,
    ...                          time_constant_s=600, depth_drift_mm_per_c=0.4)
    >>> illumination_temperature_c(0.0, spec), round(illumination_temperature_c(600.0, spec), 3)
    (25.0, 37.642)
    """
    t = float(elapsed_s)
    if not (math.isfinite(t) and t >= 0.0):
        raise InvalidInputError("elapsed_s", f"{elapsed_s!r} is not a finite time >= 0 s")
    decay = math.exp(-t / spec.time_constant_s)
    return spec.illumination_end_c + (spec.illumination_start_c - spec.illumination_end_c) * decay


@dataclass(frozen=True)
class TemperatureDrift:
    """The depth drift of one camera for a use case's frequencies.

    Attributes
    ----------
    start_c : float
        Temperature at which the drift is zero (the illumination's start) [degC].
    drift_mm_per_c : (n_f,) float
        Range drift per degree above the start, per modulation frequency [mm/degC].
    frequencies_hz : (n_f,) float
    """

    start_c: float
    drift_mm_per_c: np.ndarray
    frequencies_hz: np.ndarray

    @classmethod
    def from_spec(cls, spec: CameraTemperature, frequencies_hz) -> TemperatureDrift:
        """The drift of a file's ``camera.temperature`` for a use case's frequencies: one
        number applies to all of them, a list gives one per frequency in the use case's order."""
        freqs = np.asarray(frequencies_hz, dtype=np.float64).reshape(-1)
        drift = list(spec.depth_drift_mm_per_c)
        if len(drift) == 1:
            per_f = np.full(freqs.size, drift[0])
        elif len(drift) == freqs.size:
            per_f = np.asarray(drift, dtype=np.float64)
        else:
            raise InvalidInputError(
                "camera.temperature.depth_drift_mm_per_c",
                f"has {len(drift)} entries for {freqs.size} modulation frequencies; give one "
                "per frequency or a single one for all")
        return cls(float(spec.illumination_start_c), per_f, freqs)

    def range_drift_m(self, temperature_c: float) -> np.ndarray:
        """The range added at each frequency at ``temperature_c``, ``k_f (T - T_start)`` [m]."""
        t = float(temperature_c)
        if not math.isfinite(t):
            raise InvalidInputError("illumination_temperature_c", f"{temperature_c!r} is not "
                                    "a finite temperature")
        return self.drift_mm_per_c * 1e-3 * (t - self.start_c)

    def phase_offset_rad(self, temperature_c: float) -> np.ndarray:
        """The phase offset at each frequency at ``temperature_c``: ``4 pi f d / c`` (n_f,)."""
        d = self.range_drift_m(temperature_c)
        return np.array([range_to_phase_rad(d[k], f) for k, f in enumerate(self.frequencies_hz)])

    def remove_from_phase_rad(self, phase_rad: np.ndarray, temperature_c: float) -> np.ndarray:
        """Phases (n_f, H, W) in [0, 2 pi) measured at ``temperature_c`` -> the phases at the
        start temperature: the drift's offset subtracted, wrapped into [0, 2 pi) again (the
        drift acts after the camera's other depth errors, :mod:`sim_core.pipeline`: a fit or a
        correction of those removes it first)."""
        phase = np.asarray(phase_rad, dtype=np.float64)
        if phase.ndim < 1 or phase.shape[0] != self.frequencies_hz.size:
            raise InvalidInputError(
                "phase_rad", f"has shape {phase.shape}; the drift is for "
                f"{self.frequencies_hz.size} frequencies (n_f, H, W)")
        offsets = self.phase_offset_rad(temperature_c).reshape((-1,) + (1,) * (phase.ndim - 1))
        wrapped = np.mod(phase - offsets, 2.0 * np.pi)
        # np.mod of a tiny negative number rounds to 2 pi itself: that is a phase of 0
        return np.where(wrapped >= 2.0 * np.pi, 0.0, wrapped)

    def apply_to_phasor(self, phasor: np.ndarray, temperature_c: float) -> np.ndarray:
        """Phasors ``A exp(-1j phi)`` (n_f, H, W) -> with the drift's phase added.

        The magnitude is kept (a zero phasor stays zero), so only the range changes.
        """
        z = np.asarray(phasor)
        if z.ndim < 1 or z.shape[0] != self.frequencies_hz.size:
            raise InvalidInputError(
                "phasor", f"has shape {z.shape}; the drift is for {self.frequencies_hz.size} "
                "frequencies (n_f, H, W)")
        offsets = self.phase_offset_rad(temperature_c)
        rot = np.exp(-1j * offsets).reshape((-1,) + (1,) * (z.ndim - 1))
        return z * rot
