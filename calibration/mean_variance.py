"""Gain, read noise and an empirical noise model from the mean and variance of repeated frames,
after the peer paper's section 3.4 (Bulczak et al., "Quantified, interactive simulation of AMCW
ToF cameras including multipath effects", Sensors 2018), in EMVA 1288 terms.

The paper's procedure (section 3.4; its equations in that section are not numbered) is:

1. take many frames of a static view at several exposures,
2. subtract the dark image from every raw image (fixed-pattern offset),
3. transform the charge values into Freeman-Tukey (FT) space, ``y = sqrt(x) + sqrt(x + 1)``,
   which turns Poisson-distributed charges into approximately normal ones of variance 1,
4. per pixel, the mean and variance of ``y`` over the frames (the paper's Fig. 2),
5. fit the variance as a polynomial of the mean (degree 9 in the paper; it reports the fit's
   SSE and RMSE), which is then the noise model: a noise-free charge is transformed, a normal
   draw with the curve's variance added, and the value transformed back.

The charge values are those of the paper's eqs. 13-14 (N_A and N_B of each phase step, eq. 6),
here in DN as the simulator's frames carry them (``RawFrame.taps``). A camera's wire does not
deliver the taps, only their differences C_i and the intensity I (the mean tap sum over the
phase steps); there the intensity, itself a sum of Poisson charges, is the charge value.

Step 5's polynomial describes the curve; the camera's parameters come from fitting the physical
curve to the same FT-space points. A charge value x [DN] with mean mu (dark subtracted) has,
with g the conversion gain [e-/DN] (EMVA 1288's system gain K = 1/g [DN/e-]) and sigma_r the
read noise per tap [e-] (sim_core.sensor),

    tap:        var(x) = mu / g + sigma_r^2 / g^2 + 1/12
    intensity:  var(x) = mu / (4 g) + sigma_r^2 / (2 g^2) + 1/24 (+ 3/32 if rounded to DN)

(EMVA 1288 eq. 8: sigma_y^2 = K (mu_y - mu_y.dark) + sigma_y.dark^2; each rounded tap adds
1/12 DN^2, the wire's rounding of the quarter-DN intensity 3/32). In FT space the variance of
x is ``var_FT(mu) = Var[FT(X)]`` with X normal of that mean and variance (computed by
Gauss-Hermite quadrature, not by the first-order delta method, which is ~10 % off where the
read noise dominates); for large mu it tends to K (per tap): the variance-stabilised curve's
plateau is the system gain, its rise toward small means the read noise. The fit is a robust
weighted least-squares fit of (K, sigma_y.dark^2) to the binned FT variances, plus, given an
unclipped dark stack (a black level), its variance as the curve's value at zero (EMVA 1288).

Only samples in the linear range are used: below ``linear_share`` of the largest mean (the
pixel's SBI starts above, adding the compensation charge's own noise) and above the mean where
the charge is five of its standard deviations from zero (the sensor clips tap charges at 0,
which truncates the noise), found from a first linear photon-transfer fit of the upper range.
On frames (:func:`calibrate_mean_variance`) the upper end is found per pixel instead, from
where the variance leaves the linear photon transfer (the SBI's onset, :func:`_linear_limit`),
not from a share of the view's brightest pixel: a view far below the SBI (a board at 1 m in
the lab) would otherwise lose its bright pixels, and through the wire (one intensity per pixel,
not 16 taps) the fit would rest on the few hundred mixed pixels at the board's edges, a gain
that moved by +-17 % with the render's pixel jitter.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import Polynomial
from scipy.optimize import least_squares

from calibration.noise_gain import check_stack
from sim_core.errors import InvalidInputError
from sim_core.raw import RawFrame

#: bins of the FT-space curve the physical model is fitted to, spaced geometrically in the mean
#: (narrow where the curve bends, so that a bin's mean stands for its samples)
BINS = 60
#: share of the largest mean below which the linear range starts (:func:`_linear_limit`)
LINEAR_SHARE = 0.5
#: the lowest mean used is where the charge is this many standard deviations from zero
CLIP_SIGMAS = 5.0
#: the wire's darkest tap (seen through the intensity) this many standard deviations from zero:
#: a normal clipped 3 sigma below its mean keeps 99.75 % of its variance, and the darkest tap
#: is one of the 8 taps whose sum is the intensity (its share of the variance at most 1/4)
WIRE_CLIP_SIGMAS = 3.0
#: the linear range's upper end is searched in steps of this factor in the fuller tap ...
LIMIT_STEP = 2.0 ** 0.25
#: ... and ends at the first step whose variance is this much above the linear photon transfer
LIMIT_EXCESS = 0.05
#: the fewest samples (pixel x charge) the fit accepts
MIN_SAMPLES = 100
#: the paper's polynomial degree (section 3.4) and the range this fit allows
PAPER_DEGREE = 9
DEGREE_RANGE = (1, 15)
_GH_T, _GH_W = np.polynomial.hermite_e.hermegauss(40)
_GH_W = _GH_W / _GH_W.sum()


@dataclass(frozen=True)
class ChargeModel:
    """How a charge value's variance [DN^2] depends on gain and read noise:
    ``var = shot * mu / g + read * sigma_r^2 / g^2 + quantisation_dn2``."""

    name: str
    shot: float
    read: float
    quantisation_dn2: float


#: one tap of one phase step (the paper's N_A or N_B, eqs. 13-14), each rounded to DN
TAP = ChargeModel("taps", 1.0, 1.0, 1.0 / 12.0)
#: the intensity, the mean over 4 phase steps of the tap sum (seed eq. 6), quarter-DN steps
INTENSITY = ChargeModel("intensity", 0.25, 0.5, 1.0 / 24.0)
#: the same rounded to whole DN (the wire's 12-bit grey words)
INTENSITY_ROUNDED = ChargeModel("intensity", 0.25, 0.5, 1.0 / 24.0 + 3.0 / 32.0)


def freeman_tukey(x: np.ndarray) -> np.ndarray:
    """The Freeman-Tukey transform ``sqrt(x) + sqrt(x + 1)`` (paper section 3.4), x >= 0."""
    x = np.maximum(np.asarray(x, dtype=np.float64), 0.0)
    return np.sqrt(x) + np.sqrt(x + 1.0)


def inverse_freeman_tukey(y: np.ndarray) -> np.ndarray:
    """The inverse of :func:`freeman_tukey`: ``((y^2 - 1) / (2 y))^2`` for y >= 1."""
    y = np.maximum(np.asarray(y, dtype=np.float64), 1.0)
    return ((y * y - 1.0) / (2.0 * y)) ** 2


def ft_variance(mean: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """Variance in FT space of a normal charge of the given mean and variance [DN, DN^2]."""
    mu = np.asarray(mean, dtype=np.float64)[..., None]
    sd = np.sqrt(np.maximum(np.asarray(variance, dtype=np.float64), 0.0))[..., None]
    y = freeman_tukey(mu + sd * _GH_T)
    m1 = (y * _GH_W).sum(axis=-1)
    return np.maximum((y * y * _GH_W).sum(axis=-1) - m1 * m1, 0.0)


@dataclass(frozen=True)
class MeanVarianceFit:
    """What the mean-variance fit estimates (module docstring).

    Attributes
    ----------
    adc_gain_e_per_dn : float
        Conversion gain g = 1/K [e-/DN] (the sensor parameter).
    system_gain_dn_per_e : float
        EMVA 1288's K [DN/e-].
    read_noise_e : float
        Read noise per tap sigma_r [e-]. Without a dark stack the dark current's electrons are
        part of the signal and this is the read noise alone (the sensor parameter); with one
        (subtracted) it is EMVA 1288's sigma_d, dark-current shot noise included.
    gain_std_error, read_noise_std_error : float
        Standard errors of the two from the fit's covariance.
    dark_noise_dn2 : float
        sigma_y.dark^2 of one charge value as fitted [DN^2] (read noise and quantisation).
    dark_signal_dn : float or None
        EMVA 1288's mu_y.dark: the mean of the dark image, if a dark stack was given (it is then
        subtracted from every frame, as the paper does); None otherwise (offset taken as 0: the
        simulated and the PMD sensor's taps have no black level).
    dark_temporal_noise_dn : float or None
        Temporal standard deviation of the dark stack [DN], if given (EMVA's sigma_y.dark; on a
        sensor that clips at 0 without a black level this underestimates it).
    charge : str
        The charge values used: ``"taps"`` or ``"intensity"``.
    polynomial : numpy.polynomial.Polynomial
        The paper's empirical noise model: FT variance against FT mean.
    polynomial_sse, polynomial_rmse : float
        The polynomial's sum of squared errors and RMS error over the samples (the paper
        reports SSE 0.0391, RMSE 0.0112 for its camera).
    mean_range_dn : (float, float)
        The range of (dark-subtracted) means used.
    nonlinearity : float
        RMS relative deviation of the binned FT variances from the physical model.
    samples, frames : int
        Samples (pixel x charge value) used; frames in the stacks.
    curve : (3, n_bins) ndarray
        Binned mean [DN], FT mean and FT variance (for the plot).
    """

    adc_gain_e_per_dn: float
    system_gain_dn_per_e: float
    read_noise_e: float
    gain_std_error: float
    read_noise_std_error: float
    dark_noise_dn2: float
    dark_signal_dn: float | None
    dark_temporal_noise_dn: float | None
    charge: str
    polynomial: Polynomial
    polynomial_sse: float
    polynomial_rmse: float
    mean_range_dn: tuple[float, float]
    nonlinearity: float
    samples: int
    frames: int
    curve: np.ndarray
    method: str = "mean-variance (Freeman-Tukey, peer paper 3.4)"

    def to_sensor_overrides(self) -> dict:
        return {"adc_gain_e_per_dn": self.adc_gain_e_per_dn, "read_noise_e": self.read_noise_e}

    def ft_variance_model(self, ft_mean: np.ndarray) -> np.ndarray:
        """The paper's noise model: FT-space variance at an FT-space mean (the polynomial,
        held constant beyond the range it was fitted on)."""
        lo, hi = self.polynomial.domain
        return np.maximum(self.polynomial(np.clip(ft_mean, lo, hi)), 0.0)

    def add_noise(self, charges_dn: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy charges from noise-free ones the paper's way (section 3.4): to FT space, a
        normal draw of the model's variance added, back to charges."""
        y = freeman_tukey(charges_dn)
        y = y + np.sqrt(self.ft_variance_model(y)) * rng.standard_normal(y.shape)
        return inverse_freeman_tukey(y)

    def summary(self) -> dict:
        return {"adc_gain_e_per_dn": self.adc_gain_e_per_dn,
                "system_gain_dn_per_e": self.system_gain_dn_per_e,
                "read_noise_e": self.read_noise_e, "gain_std_error": self.gain_std_error,
                "read_noise_std_error": self.read_noise_std_error,
                "dark_noise_dn2": self.dark_noise_dn2, "dark_signal_dn": self.dark_signal_dn,
                "dark_temporal_noise_dn": self.dark_temporal_noise_dn, "charge": self.charge,
                "polynomial_degree": self.polynomial.degree(),
                "polynomial_sse": self.polynomial_sse, "polynomial_rmse": self.polynomial_rmse,
                "mean_range_dn": list(self.mean_range_dn),
                "nonlinearity_rms_rel": self.nonlinearity, "samples": self.samples,
                "frames": self.frames, "method": self.method}

    def plot(self, ax) -> str:
        _, ftm, ftv = self.curve
        ax.plot(ftm, ftv, "o", ms=3)
        x = np.linspace(*self.polynomial.domain, 100)
        ax.plot(x, self.ft_variance_model(x), "-")
        ax.axhline(self.system_gain_dn_per_e, ls=":", lw=1)
        ax.set_xlabel("mean in Freeman-Tukey space")
        ax.set_ylabel("variance in Freeman-Tukey space")
        return (f"Mean-variance (FT): gain {self.adc_gain_e_per_dn:.2f} e-/DN, read noise "
                f"{self.read_noise_e:.1f} e-")


