"""The stray light's fraction and kernel radius from a bright patch beside a dark one (issue 27).

Procedure (the real rig and the simulated lab alike): a bright, flat target fills part of the
image and nothing else returns light (the rest of the view is empty to beyond the camera's
range, or a light trap); a few frames of that static view are averaged as complex phasors
(their noise averages to zero; amplitudes would keep a noise bias). The camera's stray light
(:class:`sim_core.optics.StrayLight`)

    Z = (1 - f) I + f S_r(I)

puts ``f S_r(I)`` on the dark pixels, where the true light ``I`` is zero; on the bright ones
``I ~ Z / (1 - f)`` to first order in ``f``. So the dark pixels' phasors are predicted from the
bright pixels' alone (their own share of the stray light removed by one fixed-point step), and
a least-squares fit of ``f`` and ``r`` to the dark pixels' phasors (real and imaginary parts,
weighted by the frames' own temporal noise, pooled over the dark pixels) measures both. A guard
band of :data:`GUARD_PX` around the bright pixels is left out: there the optics' blur
(diffraction, the pixel aperture) spreads the edge and is not stray light. Beyond it the blur's
far tails still carry light (a diffraction pattern's rings: about a thousandth of the light, a
tenth of a 1 % stray light); the twin models that blur itself (the nominal optics' MTF chain,
:mod:`sim_core.optics`), so when the caller gives those components their tails are predicted
from the bright pixels and subtracted, and only what they do not explain is read as stray light.

The dark pixels' taps must sit on a pedestal well above their noise (a camera's black level;
in the simulated lab, dark current): a sensor clips a tap at zero, and clipped noise carries only
part of a weak signal (a third less on the simulated sensor with 30 e- of read noise and no
pedestal). Their mean grey value against the temporal noise of their correlations says whether
they do (:data:`PEDESTAL_SIGMAS`); where not, both keys are ``not determined``.

The verdicts come from :func:`calibration.verdicts.judge`: the standard deviations from the
fit's Jacobian, made honest by its reduced chi-square.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.optimize import least_squares

from calibration.verdicts import Verdict, Verdicts, honest_std, judge
from sim_core.errors import InvalidInputError
from sim_core.optics import MTFComponent, StrayLight, apply_mtf
from sim_core.raw import RawFrame

FRACTION_KEY = "camera.stray_light.fraction"
RADIUS_KEY = "camera.stray_light.kernel_radius_px"
#: bright pixels: amplitude above this share of the largest
BRIGHT_SHARE = 0.25
#: pixels this close to a bright one are neither bright nor dark (the optics' blur) [px]
GUARD_PX = 6
#: the least dark pixels a fit needs
MIN_DARK_PX = 200
#: the radii the fit starts from (each with its best fraction) [px]
START_RADII_PX = (2.0, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0)
#: the radii the fit searches [px]
RADIUS_BOUNDS_PX = (0.5, 5000.0)
#: the dark pixels' grey value must be this many times their correlations' temporal noise: each
#: tap's mean then lies 2.5 of its standard deviations above zero, where clipping is negligible
PEDESTAL_SIGMAS = 3.5
#: largest standard deviations of determined keys: a fifth of a typical 1 % and 10 px
FRACTION_STD_LIMIT = 0.002
RADIUS_STD_LIMIT_PX = 10.0


@dataclass(frozen=True)
class StrayLightFit:
    """The fitted stray light, its honest standard deviations and the fit's evidence."""

    fraction: float
    kernel_radius_px: float
    fraction_std: float
    radius_std_px: float
    reduced_chi2: float
    n_dark_px: int
    n_bright_px: int
    verdicts: Verdicts

    def stray_light_key(self) -> dict:
        """The calibration file's ``camera.stray_light``."""
        return {"fraction": round(self.fraction, 5),
                "kernel_radius_px": round(self.kernel_radius_px, 2)}


def _pedestal_problem(frames: Sequence[RawFrame], dark: np.ndarray) -> str | None:
    """Why the dark pixels' taps may be clipped at zero, or None (see :data:`PEDESTAL_SIGMAS`)."""
    c = np.stack([f.phase_images[0][:, dark] for f in frames]).astype(np.float64)
    sigma_c = float(np.sqrt(c.var(axis=0, ddof=1).mean()))
    grey = float(np.median(np.mean([f.intensity[dark] for f in frames], axis=0)))
    if grey >= PEDESTAL_SIGMAS * sigma_c:
        return None
    return (f"the dark pixels' grey value {grey:.3g} DN is below {PEDESTAL_SIGMAS:g} x their "
            f"correlations' noise {sigma_c:.3g} DN: their taps are clipped at zero and carry "
            "only part of the stray light (give them a pedestal: a black level)")


