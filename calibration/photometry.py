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
#: fewest pixels of a region (white square) judged on its own
MIN_REGION_PIXELS = 8


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
    n_regions : int
        The connected areas (white squares) the pixels form, with at least
        :data:`MIN_REGION_PIXELS` each.
    regions_reduced_chi2 : float
        The regions' own ratios about ``ratio``, each against its standard error, per degree of
        freedom (1 when they agree as their pixels' spread allows; far above when the twin's
        shading of the image differs from the camera's); NaN with fewer than two regions.
    regions_std_error : float
        Standard error of ``ratio`` from the regions' spread (their standard deviation over
        sqrt(regions)); NaN with fewer than two regions.
    """

    power_w: float
    ratio: float
    ratio_std_error: float
    residual_rel_rms: float
    n_pixels: int
    n_regions: int = 0
    regions_reduced_chi2: float = float("nan")
    regions_std_error: float = float("nan")

    def to_dict(self) -> dict:
        return {"power_w": self.power_w, "ratio": self.ratio,
                "ratio_std_error": self.ratio_std_error,
                "residual_rel_rms": self.residual_rel_rms, "n_pixels": self.n_pixels,
                "n_regions": self.n_regions, "regions_reduced_chi2": self.regions_reduced_chi2,
                "regions_std_error": self.regions_std_error}


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
    n_regions, chi2, regions_se = region_agreement(m / np.where(use, p, 1.0), use, ratio)
    return SourcePowerResult(
        power_w=nominal_power_w * ratio,
        ratio=ratio,
        ratio_std_error=1.4826 * mad / np.sqrt(n),
        residual_rel_rms=float(np.sqrt(np.mean((r / ratio - 1.0) ** 2))),
        n_pixels=n, n_regions=n_regions, regions_reduced_chi2=chi2,
        regions_std_error=regions_se,
    )


def region_agreement(ratio_image: np.ndarray, use: np.ndarray, ratio: float
                     ) -> tuple[int, float, float]:
    """How the connected regions of ``use`` agree on ``ratio``: their count, the reduced
    chi-square of their medians about it (each median's standard error 1.4826 MAD / sqrt(n),
    1.2533 sigma / sqrt(n) for a median of Gaussian values) and the standard error of the ratio
    from their spread. Regions under :data:`MIN_REGION_PIXELS` pixels are left out; with fewer
    than two regions the last two are NaN."""
    labels, n_labels = ndimage.label(use)
    meds, ses = [], []
    for k in range(1, n_labels + 1):
        r = ratio_image[labels == k]
        if r.size < MIN_REGION_PIXELS:
            continue
        med = float(np.median(r))
        mad = float(np.median(np.abs(r - med)))
        meds.append(med)
        # a region of identical values has MAD 0: its error is that of the ratio's last digit
        ses.append(max(1.2533 * 1.4826 * mad / np.sqrt(r.size), 1e-12 * max(abs(med), 1.0)))
    if len(meds) < 2:
        return len(meds), float("nan"), float("nan")
    med_a, se_a = np.asarray(meds), np.asarray(ses)
    chi2 = float(np.sum(((med_a - ratio) / se_a) ** 2) / (med_a.size - 1))
    return med_a.size, chi2, float(np.std(med_a, ddof=1) / np.sqrt(med_a.size))