def fit_mean_variance(
    stacks: Sequence[np.ndarray],
    *,
    model: ChargeModel = TAP,
    dark: np.ndarray | None = None,
    usable: Sequence[np.ndarray] | None = None,
    degree: int = PAPER_DEGREE,
    linear_share: float = LINEAR_SHARE,
    field: str = "stacks",
) -> MeanVarianceFit:
    """Fit gain and read noise from stacks of charge values [DN] (module docstring).

    Parameters
    ----------
    stacks : sequence of (n_frames, ...) arrays
        Each a stack of repeated frames of one static view (one exposure or source level);
        every element after the first axis is one sample (a pixel's tap, say).
    model : ChargeModel
        What a value is (:data:`TAP`, :data:`INTENSITY`, :data:`INTENSITY_ROUNDED`).
    dark : (n_dark, ...) array, optional
        A dark stack of the same sample shape: its mean image is subtracted from every frame
        (the paper's step 2) and reported as the dark signal.
    usable : sequence of bool arrays, optional
        Per stack, the samples that are neither saturated nor in the SBI limit (sample shape).
    degree : int
        Degree of the paper's polynomial (9 in the paper), 1 to 15.
    linear_share : float
        Share of the largest mean used (0 < share <= 1).

    Raises
    ------
    InvalidInputError
        A stack with fewer than 2 frames, non-finite values, too few unsaturated samples in
        the linear range, a range too narrow for a curve, or a variance that does not grow
        with the mean.
    """
    lo_deg, hi_deg = DEGREE_RANGE
    if not (isinstance(degree, (int, np.integer)) and lo_deg <= degree <= hi_deg):
        raise InvalidInputError("degree", f"{degree!r}: must be an integer from {lo_deg} to "
                                f"{hi_deg} (the paper uses {PAPER_DEGREE})")
    if not 0.0 < linear_share <= 1.0:
        raise InvalidInputError("linear_share", f"{linear_share}: must be in (0, 1]")
    if len(stacks) == 0:
        raise InvalidInputError(field, "no stacks: at least one stack of 2 or more frames")
    dark_mean = None
    dark_sd = None
    dark_point = None
    if dark is not None:
        d = _checked(dark, "dark")
        dark_mean = d.mean(axis=0)
        dark_var = d.var(axis=0, ddof=1)
        dark_sd = float(np.sqrt(dark_var.mean()))
        # Unclipped (a black level), the dark stack's variance is sigma_y.dark^2 itself: the
        # curve's value at zero (EMVA 1288's dark measurement), fitted with the FT points.
        if np.all(d > 0.0):
            dark_point = (float(dark_var.mean()), (d.shape[0] - 1.0) * dark_var.size)
    m_all, v_all, fm_all, fv_all, dof_all = [], [], [], [], []
    n_frames = 0
    for i, s in enumerate(stacks):
        x = _checked(s, f"{field}[{i}]")
        if dark_mean is not None:
            if dark_mean.shape != x.shape[1:]:
                raise InvalidInputError("dark", f"samples of shape {dark_mean.shape} do not "
                                        f"match {field}[{i}]'s {x.shape[1:]}")
            x = x - dark_mean
        ok = np.ones(x.shape[1:], dtype=bool) if usable is None else np.asarray(usable[i])
        if ok.shape != x.shape[1:]:
            raise InvalidInputError(f"usable[{i}]", f"shape {ok.shape}; must be {x.shape[1:]}")
        # A sample clipped at zero in any frame has a truncated noise (and is not in FT space).
        ok = ok & (x.min(axis=0) > 0.0)
        y = freeman_tukey(x)
        m_all.append(x.mean(axis=0)[ok])
        v_all.append(x.var(axis=0, ddof=1)[ok])
        fm_all.append(y.mean(axis=0)[ok])
        fv_all.append(y.var(axis=0, ddof=1)[ok])
        dof_all.append(np.full(int(ok.sum()), x.shape[0] - 1.0))
        n_frames += x.shape[0]
    m, v, fm, fv, dof = (np.concatenate(a) for a in (m_all, v_all, fm_all, fv_all, dof_all))
    total = sum(int(np.prod(np.shape(s)[1:])) for s in stacks)
    if m.size < MIN_SAMPLES:
        raise InvalidInputError(
            field, f"only {m.size} of {total} samples are unsaturated and above zero in every "
            f"frame; at least {MIN_SAMPLES} are needed (a view with mid-grey areas, not "
            "saturated)")
    top = linear_share * float(np.percentile(m, 99.9))
    # First pass: a linear photon-transfer fit of the upper range finds where clipping at zero
    # stops mattering.
    upper = (m >= 0.25 * top) & (m <= top)
    slope0, icpt0 = _linear_ptc(m[upper], v[upper], field)
    bottom = 0.5 * (CLIP_SIGMAS**2 * slope0
                    + np.sqrt(CLIP_SIGMAS**4 * slope0**2 + 4 * CLIP_SIGMAS**2 * max(icpt0, 0)))
    bottom = max(bottom, 1.0)
    use = (m >= bottom) & (m <= top)
    if np.count_nonzero(use) < MIN_SAMPLES:
        raise InvalidInputError(
            field, f"only {np.count_nonzero(use)} samples have a mean between {bottom:.0f} and "
            f"{top:.0f} DN (the linear range); at least {MIN_SAMPLES} are needed")
    edges = np.geomspace(bottom, top, BINS + 1)
    idx = np.clip(np.digitize(m[use], edges) - 1, 0, BINS - 1)
    cnt = np.bincount(idx, minlength=BINS).astype(float)
    keep = cnt >= 3
    if np.count_nonzero(keep) < 3 or top < 2.0 * bottom:
        raise InvalidInputError(
            field, f"the samples' means span {bottom:.0f}-{top:.0f} DN in "
            f"{np.count_nonzero(keep)} bins: too narrow a range for a curve (at least 3 "
            "levels, the brightest at least twice the darkest; use a view with bright and "
            "dark areas or several exposures)")

    def per_bin(a):
        return np.bincount(idx, weights=a, minlength=BINS)[keep] / cnt[keep]

    bm, bfm, bfv = per_bin(m[use]), per_bin(fm[use]), per_bin(fv[use])
    bdof = per_bin(dof[use]) * cnt[keep]
    # Each bin's mean variance has a relative standard error sqrt(2 / (dof * samples)).
    rel = np.sqrt(2.0 / bdof)
    q = model.quantisation_dn2

    def predict(p):
        k, s2 = p
        return ft_variance(bm, model.shot * k * bm + model.read * s2 + q)

    def resid(p):
        pred = predict(p)
        r = (pred - bfv) / (pred * rel)
        if dark_point is None:
            return r
        v0 = model.read * p[1] + q
        return np.append(r, (v0 - dark_point[0]) / (v0 * np.sqrt(2.0 / dark_point[1])))

    k0 = max(slope0 / model.shot, 1e-9)
    s0 = max((icpt0 - q) / model.read, 0.0)
    fit = least_squares(resid, [k0, s0], bounds=([1e-12, 0.0], [np.inf, np.inf]),
                        loss="soft_l1", f_scale=3.0, x_scale=[k0, max(s0, 1e-3 * k0 * top)])
    k, s2 = (float(a) for a in fit.x)
    cov = np.linalg.pinv(fit.jac.T @ fit.jac)
    g = 1.0 / k
    read = float(np.sqrt(s2)) * g
    g_se = float(np.sqrt(max(cov[0, 0], 0.0))) * g**2
    # sigma_r = sqrt(s2) / k: first-order error propagation.
    grad = np.array([-read / k, g / (2.0 * np.sqrt(s2))]) if s2 > 0 else np.array([0.0, g])
    r_se = float(np.sqrt(max(grad @ cov @ grad, 0.0)))
    pred = predict(fit.x)
    nonlin = float(np.sqrt(np.mean(((bfv - pred) / pred) ** 2)))
    # The paper's empirical curve (its Fig. 2): a polynomial of the FT mean, on the samples.
    poly = Polynomial.fit(fm[use], fv[use], int(degree))
    res = poly(fm[use]) - fv[use]
    return MeanVarianceFit(
        adc_gain_e_per_dn=float(g), system_gain_dn_per_e=k, read_noise_e=read,
        gain_std_error=g_se, read_noise_std_error=r_se,
        dark_noise_dn2=float(model.read * s2 + q),
        dark_signal_dn=None if dark_mean is None else float(dark_mean.mean()),
        dark_temporal_noise_dn=dark_sd, charge=model.name, polynomial=poly,
        polynomial_sse=float(np.sum(res**2)), polynomial_rmse=float(np.sqrt(np.mean(res**2))),
        mean_range_dn=(float(bottom), float(top)), nonlinearity=nonlin,
        samples=int(np.count_nonzero(use)), frames=n_frames, curve=np.stack([bm, bfm, bfv]))


