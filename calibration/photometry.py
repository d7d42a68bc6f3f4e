"""Effective source power from the amplitude of the board's white squares (issue 13, section 4).

The amplitude a pixel measures is proportional to the camera source's optical power (seed eqs.
20-21 and 32: irradiance, radiance and electrons are all linear in it). With the camera's geometry
and gain calibrated, the twin predicts the amplitude of every pixel for the nominal power
``P0``; the measured amplitude over the predicted one, on pixels well inside the white squares,
is then ``P / P0``. The power found is *effective*: it absorbs whatever else scales the signal
and is not calibrated separately (quantum efficiency, fill factor, lens transmittance, the board's
albedo), which is what the twin needs to reproduce the camera's amplitudes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from sim_core.errors import InvalidInputError

#: a pixel counts as "white square" when its predicted amplitude exceeds this share of the
#: bright level (the 99th percentile of the predicted amplitude)
WHITE_SHARE = 0.6
#: ... and its 3x3 neighbourhood's predicted amplitude varies by less than this (no edge)
MAX_LOCAL_VARIATION = 0.05
#: fewest pixels the ratio is taken over
MIN_PIXELS = 50


@dataclass(frozen=True)
class SourcePowerResult:
    """The effective source power and how well the pixels agree on it.

    Attributes
    ----------
    power_w : float
        Effective mean optical power of the camera's source [W].
    ratio : float
        Measured over predicted amplitude (median over the pixels used).
    ratio_std_error : float
        Standard error of ``ratio`` (1.4826 MAD / sqrt(n)).
    residual_rel_rms : float
        RMS of the pixels' relative deviation from ``ratio`` (noise plus model error).
    n_pixels : int
    """

    power_w: float
    ratio: float
    ratio_std_error: float
    residual_rel_rms: float
    n_pixels: int

    def to_dict(self) -> dict:
        return {"power_w": self.power_w, "ratio": self.ratio,
                "ratio_std_error": self.ratio_std_error,
                "residual_rel_rms": self.residual_rel_rms, "n_pixels": self.n_pixels}


def white_square_mask(predicted_amplitude: np.ndarray) -> np.ndarray:
    """Pixels well inside bright, uniform areas of the predicted amplitude image."""
    p = np.asarray(predicted_amplitude, dtype=np.float64)
    finite = np.isfinite(p)
    if not finite.any():
        return np.zeros(p.shape, dtype=bool)
    bright = float(np.percentile(p[finite], 99.0))
    if not bright > 0.0:
        return np.zeros(p.shape, dtype=bool)
    q = np.where(finite, p, 0.0)
    hi = ndimage.maximum_filter(q, size=3)
    lo = ndimage.minimum_filter(q, size=3)
    flat = (hi - lo) <= MAX_LOCAL_VARIATION * np.maximum(q, 1e-300)
    return finite & (q >= WHITE_SHARE * bright) & flat


def fit_source_power(
    measured_amplitude: np.ndarray,
    predicted_amplitude: np.ndarray,
    nominal_power_w: float,
    mask: np.ndarray | None = None,
) -> SourcePowerResult:
    """Effective power from measured and predicted amplitudes (both DN, same geometry).

    Parameters
    ----------
    measured_amplitude : (H, W) float
        Amplitude of the frames' mean phasor (average the phase images first, then take the
        amplitude: averaging amplitudes would keep the noise's bias).
    predicted_amplitude : (H, W) float
        The twin's noise-free amplitude at ``nominal_power_w``, calibrated geometry and gain.
    nominal_power_w : float
        Source power the prediction was made with [W].
    mask : (H, W) bool, optional
        Pixels to use; default :func:`white_square_mask` of the prediction.

    Raises
    ------
    InvalidInputError
        Shapes differ, the nominal power is not positive, or fewer than :data:`MIN_PIXELS`
        usable pixels (no board in view, or everything saturated).
    """
    m = np.asarray(measured_amplitude, dtype=np.float64)
    p = np.asarray(predicted_amplitude, dtype=np.float64)
    if m.shape != p.shape:
        raise InvalidInputError("measured_amplitude",
                                f"shape {m.shape} differs from the prediction's {p.shape}")
    if not (np.isfinite(nominal_power_w) and nominal_power_w > 0.0):
        raise InvalidInputError("nominal_power_w", f"{nominal_power_w} must be > 0")
    use = white_square_mask(p) if mask is None else np.asarray(mask, dtype=bool)
    use = use & np.isfinite(m) & np.isfinite(p) & (p > 0.0)
    n = int(use.sum())
    if n < MIN_PIXELS:
        raise InvalidInputError(
            "photometry",
            f"only {n} pixels lie well inside the board's white squares (at least {MIN_PIXELS} "
            "are needed): is the board in view and lit, and not saturated?",
        )
    r = m[use] / p[use]
    ratio = float(np.median(r))
    if not ratio > 0.0:
        raise InvalidInputError("photometry", "the measured amplitude on the white squares is 0")
    mad = float(np.median(np.abs(r - ratio)))
    return SourcePowerResult(
        power_w=nominal_power_w * ratio,
        ratio=ratio,
        ratio_std_error=1.4826 * mad / np.sqrt(n),
        residual_rel_rms=float(np.sqrt(np.mean((r / ratio - 1.0) ** 2))),
        n_pixels=n,
    )