def _mean_phasor(frames: Sequence[RawFrame]) -> tuple[np.ndarray, np.ndarray]:
    """The frames' mean phasor of the first frequency and the variance of that mean per pixel
    (of each of its real and imaginary parts)."""
    if len(frames) < 2:
        raise InvalidInputError("frames", f"{len(frames)} frames; the noise of the mean needs "
                                "at least 2")
    z = np.stack([f.phasor()[0] for f in frames])
    n = z.shape[0]
    var = (np.abs(z - z.mean(axis=0)) ** 2).sum(axis=0) / (2.0 * (n - 1)) / n
    return z.mean(axis=0), var


def fit_stray_light(frames: Sequence[RawFrame],
                    optics: Sequence[MTFComponent] = ()) -> StrayLightFit:
    """The stray light from frames of a bright patch beside a dark view (module docstring).

    ``optics``: the nominal optics' MTF components (the scene's, as the twin applies them),
    whose far tails are subtracted from the dark pixels; none: every light on them is stray.
    """
    z, var = _mean_phasor(frames)
    amp = np.abs(z)
    peak = float(amp.max())
    if not peak > 0.0:
        raise InvalidInputError("frames", "every frame is dark: no bright patch to scatter")
    bright = amp > BRIGHT_SHARE * peak
    near = ndimage.binary_dilation(bright, iterations=GUARD_PX)
    dark = ~near
    if int(dark.sum()) < MIN_DARK_PX:
        raise InvalidInputError("frames", f"{int(dark.sum())} dark pixels at least {GUARD_PX} "
                                f"px from the bright patch; the fit needs {MIN_DARK_PX}")
    source = np.where(bright, z, 0.0)
    # The noise of the mean, pooled over the dark pixels (their noise is the same everywhere:
    # read noise and the pedestal's shot noise; a per-pixel variance of a few frames would
    # scatter the weights), floored at a thousandth of a DN^2: finite for noise-free frames.
    sigma = math.sqrt(max(float(var[dark].mean()), 1e-6))
    # The optics' own blur of the bright patch, as far as it reaches the dark pixels.
    z_dark = z[dark] - apply_mtf(source, list(optics))[dark] if optics else z[dark]

    def residual(p: np.ndarray) -> np.ndarray:
        f, log_r = p
        spread = StrayLight(1.0, math.exp(log_r)).apply
        # The bright pixels' true light: Z_b = (1 - f) I_b + f S(I)_b, solved by one step of
        # the fixed point from I_b ~ Z_b / (1 - f) (f <= 0.5: the step contracts by f / (1-f)).
        light = source / (1.0 - f)
        light = np.where(bright, (source - f * spread(light)) / (1.0 - f), 0.0)
        d = (z_dark - f * spread(light)[dark]) / sigma
        return np.concatenate([d.real, d.imag])

    starts = []
    for r in START_RADII_PX:
        s = StrayLight(1.0, r).apply(source)[dark] / sigma
        w = z_dark / sigma
        f0 = float(np.clip(np.real(np.vdot(s, w)) / max(float(np.vdot(s, s).real), 1e-300),
                           0.0, 0.4))
        starts.append((float(np.sum(np.abs(w - f0 * s) ** 2)), f0, math.log(r)))
    _, f0, lr0 = min(starts)
    lo, hi = math.log(RADIUS_BOUNDS_PX[0]), math.log(RADIUS_BOUNDS_PX[1])
    sol = least_squares(residual, [f0, lr0], bounds=([0.0, lo], [0.5, hi]), x_scale=[0.01, 0.3])
    dof = sol.fun.size - 2
    chi2 = float(np.sum(sol.fun**2)) / dof
    f, r = float(sol.x[0]), math.exp(float(sol.x[1]))
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac)
        f_std = math.sqrt(max(cov[0, 0], 0.0))
        r_std = r * math.sqrt(max(cov[1, 1], 0.0))  # d r = r d(log r)
    except np.linalg.LinAlgError:  # a singular Jacobian: the data do not see the parameter
        f_std = r_std = math.inf
    where = f"the dark pixels ({int(dark.sum())}) beside the bright patch"
    clipped = _pedestal_problem(frames, dark)
    if clipped is not None:
        verdicts = Verdicts({key: Verdict("not determined", None, clipped)
                             for key in (FRACTION_KEY, RADIUS_KEY)})
    else:
        verdicts = Verdicts({
            FRACTION_KEY: judge(f_std, FRACTION_STD_LIMIT, reduced_chi2=chi2, where=where),
            RADIUS_KEY: judge(r_std, RADIUS_STD_LIMIT_PX, reduced_chi2=chi2, unit=" px",
                              where=where),
        })
    return StrayLightFit(f, r, honest_std(f_std, chi2), honest_std(r_std, chi2), chi2,
                         int(dark.sum()), int(bright.sum()), verdicts)


__all__ = ["FRACTION_KEY", "RADIUS_KEY", "StrayLightFit", "fit_stray_light"]