def calibrate_mean_variance(
    stacks: Sequence[Sequence[RawFrame]],
    dark: Sequence[RawFrame] | None = None,
    degree: int = PAPER_DEGREE,
) -> MeanVarianceFit:
    """The mean-variance fit on stacks of frames (the rig sequence's noise stacks).

    The charge values are the taps of every phase step and frequency where all frames carry
    them (the simulator's frames), else the intensity (a camera's wire: rounded to whole DN).
    Left out are pixels saturated or in the SBI limit in any frame, pixels whose fuller tap is
    above the linear range (:func:`_linear_limit`: where the variance leaves the linear
    photon transfer, the SBI's onset), and for the intensity pixels whose darkest tap may clip
    at zero (:func:`_taps_unclipped`).
    """
    if len(stacks) == 0:
        raise InvalidInputError("stacks", "no stacks: at least one stack of 2 or more frames")
    all_frames = [f for s in stacks for f in s] + list(dark or [])
    with_taps = all(f.taps is not None for f in all_frames)
    values, usable = [], []
    for i, stack in enumerate(stacks):
        check_stack(stack, i)
        x = _charges(stack, with_taps)
        bad = np.any([f.saturated | f.sbi_limit for f in stack], axis=0)
        # SBI acts on both taps of a pixel once the fuller one passes n_SBI,start.
        if with_taps:
            fuller = x.mean(axis=0).max(axis=0)
        else:
            fuller = 0.5 * (x[:, 0].mean(axis=0) + _abs_differences(stack).max(axis=0))
            bad = bad | ~_taps_unclipped(stack, x[:, 0], ~bad, f"stacks[{i}]")
        ok = ~bad & (fuller < _linear_limit(x, fuller, ~bad, f"stacks[{i}]"))
        values.append(x)
        usable.append(np.broadcast_to(ok, x.shape[1:]))
    if with_taps:
        model = TAP
    else:
        grey = np.concatenate([v.ravel() for v in values])
        model = INTENSITY_ROUNDED if np.all(grey == np.rint(grey)) else INTENSITY
    dark_values = None
    if dark is not None:
        if len(dark) < 2:
            raise InvalidInputError("dark", f"{len(dark)} frame(s) are too short for a "
                                    "variance: at least 2 are needed")
        dark_values = _charges(list(dark), with_taps)
    # The linear range is already cut per pixel (its fuller tap).
    return fit_mean_variance(values, model=model, dark=dark_values, usable=usable,
                             degree=degree, linear_share=1.0)


