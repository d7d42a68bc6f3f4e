"""Gain and read noise from a stack of frames of a static view (photon transfer, EMVA 1288).

Through the camera's wire a frame has the tap differences C_i = A_i - B_i and the intensity I
(the mean tap sum, both in DN), not the taps. With g the conversion gain [e-/DN] (EMVA 1288's
K = 1/g), N_A + N_B = N the electrons of a phase step (shot noise: var = mean), sigma_r the read
noise per tap [e-] (sim_core.sensor):

    var(C_i) = (N + 2 sigma_r^2) / g^2 + 1/6 = I / g + 2 sigma_r^2 / g^2 + 1/6   [DN^2]

(each rounded tap adds 1/12 DN^2 of quantisation). The temporal variance of every pixel's C_i
over the stack, against its mean intensity, is a line (the photon transfer curve): slope 1/g,
intercept 2 sigma_r^2 / g^2 + 1/6. The variance is taken from successive frames' differences
(:func:`successive_difference_variance`) on the pixels flat enough that a scene moving by a
fraction of a pixel does not add to it (:func:`flat_pixels`): a table still ringing, a warm-up
drift, leave the curve to the noise. The pixels of one view span a wide intensity range (white
and black squares, the source's fall-off, the dark background), so one stack determines it. The
fit is robust (soft-L1) and uses intensities below half the largest seen, where SBI (which adds
the compensation charge's own noise above n_SBI,start) has not started; the linearity over the
range used is reported. With taps in the frames (the simulator's own files) the same holds per
tap (var(A) = N_A / g^2 + sigma_r^2 / g^2 + 1/12): :func:`calibration.mean_variance.
calibrate_mean_variance` fits that (the peer paper's section 3.4 mean-variance fit in
Freeman-Tukey space, EMVA 1288 per tap) on the same stacks, an independent second estimate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from sim_core.errors import InvalidInputError
from sim_core.raw import RawFrame

QUANTISATION_DN2 = 1.0 / 6.0
#: pixel-intensity bins of the photon transfer curve
BINS = 40
#: share of the largest mean intensity the fit uses (SBI starts above)
LINEAR_SHARE = 0.5
#: pixels darker than this [DN] or this share of the range used are left out (tap clipping)
MIN_INTENSITY_DN = 20.0
MIN_INTENSITY_SHARE = 0.05
#: a pixel enters the curve when its mean C_i changes across it by at most this many standard
#: deviations of the noise at its intensity (:func:`flat_pixels`)
FLAT_GRADIENT_SIGMAS = 3.0


@dataclass(frozen=True)
class NoiseCalibration:
    """Gain and read noise with their standard errors, and the curve they came from."""

    adc_gain_e_per_dn: float
    read_noise_e: float
    gain_std_error: float
    read_noise_std_error: float
    dark_signal_dn: float
    intensity_range_dn: tuple[float, float]
    nonlinearity: float
    frames: int
    method: str
    curve: tuple[np.ndarray, np.ndarray]
    #: chi-square of the bins about the line, per degree of freedom (each bin's variance
    #: against its standard error; 1 when the line explains the curve to the noise)
    reduced_chi2: float = float("nan")

    def to_sensor_overrides(self) -> dict:
        return {"adc_gain_e_per_dn": self.adc_gain_e_per_dn, "read_noise_e": self.read_noise_e}

    def summary(self) -> dict:
        return {"adc_gain_e_per_dn": self.adc_gain_e_per_dn, "read_noise_e": self.read_noise_e,
                "gain_std_error": self.gain_std_error,
                "read_noise_std_error": self.read_noise_std_error,
                "dark_signal_dn": self.dark_signal_dn,
                "intensity_range_dn": list(self.intensity_range_dn),
                "nonlinearity_rms_rel": self.nonlinearity, "frames": self.frames,
                "method": self.method, "reduced_chi2": self.reduced_chi2}

    def plot(self, ax) -> str:
        mean, var = self.curve
        ax.plot(mean, var, "o", ms=3)
        x = np.linspace(0, mean.max(), 50)
        g, s = self.adc_gain_e_per_dn, self.read_noise_e
        ax.plot(x, x / g + 2 * s**2 / g**2 + QUANTISATION_DN2, "-")
        ax.set_xlabel("mean intensity [DN]")
        ax.set_ylabel("temporal variance of C_i [DN^2]")
        return f"Photon transfer: gain {g:.2f} e-/DN, read noise {s:.1f} e-"


def check_stack(stack: list[RawFrame], i: int) -> None:
    """Refuse stack ``i`` if it cannot give a variance: fewer than 2 frames, or frames of
    different use cases (shapes)."""
    if len(stack) < 2:
        raise InvalidInputError(f"stacks[{i}]", f"{len(stack)} frame(s) are too short for a "
                                "variance: at least 2 (better 16 or more) are needed")
    shape = stack[0].phase_images.shape
    if any(f.phase_images.shape != shape for f in stack):
        raise InvalidInputError(f"stacks[{i}]", "frames of different shapes (use cases)")


def calibrate_noise(stacks: list[list[RawFrame]]) -> NoiseCalibration:
    """Fit gain and read noise from one or more stacks (module docstring)."""
    means, variances, gradients = [], [], []
    n_frames = 0
    for i, stack in enumerate(stacks):
        check_stack(stack, i)
        c = np.stack([f.phase_images[0].astype(np.float64) for f in stack])  # (n, 4, H, W)
        inten = np.stack([f.intensity.astype(np.float64) for f in stack])
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(inten))):
            raise InvalidInputError(f"stacks[{i}]", "non-finite values in the frames")
        sat = np.any([f.saturated | f.sbi_limit for f in stack], axis=0)
        v = successive_difference_variance(c).mean(axis=0)  # mean over the 4 phase steps
        m = inten.mean(axis=0)
        means.append(m[~sat])
        variances.append(v[~sat])
        gradients.append(steepest_gradient(c.mean(axis=0))[~sat])
        n_frames += len(stack)
    m = np.concatenate(means)
    v = np.concatenate(variances)
    if m.size < 100:
        raise InvalidInputError("stacks", f"only {m.size} unsaturated pixels; at least 100")
    top = LINEAR_SHARE * float(np.percentile(m, 99.9))
    # Near zero the taps are clipped at 0 (no black level), which truncates the read noise:
    # only pixels whose mean is well above it are used.
    bottom = max(MIN_INTENSITY_DN, MIN_INTENSITY_SHARE * top)
    use = (m <= top) & (m >= bottom)
    use[use] = flat_pixels(m[use], v[use], np.concatenate(gradients)[use])
    if np.count_nonzero(use) < 100:
        raise InvalidInputError(
            "stacks", f"only {np.count_nonzero(use)} flat pixels have a mean intensity between "
            f"{bottom:.0f} and {top:.0f} DN: too few to determine the gain (a view with bright "
            "and dark areas, each wider than a few pixels, is needed)")
    edges = np.unique(np.linspace(bottom, top, BINS + 1))
    if edges.size < 6 or top <= 0 or (edges[-1] - edges[0]) < 50.0:
        raise InvalidInputError(
            "stacks", f"the pixels' mean intensities span {edges[0]:.0f}-{edges[-1]:.0f} DN: too "
            "narrow a range to determine the gain (a view with bright and dark areas is needed)")
    idx = np.clip(np.digitize(m[use], edges) - 1, 0, edges.size - 2)
    bm = np.array([m[use][idx == b].mean() for b in range(edges.size - 1) if np.any(idx == b)])
    bv = np.array([v[use][idx == b].mean() for b in range(edges.size - 1) if np.any(idx == b)])
    cnt = np.array([np.sum(idx == b) for b in range(edges.size - 1) if np.any(idx == b)])
    # Each bin's mean variance has a relative standard error sqrt(2 / (dof * pixels)).
    dof = successive_difference_dof(n_frames / len(stacks))
    sig = bv * np.sqrt(2.0 / (dof * 4 * cnt))

    def resid(p):
        return (p[0] * bm + p[1] - bv) / sig

    fit = least_squares(resid, [max(bv[-1] - bv[0], 1e-6) / max(bm[-1] - bm[0], 1e-6),
                                max(bv[0], QUANTISATION_DN2)], loss="soft_l1", f_scale=3.0)
    slope, icpt = fit.x
    jac = fit.jac
    cov = np.linalg.pinv(jac.T @ jac)
    if not slope > 0:
        raise InvalidInputError("stacks", "the variance does not grow with the intensity: no "
                                "shot noise seen (frames identical, or all dark)")
    g = 1.0 / slope
    read2 = (icpt - QUANTISATION_DN2) * g**2 / 2.0
    read = float(np.sqrt(max(read2, 0.0)))
    g_se = float(np.sqrt(cov[0, 0])) * g**2
    d_read = np.sqrt(max(cov[1, 1], 0.0)) * g**2 / (4.0 * max(read, 1e-9))
    pred = slope * bm + icpt
    nonlin = float(np.sqrt(np.mean(((bv - pred) / pred) ** 2)))
    dark = float(np.percentile(m, 0.5))
    # two parameters: fewer than three bins leave no degree of freedom to judge the fit by
    dof = bm.size - 2
    chi2 = float(np.sum(resid(fit.x) ** 2) / dof) if dof > 0 else float("inf")
    return NoiseCalibration(
        adc_gain_e_per_dn=float(g), read_noise_e=read, gain_std_error=g_se,
        read_noise_std_error=float(d_read), dark_signal_dn=dark,
        intensity_range_dn=(float(edges[0]), float(edges[-1])), nonlinearity=nonlin,
        frames=n_frames, method="differences", curve=(bm, bv), reduced_chi2=chi2)


def steepest_gradient(mean_c: np.ndarray) -> np.ndarray:
    """(H, W): the largest change across a pixel [DN/px] of the mean ``C_i`` images
    ``mean_c`` (4, H, W) over the four phase steps (central differences)."""
    gy, gx = np.gradient(np.asarray(mean_c, dtype=np.float64), axis=(-2, -1))
    return np.hypot(gx, gy).max(axis=0)


def flat_pixels(mean_dn: np.ndarray, var_dn2: np.ndarray, gradient_dn_per_px: np.ndarray,
                max_gradient_sigmas: float = FLAT_GRADIENT_SIGMAS) -> np.ndarray:
    """Which pixels (flat arrays of their mean intensity, temporal variance and
    :func:`steepest_gradient`) change across the pixel by at most ``max_gradient_sigmas``
    temporal standard deviations of the noise at their intensity.

    A scene that moves by ``d`` px between frames adds ``(gradient d)^2 / 2`` to a successive
    difference's variance: at 3 standard deviations per pixel and ``d`` = 0.05 px, 1 % of the
    noise; on the board's edges (hundreds of DN per pixel) the same motion is many times it
    (EMVA 1288 measures on a uniform target for this reason). The noise at an intensity is
    the median variance of the pixels in its bin (robust to the minority on edges), not the
    pixel's own: choosing pixels by their own variance would keep those whose variance came
    out high and bias the gain low.
    """
    if mean_dn.size == 0:
        return np.zeros(0, dtype=bool)
    edges = np.unique(np.quantile(mean_dn, np.linspace(0.0, 1.0, BINS + 1)))
    idx = np.clip(np.digitize(mean_dn, edges) - 1, 0, max(edges.size - 2, 0))
    reference = np.empty_like(var_dn2)
    for b in np.unique(idx):
        reference[idx == b] = np.median(var_dn2[idx == b])
    return gradient_dn_per_px <= max_gradient_sigmas * np.sqrt(np.maximum(reference, 0.0))


def successive_difference_variance(values: np.ndarray) -> np.ndarray:
    """The temporal variance of a stack, ``values`` (n, ...) in capture order, from its
    successive differences: ``sum_k (x_{k+1} - x_k)^2 / (2 (n - 1))`` (von Neumann's mean
    square successive difference; EMVA 1288 takes its temporal noise from the difference of
    two frames for the same reason).

    Unbiased for white noise like the sample variance, but blind to what changes slowly over
    the stack: a table still ringing at a few hertz under frames at 45 fps, a warm-up drift. On
    the rig sweep's reality 203 (the table ringing 0.125 deg at 2.1 Hz through the noise stack,
    24 frames) the sample variance of the board's edge pixels was 2-11 times the noise's and
    the gain came out 58 % off. Needs n >= 2.
    """
    x = np.asarray(values, dtype=np.float64)
    d = np.diff(x, axis=0)
    return (d * d).sum(axis=0) / (2.0 * (x.shape[0] - 1))


def successive_difference_dof(n: float) -> float:
    """The degrees of freedom of :func:`successive_difference_variance` over ``n`` frames of
    white noise: ``2 (n - 1)^2 / (3 n - 4)`` (its variance ``sigma^4 (3 n - 4) / (n - 1)^2``
    against the chi-square's ``2 sigma^4 / dof``): 1 for two frames, as the sample variance's,
    about 2 n / 3 for many."""
    return 2.0 * (n - 1.0) ** 2 / (3.0 * n - 4.0)


def tap_difference_variance_dn2(intensity_dn: np.ndarray, adc_gain_e_per_dn: float,
                                read_noise_e: float) -> np.ndarray:
    """One frame's temporal variance of each tap difference C_i [DN^2] at mean intensity
    ``intensity_dn`` (the module docstring's photon transfer line:
    ``I / g + 2 sigma_r^2 / g^2 + 1/6``); a negative or non-finite intensity counts as 0 (no
    shot noise), so the variance is never below the read and quantisation noise.

    The phasor ``(C0 - C2) - 1j (C3 - C1)`` then has ``2 var(C)`` per component, the amplitude
    (half its magnitude) ``var(C) / 2``, and the phase ``var(C) / (2 a^2)`` at amplitude ``a``
    (seed eqs. 4-5): divide by the frames averaged.
    """
    if not (np.isfinite(adc_gain_e_per_dn) and adc_gain_e_per_dn > 0):
        raise InvalidInputError("adc_gain_e_per_dn", f"got {adc_gain_e_per_dn!r}; allowed: a "
                                "finite gain above 0 e-/DN")
    if not (np.isfinite(read_noise_e) and read_noise_e >= 0):
        raise InvalidInputError("read_noise_e", f"got {read_noise_e!r}; allowed: a finite "
                                "read noise of 0 e- or more")
    i = np.asarray(intensity_dn, dtype=np.float64)
    shot = np.where(np.isfinite(i), np.maximum(i, 0.0), 0.0) / adc_gain_e_per_dn
    return shot + 2.0 * read_noise_e**2 / adc_gain_e_per_dn**2 + QUANTISATION_DN2
