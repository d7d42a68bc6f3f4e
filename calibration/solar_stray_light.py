"""The camera's stray light and the solar simulator's scale, fitted together from the solar
stage's frames (issue 27).

The solar stage (:mod:`calibration.rig_sequence`, step 7) looks at the calibration board under
the solar simulator at several levels: white squares beside black ones, and around the board the
rig's dark backdrop, all lit. Stray light of lens and cover glass (:class:`sim_core.optics.
StrayLight`)

    Z = (1 - f) I + f S_r(I)

takes a share ``f`` of every pixel's light and spreads it with a Gaussian of radius ``r``: the
white squares read ``f`` dimmer than the twin predicts, the black squares and the backdrop
brighter by the light of their surroundings. A twin without it explains the white squares with
a solar scale a few per cent off and the dark pixels not at all (reduced chi-square 49 for
``f`` = 1.7 %; :mod:`calibration.solar`). The spread's shape tells it apart from the scale: a
scale changes every pixel's solar light in proportion, the stray light moves light from bright
pixels to dark ones over ``r``. So the scale ``s``, ``f`` and ``r`` are fitted together, by
robust least squares (Huber, as the scale alone) of the measured intensities at every level
against the twin's prediction ``predict(level x s)`` seen through ``StrayLight(f, r)`` (one
render, re-exposed: :meth:`calibration.twin_prediction.Prediction.with_stray_light`), on the
pixels the scale's own fit uses (:func:`calibration.solar.response_pixels`).

The camera's own light is a fourth parameter ``a`` (its DC and phasors times ``a``): the source
power the prediction is made with comes from the white squares' amplitudes, which the stray
light dims by its own share, so a prediction at that power is off by about ``f``, and a fit that
held it fixed put the error into the stray light (reality 505: the fraction 21 % and the radius
38 % low at a power 2 % low, 40 standard deviations; with ``a`` free, 0.1 % and 0.4 %). The
caller fits the power again through the stray light found.

The standard deviations come from the fit's Jacobian, made honest by its reduced chi-square
(:func:`calibration.verdicts.honest_std`). A fraction within three of its standard deviations
of zero is no stray light the frames can see: the calibration keeps no ``camera.stray_light``
and says so; its radius is then not determined either (the Jacobian's column is ``f`` times the
spread's change).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from calibration.solar import HUBER, SCALE_BOUNDS, SolarScaleResult
from calibration.stray_light import (
    FRACTION_KEY,
    FRACTION_STD_LIMIT,
    RADIUS_KEY,
    RADIUS_STD_LIMIT_PX,
)
from calibration.twin_prediction import Prediction
from calibration.verdicts import Verdict, Verdicts, honest_std, judge
from sim_core.optics import StrayLight

#: the camera's own light against the prediction's: its bounds
ACTIVE_BOUNDS = (0.2, 5.0)
#: the fraction's bounds (the optics' model takes up to 1; a real lens scatters a few per cent)
FRACTION_BOUNDS = (0.0, 0.45)
#: the kernel radius's bounds [px]: below half a pixel the spread is the pixel itself, beyond
#: 2000 px it is flat over the 224 x 171 image
RADIUS_BOUNDS_PX = (0.5, 2000.0)
#: where the fit starts: a per cent spread over 25 px (the fit found the same optimum from 8 to
#: 250 px on the simulated lab's realities)
START_FRACTION, START_RADIUS_PX = 0.01, 25.0
#: a stray light is seen when its fraction is this many standard deviations above zero
SIGNIFICANT_SIGMAS = 3.0
#: finite-difference step of the Jacobian, relative to each parameter (the predicted
#: intensities are float32: a smaller step would difference rounding)
DIFF_STEP = 1e-3
#: the fit stops when a step moves the parameters by less than this share of themselves, or
#: the cost by less than this share of itself: far below the standard deviations (a third of
#: the evaluations of scipy's defaults, the same estimates to 1e-4 of their std)
X_TOL, F_TOL = 1e-4, 1e-6


@dataclass(frozen=True)
class SolarStrayLightFit:
    """The solar scale and the camera's stray light fitted together, with the fit's evidence.

    Attributes
    ----------
    irradiance_scale, scale_std : float
        True suns = set suns x this, and its honest standard deviation.
    fraction, fraction_std : float
        The stray light's share of every pixel's light and its honest standard deviation.
    radius_px, radius_std_px : float
        The spread's Gaussian radius [px] and its honest standard deviation (inf when the
        fraction is too small to see its shape).
    reduced_chi2 : float
        The residuals' chi-square per degree of freedom (four parameters).
    n_pixels : int
        Pixels per level the fit used.
    active_scale, active_scale_std : float
        The camera's own light against the prediction's (its source power), and its honest
        standard deviation: fitted with the rest, not used (the source power is fitted from
        the amplitudes again through the stray light found).
    """

    irradiance_scale: float
    scale_std: float
    fraction: float
    fraction_std: float
    radius_px: float
    radius_std_px: float
    reduced_chi2: float
    n_pixels: int
    active_scale: float = 1.0
    active_scale_std: float = 0.0

    @property
    def significant(self) -> bool:
        """Whether the frames see a stray light: the fraction :data:`SIGNIFICANT_SIGMAS`
        standard deviations above zero, with a finite standard deviation."""
        return (math.isfinite(self.fraction_std)
                and self.fraction > SIGNIFICANT_SIGMAS * self.fraction_std)

    def stray_light_key(self) -> dict[str, float]:
        """The calibration file's ``camera.stray_light``."""
        return {"fraction": round(self.fraction, 5),
                "kernel_radius_px": round(self.radius_px, 2)}

    def stray_light(self) -> StrayLight:
        """The optics' stray light as fitted."""
        return StrayLight(self.fraction, self.radius_px)

    def verdicts(self) -> Verdicts:
        """The two keys' verdicts: judged against their limits when the frames see a stray
        light, else both not determined with the fraction found."""
        where = f"the solar stage's intensities ({self.n_pixels} pixels a level)"
        if not self.significant:
            reason = (f"the solar stage's frames show no stray light above their noise (fraction "
                      f"{self.fraction:.2g} +- {self.fraction_std:.2g}): no key written")
            return Verdicts({key: Verdict("not determined", None, reason)
                             for key in (FRACTION_KEY, RADIUS_KEY)})
        return Verdicts({
            FRACTION_KEY: judge(self.fraction_std, FRACTION_STD_LIMIT, where=where),
            RADIUS_KEY: judge(self.radius_std_px, RADIUS_STD_LIMIT_PX, unit=" px", where=where),
        })

    def solar_result(self) -> SolarScaleResult:
        """The solar scale as :mod:`calibration.solar` reports it, from this fit."""
        return SolarScaleResult(
            self.irradiance_scale, self.scale_std, "frames", self.n_pixels, float("nan"),
            f"{self.n_pixels} pixels respond to the level, fitted with the camera's stray light "
            f"({100 * self.fraction:.2f} % over {self.radius_px:.0f} px); standard error "
            f"{100 * self.scale_std / self.irradiance_scale:.2f} %", self.reduced_chi2)

    def to_dict(self) -> dict:
        return {"irradiance_scale": self.irradiance_scale, "scale_std": self.scale_std,
                "fraction": self.fraction, "fraction_std": self.fraction_std,
                "radius_px": self.radius_px, "radius_std_px": self.radius_std_px,
                "reduced_chi2": self.reduced_chi2, "n_pixels": self.n_pixels,
                "active_scale": self.active_scale, "active_scale_std": self.active_scale_std,
                "significant": self.significant}