def _abs_differences(stack: Sequence[RawFrame]) -> np.ndarray:
    """(n_f * 4, H, W): each tap difference's magnitude |C_i| averaged over the frames."""
    c = np.mean([np.abs(np.asarray(f.phase_images, dtype=np.float64)) for f in stack], axis=0)
    return c.reshape(-1, *c.shape[-2:])


def _taps_unclipped(stack: Sequence[RawFrame], grey: np.ndarray, ok: np.ndarray,
                    field: str) -> np.ndarray:
    """Pixels whose darkest tap stays clear of zero, from frames without taps.

    The intensity's noise is truncated where a tap clips at 0, which its own spread does not
    show: the darkest tap's mean, min_i (I - |C_i|) / 2, must be :data:`WIRE_CLIP_SIGMAS` of
    its standard deviation from zero. A tap's variance is at most twice the intensity's (module
    docstring), taken from a linear fit of the intensity's variance over the bright range (not
    from each pixel's own variance, which would select pixels by their noise).
    """
    mean_i = grey.mean(axis=0)
    darkest = 0.5 * (mean_i - _abs_differences(stack).max(axis=0))
    m, v = mean_i[ok], grey.var(axis=0, ddof=1)[ok]
    top = float(np.percentile(m, 99.9)) if m.size else 0.0
    upper = (m >= 0.25 * top) & (m <= top)
    slope, icpt = _linear_ptc(m[upper], v[upper], field)
    return darkest >= WIRE_CLIP_SIGMAS * np.sqrt(2.0 * np.maximum(slope * mean_i + icpt, 0.0))


