"""Effective source power from the amplitude of the board's white squares (issue 13, section 4).

The amplitude a pixel measures is proportional to the camera source's optical power (seed eqs.
20-21 and 32: irradiance, radiance and electrons are all linear in it). With the camera's geometry
and gain calibrated, the twin predicts the amplitude of every pixel for the nominal power
``P0``; the measured amplitude over the predicted one, on pixels well inside the white squares,
is then ``P / P0``. The power found is *effective*: it absorbs whatever else scales the signal
and is not calibrated separately (quantum efficiency, fill factor, lens transmittance, the board's
albedo), which is what the twin needs to reproduce the camera's amplitudes.

Whether the twin explains the squares is judged square by square (:func:`region_agreement`):
their ratios must agree within their pixels' spread. The twin's geometry is calibrated to a
tenth of a pixel, not to nothing, and where a square's predicted amplitude has a gradient (the
illumination's fall-off, the optics' blur near the mask's edge) a tenth of a pixel moves that
square's ratio by a few 1e-4: as much as its noise. The fit is therefore given the prediction's
change for a small shift of the image (``image_shift_modes``: the twin rendered with the
principal point moved), and each mode's pattern over the squares is fitted out before the
chi-square is taken, one degree of freedom each: a calibration error within its error bars is
not a model that fails to explain the data, while what no image shift explains (a smooth
gradient of unmodelled stray light, a wrong reflectance) still is.
"""

from __future__ import annotations

from collections.abc import Sequence
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
    regions_dof : int
        The degrees of freedom of ``regions_reduced_chi2``: the regions less one, less one for
        each image-shift mode fitted out (0 with fewer than two regions).
    """

    power_w: float
    ratio: float
    ratio_std_error: float
    residual_rel_rms: float
    n_pixels: int
    n_regions: int = 0
    regions_reduced_chi2: float = float("nan")
    regions_std_error: float = float("nan")
    regions_dof: int = 0

    def to_dict(self) -> dict:
        return {"power_w": self.power_w, "ratio": self.ratio,
                "ratio_std_error": self.ratio_std_error,
                "residual_rel_rms": self.residual_rel_rms, "n_pixels": self.n_pixels,
                "n_regions": self.n_regions, "regions_reduced_chi2": self.regions_reduced_chi2,
                "regions_std_error": self.regions_std_error, "regions_dof": self.regions_dof}


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
    image_shift_modes: Sequence[np.ndarray] = (),
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
    image_shift_modes : sequence of (H, W) float
        The predicted amplitude's change [DN] for a small shift of the image each (module
        docstring), fitted out of the regions' ratios before their chi-square; none by default.

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
    relative_modes = [np.asarray(d, dtype=np.float64) / np.where(use, p, 1.0)
                      for d in image_shift_modes]
    n_regions, chi2, regions_se, dof = region_agreement(m / np.where(use, p, 1.0), use, ratio,
                                                        relative_modes)
    return SourcePowerResult(
        power_w=nominal_power_w * ratio,
        ratio=ratio,
        ratio_std_error=1.4826 * mad / np.sqrt(n),
        residual_rel_rms=float(np.sqrt(np.mean((r / ratio - 1.0) ** 2))),
        n_pixels=n, n_regions=n_regions, regions_reduced_chi2=chi2,
        regions_std_error=regions_se, regions_dof=dof,
    )


def region_agreement(ratio_image: np.ndarray, use: np.ndarray, ratio: float,
                     relative_modes: Sequence[np.ndarray] = ()
                     ) -> tuple[int, float, float, int]:
    """How the connected regions of ``use`` agree on ``ratio``: their count, the reduced
    chi-square of their medians about it (each median's standard error 1.4826 MAD / sqrt(n),
    1.2533 sigma / sqrt(n) for a median of Gaussian values), the standard error of the ratio
    from their spread, and the chi-square's degrees of freedom. Regions under
    :data:`MIN_REGION_PIXELS` pixels are left out; with fewer than two regions the chi-square
    and the standard error are NaN (0 degrees of freedom).

    ``relative_modes``: patterns of the prediction's relative change (each (H, W), taken as a
    region's median) fitted out of the medians by weighted least squares before the chi-square,
    one degree of freedom each; a mode is left out when the regions are too few to leave a
    degree of freedom after it.
    """
    labels, n_labels = ndimage.label(use)
    meds, ses, cols = [], [], []
    for k in range(1, n_labels + 1):
        inside = labels == k
        r = ratio_image[inside]
        if r.size < MIN_REGION_PIXELS:
            continue
        med = float(np.median(r))
        mad = float(np.median(np.abs(r - med)))
        meds.append(med)
        # a region of identical values has MAD 0: its error is that of the ratio's last digit
        ses.append(max(1.2533 * 1.4826 * mad / np.sqrt(r.size), 1e-12 * max(abs(med), 1.0)))
        # the ratio measured / (predicted + b mode) moves by -ratio b (mode / predicted)
        cols.append([ratio * float(np.median(mode[inside])) for mode in relative_modes])
    if len(meds) < 2:
        return len(meds), float("nan"), float("nan"), 0
    med_a, se_a = np.asarray(meds), np.asarray(ses)
    resid = med_a - ratio
    n_modes = min(len(relative_modes), med_a.size - 2)
    if n_modes > 0:
        a = np.asarray(cols)[:, :n_modes] / se_a[:, None]
        finite = np.all(np.isfinite(a), axis=0)
        a = a[:, finite]
        if a.shape[1]:
            coef, *_ = np.linalg.lstsq(a, resid / se_a, rcond=None)
            resid = resid - (a @ coef) * se_a
        n_modes = a.shape[1]
    dof = med_a.size - 1 - n_modes
    chi2 = float(np.sum((resid / se_a) ** 2) / dof)
    return med_a.size, chi2, float(np.std(med_a, ddof=1) / np.sqrt(med_a.size)), dof