def fit_solar_stray_light(
    levels: Sequence[float],
    measured: Sequence[np.ndarray],
    std: Sequence[np.ndarray],
    use: np.ndarray,
    prediction: Prediction,
    start_scale: float,
) -> SolarStrayLightFit:
    """Fit the solar scale, the stray light's fraction and its radius together (module
    docstring).

    ``measured`` and ``std``: each level's mean intensity [DN] and its standard error with the
    twin's floor, ``use`` the pixels to fit (both from :func:`calibration.solar.
    response_pixels`); ``prediction``: the twin's view at a solar level of 1 sun, without stray
    light; ``start_scale``: where the scale starts (the scale's fit without stray light).
    """
    n = int(np.count_nonzero(use))
    if n < 4:
        raise ValueError(f"use: {n} pixels; the fit of four parameters needs more")
    targets = [(float(level), np.asarray(m, dtype=np.float64)[use],
                np.asarray(e, dtype=np.float64)[use]) for level, m, e in zip(
                    levels, measured, std, strict=True)]

    def residuals(p: np.ndarray) -> np.ndarray:
        scale, active, fraction, log_r = (float(v) for v in p)
        seen = prediction.with_stray_light(StrayLight(fraction, math.exp(log_r)))
        # e > 0 on every used pixel (response_pixels keeps finite, positive errors only)
        predicted = seen.intensities([level * scale for level, _, _ in targets], active)
        return np.concatenate([(m - p[use]) / e
                               for (_, m, e), p in zip(targets, predicted, strict=True)])

    lo = [SCALE_BOUNDS[0], ACTIVE_BOUNDS[0], FRACTION_BOUNDS[0], math.log(RADIUS_BOUNDS_PX[0])]
    hi = [SCALE_BOUNDS[1], ACTIVE_BOUNDS[1], FRACTION_BOUNDS[1], math.log(RADIUS_BOUNDS_PX[1])]
    x0 = [float(np.clip(start_scale, *SCALE_BOUNDS)), 1.0, START_FRACTION,
          math.log(START_RADIUS_PX)]
    sol = least_squares(residuals, x0, bounds=(lo, hi), loss="huber", f_scale=HUBER,
                        x_scale=[0.01 * x0[0], 0.01, 0.005, 0.3], diff_step=DIFF_STEP,
                        xtol=X_TOL, ftol=F_TOL)
    dof = max(sol.fun.size - 4, 1)
    chi2 = float(np.sum(sol.fun**2) / dof)
    scale, active, fraction = (float(v) for v in sol.x[:3])
    radius = math.exp(float(sol.x[3]))
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac)
        stds = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:  # a singular Jacobian: the frames do not see a parameter
        stds = np.full(4, math.inf)
    scale_std, active_std, fraction_std, log_r_std = (honest_std(float(s), chi2) for s in stds)
    # d r = r d(log r); at the fraction's lower bound the spread's shape is invisible
    radius_std = radius * log_r_std if fraction > 0.0 else math.inf
    return SolarStrayLightFit(scale, scale_std, fraction, fraction_std, radius, radius_std,
                              chi2, n, active, active_std)


__all__ = ["SolarStrayLightFit", "fit_solar_stray_light"]