def _linear_limit(x: np.ndarray, fuller: np.ndarray, ok: np.ndarray, field: str) -> float:
    """The fuller tap's level [DN] where the charge values leave the linear photon transfer.

    The SBI (sim_core.sensor) removes a compensation charge n_delta = A - n_SBI,start, a
    Poisson draw of its own, from both taps once the fuller tap A passes n_SBI,start: a phase
    step's tap sum then has the mean B - A + 2 n_SBI,start and the variance
    3 A + B - 2 n_SBI,start [e-^2], 4 n_delta above the linear photon transfer, which is what
    marks the end of the linear range (EMVA 1288's linear range ends at saturation likewise).
    Where n_SBI,start is in DN is not known before the gain, nor where a view's brightest
    pixel is against it, so the range is found from the data: the linear photon transfer of
    the pixels below :data:`LINEAR_SHARE` of the brightest, then steps of :data:`LIMIT_STEP`
    in the fuller tap upward, each accepted (and the line fitted again with it) while its
    summed variance is within :data:`LIMIT_EXCESS` (or 4 standard errors) of the line's, the
    first excess ending the range at the last step tested before it (steps of fewer than a
    tenth of :data:`MIN_SAMPLES` values are not tested). ``inf`` if the whole unsaturated
    range is linear.
    """
    if not np.any(ok):
        return np.inf
    clear = ok & np.all(x.min(axis=0) > 0.0, axis=0)
    m_all, v_all = x.mean(axis=0), x.var(axis=0, ddof=1)
    dof = x.shape[0] - 1.0
    top = float(np.percentile(fuller[ok], 99.9))
    limit = LINEAR_SHARE * top
    accepted = clear & (fuller < limit)
    safe = limit  # the end of the last step tested and found linear
    while limit <= float(fuller[ok].max()):
        nxt = limit * LIMIT_STEP
        step = clear & (fuller >= limit) & (fuller < nxt)
        n_values = int(step.sum()) * x.shape[1]
        if np.count_nonzero(accepted) * x.shape[1] < MIN_SAMPLES:
            return limit
        if n_values >= MIN_SAMPLES // 10:
            m, v = m_all[:, accepted].ravel(), v_all[:, accepted].ravel()
            upper = m >= 0.25 * float(np.percentile(m, 99.9))
            slope, icpt, cov = _linear_ptc(m[upper], v[upper], field, with_cov=True)
            ms, vs = m_all[:, step].ravel(), v_all[:, step].ravel()
            pred = np.maximum(slope * ms + icpt, 1e-12)
            excess = vs.sum() / pred.sum() - 1.0
            # The line's own uncertainty at the step's mean level, and the step's sampling.
            g = np.array([ms.mean(), 1.0])
            se = np.hypot(np.sqrt(max(g @ cov @ g, 0.0)) / pred.mean(),
                          np.sqrt(2.0 / (dof * ms.size)))
            if excess > max(LIMIT_EXCESS, 4.0 * se):
                return safe
            safe = nxt
        accepted = accepted | step
        limit = nxt
    return np.inf


