"""The solar simulator's irradiance scale from the frames' response to its level (issue 13, §4).

Ambient light adds to both taps of every phase step, so it raises the frames' intensity (the
mean tap sum, seed eq. 6) in proportion to the true irradiance, until SBI (seed section 2.2.3)
starts removing the common charge. The twin predicts the intensity for a true level; the scale
``s`` (true suns = set suns x s) is the one whose predictions match the measured intensities at
every set level, by least squares over the pixels the beam reaches. SBI's clipping is part of
the prediction, so a level range that SBI flattens simply carries less information.

Whether the frames *determine* the scale is judged from that information: the standard error
``sigma / sqrt(sum (dI/ds)^2)``. Beyond :data:`MAX_REL_UNCERTAINTY` the frames do not determine it
and the scale must come from a reference-cell reading the operator enters; the result says which.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from sim_core.errors import InvalidInputError

#: relative standard error beyond which the frames do not determine the scale
MAX_REL_UNCERTAINTY = 0.01
#: relative error of the twin's predicted intensity (calibrated gain and power)
MODEL_ERROR_REL = 0.01
#: Huber threshold of the normalised residuals
HUBER = 3.0
#: a pixel is "flat" when its 3 x 3 neighbourhood in the prediction varies by less than this
FLAT_VARIATION = 0.05
#: the scale is searched in this range
SCALE_BOUNDS = (0.2, 5.0)
#: a reference cell's reading at a set level of 1 sun [sun]: above 0, up to 5
REFERENCE_SUNS_RANGE = (0.0, 5.0)


@dataclass(frozen=True)
class SolarScaleResult:
    """The solar simulator's scale and where it came from.

    Attributes
    ----------
    irradiance_scale : float
        True suns = set suns x this.
    std_error : float
        Standard error of the scale (from the frames; 0 for a reference-cell reading).
    method : str
        ``"frames"`` (the frames' intensity response) or ``"reference-cell"``.
    n_pixels : int
        Pixels the fit used (0 for a reference-cell reading).
    residual_rms_dn : float
        RMS of measured minus predicted intensity at the fitted scale [DN].
    reason : str
        Why the frames did or did not determine it.
    reduced_chi2 : float
        The normalised residuals' chi-square per degree of freedom at the fitted scale (each
        pixel's temporal standard error and the twin's :data:`MODEL_ERROR_REL`); NaN for a
        reference-cell reading.
    """

    irradiance_scale: float
    std_error: float
    method: str
    n_pixels: int
    residual_rms_dn: float
    reason: str
    reduced_chi2: float = float("nan")

    def to_dict(self) -> dict:
        return {"irradiance_scale": self.irradiance_scale, "std_error": self.std_error,
                "method": self.method, "n_pixels": self.n_pixels,
                "residual_rms_dn": self.residual_rms_dn, "reason": self.reason,
                "reduced_chi2": self.reduced_chi2}


def check_reference_suns(value: float, field: str = "solar_reference_suns") -> float:
    """``value`` if it is a reference cell's reading in :data:`REFERENCE_SUNS_RANGE`, else an
    input error naming ``field``."""
    lo, hi = REFERENCE_SUNS_RANGE
    if not (math.isfinite(value) and lo < value <= hi):
        raise InvalidInputError(field, f"got {value!r} sun; allowed: above {lo:g} up to {hi:g} "
                                "sun")
    return float(value)


def _flat(image: np.ndarray) -> np.ndarray:
    from scipy import ndimage

    q = np.nan_to_num(np.asarray(image, dtype=np.float64))
    span = ndimage.maximum_filter(q, size=3) - ndimage.minimum_filter(q, size=3)
    return span <= FLAT_VARIATION * np.maximum(np.abs(q), 1e-12)


def response_pixels(
    levels: Sequence[float],
    measured_intensity: Sequence[np.ndarray],
    intensity_std: Sequence[np.ndarray],
    predict: Callable[[float], np.ndarray],
    saturation_dn: float = 4000.0,
) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
    """The measured intensities, their standard errors with the twin's own error as a floor,
    and the pixels that carry the solar simulator's level: finite, unsaturated, off the
    prediction's edges, and responding to the level by more than three times the noise (the
    solar scale's fit and the stray light's, :mod:`calibration.solar_stray_light`, use the
    same pixels)."""
    meas = [np.asarray(m, dtype=np.float64) for m in measured_intensity]
    # The twin's own error (gain, power: a per cent or so) bounds how well a pixel can agree,
    # however many frames were averaged: without the floor a few bright pixels near SBI or
    # saturation, where a small gain error changes the response most, would decide the fit.
    std = [np.hypot(np.asarray(s, dtype=np.float64), MODEL_ERROR_REL * np.abs(m))
           for s, m in zip(intensity_std, meas, strict=True)]
    # Pixels the beam reaches: the prediction at the highest level differs from the lowest.
    pred_lo, pred_hi = predict(min(levels)), predict(max(levels))
    reach = np.abs(pred_hi - pred_lo)
    finite = np.all([np.isfinite(m) & np.isfinite(s) & (s > 0) & (m < saturation_dn)
                     for m, s in zip(meas, std, strict=True)], axis=0)
    noise = float(np.median(np.concatenate([s[finite] for s in std]))) if finite.any() else 0.0
    # Pixels on an edge of the prediction (a board square's border, an object's outline) are
    # left out: a fraction of a pixel of geometry error changes them more than the level does.
    flat = _flat(pred_lo) & _flat(pred_hi)
    return meas, std, finite & flat & (reach > 3.0 * noise)


def fit_solar_scale(
    set_suns: Sequence[float],
    measured_intensity: Sequence[np.ndarray],
    intensity_std: Sequence[np.ndarray],
    predict: Callable[[float], np.ndarray],
    reference_cell_suns: float | None = None,
    saturation_dn: float = 4000.0,
) -> SolarScaleResult:
    """Fit the scale from intensity frames at several set levels.

    Parameters
    ----------
    set_suns : sequence of float
        The levels the lamp was set to (0 for shutter closed is allowed and useful: it pins the
        active light's share).
    measured_intensity : sequence of (H, W)
        Mean intensity [DN] over the frames at each level.
    intensity_std : sequence of (H, W)
        Standard error of each mean [DN] (temporal std / sqrt(frames)).
    predict : callable
        ``true_suns -> (H, W)`` noise-free intensity [DN] the twin predicts.
    reference_cell_suns : float, optional
        A reference cell's reading at set level 1 sun, used when the frames do not determine the
        scale.
    saturation_dn : float
        Pixels at or above this intensity at any level are left out (ADC and full well).

    Raises
    ------
    InvalidInputError
        Mismatched inputs, fewer than two levels, or the frames do not determine the scale and
        no reference-cell reading was given.
    """
    levels = [float(s) for s in set_suns]
    if len(levels) != len(measured_intensity) or len(levels) != len(intensity_std):
        raise InvalidInputError("set_suns", "needs one measured image and one std per level")
    if len({round(s, 6) for s in levels}) < 2:
        raise InvalidInputError(
            "set_suns", f"got the levels {levels}; at least two different ones are needed")
    meas, std, use = response_pixels(levels, measured_intensity, intensity_std, predict,
                                     saturation_dn)
    n = int(np.count_nonzero(use))

    def cost(scale: float) -> float:
        # Huber loss of the normalised residuals: a few pixels the twin gets wrong (multipath,
        # a shadow edge) cannot outweigh the many it gets right.
        total = 0.0
        for s, m, e in zip(levels, meas, std, strict=True):
            r = np.abs((m[use] - predict(s * scale)[use]) / e[use])
            total += float(np.sum(np.where(r <= HUBER, 0.5 * r**2, HUBER * (r - 0.5 * HUBER))))
        return total

    reason = ""
    if n >= 10:
        # SBI and clipping make the cost uneven far from the optimum: a grid first, then a
        # bounded search between the best grid point's neighbours.
        grid = np.geomspace(SCALE_BOUNDS[0], SCALE_BOUNDS[1], 161)
        costs = [cost(g) for g in grid]
        j = int(np.argmin(costs))
        lo_b, hi_b = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
        best = minimize_scalar(cost, bounds=(lo_b, hi_b), method="bounded",
                               options={"xatol": 1e-5})
        scale = float(best.x)
        h = 1e-3 * scale
        info = sum(np.sum(((predict(s * (scale + h))[use] - predict(s * (scale - h))[use])
                           / (2 * h) / e[use]) ** 2) for s, e in zip(levels, std, strict=True))
        se = float(1.0 / np.sqrt(info)) if info > 0 else np.inf
        res = np.concatenate([m[use] - predict(s * scale)[use] for s, m in zip(levels, meas,
                                                                              strict=True)])
        rms = float(np.sqrt(np.mean(res**2)))
        norm = np.concatenate([res_s / e[use] for res_s, e in zip(
            np.split(res, len(levels)), std, strict=True)])
        chi2 = float(np.sum(norm**2) / max(norm.size - 1, 1))  # one parameter: the scale
        at_bound = min(abs(scale - b) for b in SCALE_BOUNDS) < 1e-3
        if se / scale <= MAX_REL_UNCERTAINTY and not at_bound:
            return SolarScaleResult(scale, se, "frames", n, rms,
                                    f"{n} pixels respond to the level; standard error "
                                    f"{100 * se / scale:.2f} %", chi2)
        reason = (f"the frames' response gives a standard error of {100 * se / scale:.1f} % "
                  f"(more than {100 * MAX_REL_UNCERTAINTY:g} %)" if not at_bound else
                  f"the fit ran to the bound {scale:.3g} of {SCALE_BOUNDS}")
    else:
        reason = f"only {n} pixels respond to the level (SBI or a beam outside the view)"
    if reference_cell_suns is None:
        raise InvalidInputError(
            "solar_simulator.irradiance_scale",
            f"the frames do not determine it: {reason}; measure the beam with a reference cell "
            "at a set level of 1 sun and enter the reading (--solar-reference-suns)",
        )
    check_reference_suns(reference_cell_suns)
    return SolarScaleResult(float(reference_cell_suns), 0.0, "reference-cell", 0, 0.0, reason)