def _charges(frames: Sequence[RawFrame], with_taps: bool) -> np.ndarray:
    """(n, k, H, W): every tap of every phase step and frequency, or the intensity (k = 1)."""
    if with_taps:
        return np.stack([np.asarray(f.taps, dtype=np.float64).reshape(-1, *f.shape)
                         for f in frames])
    return np.stack([np.asarray(f.intensity, dtype=np.float64)[None] for f in frames])


def _checked(stack: np.ndarray, field: str) -> np.ndarray:
    x = np.asarray(stack, dtype=np.float64)
    if x.ndim < 2 or x.shape[0] < 2:
        n = x.shape[0] if x.ndim >= 1 else 0
        raise InvalidInputError(field, f"{n} frame(s) are too short for a variance: at least "
                                "2 (better 16 or more) frames along the first axis are needed")
    bad = int(np.count_nonzero(~np.isfinite(x)))
    if bad:
        raise InvalidInputError(field, f"{bad} non-finite values: every value must be finite")
    return x


def _linear_ptc(m: np.ndarray, v: np.ndarray, field: str, with_cov: bool = False):
    """Slope and intercept of the variance against the mean (binned, least squares); with
    ``with_cov`` also their covariance (scaled by the residuals)."""
    if m.size < MIN_SAMPLES:
        raise InvalidInputError(
            field, f"only {m.size} samples in the upper linear range; at least {MIN_SAMPLES} "
            "are needed (a view with bright and dark areas, not saturated)")
    edges = np.linspace(m.min(), m.max(), 21)
    idx = np.clip(np.digitize(m, edges) - 1, 0, 19)
    cnt = np.bincount(idx, minlength=20)
    keep = cnt > 0
    if np.count_nonzero(keep) < 2 or m.max() - m.min() <= 0.0:
        raise InvalidInputError(field, "all samples have the same mean: too narrow a range "
                                "for a curve (at least 3 levels are needed)")
    bm = np.bincount(idx, weights=m, minlength=20)[keep] / cnt[keep]
    bv = np.bincount(idx, weights=v, minlength=20)[keep] / cnt[keep]
    w = np.sqrt(cnt[keep]) / np.maximum(bv, 1e-12)
    if with_cov and bm.size > 3:
        (slope, icpt), cov = np.polyfit(bm, bv, 1, w=w, cov=True)
    else:
        slope, icpt = np.polyfit(bm, bv, 1, w=w)
        cov = np.zeros((2, 2))
    if not slope > 0.0:
        raise InvalidInputError(
            field, f"the variance does not grow with the mean (slope {slope:.3g} DN; it must "
            "be > 0): no shot noise seen (frames identical, or all dark)")
    if with_cov:
        return float(slope), float(icpt), cov
    return float(slope), float(icpt)
