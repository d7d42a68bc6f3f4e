"""Comparison of a measured and a simulated ToF frame: the indexes of seed Table 5 and a chi-square.

Physics side only: pure functions over arrays, no I/O.

What is compared (ToF seed, Sect. 3, Table 5: "mean, variance, MSE, SSIM and PSNR of the grey
image and depth image"):

* the **grey image**: the amplitude converted to the camera tools' 8-bit grey
  (:func:`grey_8bit`, data range R = 255);
* the **depth image**: the range converted to the camera tools' 16-bit depth in millimetres, 0
  where invalid (:func:`depth_mm_16bit`, data range R = 65535).

The seed removed the background of the measured image by hand; here a boolean mask says which
pixels count (:func:`mask_by_depth_window`, :func:`mask_by_region`, :func:`mask_from_objects`),
and it is always intersected with both frames' ``valid`` masks (:func:`effective_mask`).

Equations (M = pixels of the effective mask, n = |M|, x = measured, y = simulated image):

* (M1) mean  mu = (1/n) sum_M x;   (M2) variance  var = (1/n) sum_M (x - mu)^2 (population, ddof 0)
* (M3) MSE = (1/n) sum_M (y - x)^2
* (M4) PSNR = 10 log10(R^2 / MSE) [dB], +inf when MSE = 0
* (M5) SSIM: Wang et al. (2004) as computed by ``skimage.metrics.structural_similarity``
  (7x7 uniform window, K1 = 0.01, K2 = 0.03, explicit ``data_range`` R), averaged over M
  (see :func:`masked_ssim` for how the mask is applied)
* (M6) relative error |y_stat - x_stat| / |x_stat| (the "Error" columns of Table 5)
* (M7) chi-square of the grey histograms, from the SLIM paper (planetary seed, Sect. 10,
  "Statistical Analysis"): chi2_s = sum_k (f_k - N p_k)^2 / (N p_k)  -- its Eq. (16) by count;
  see :func:`pearson_chi_square` and :func:`chi_square_distance`.

Beside Table 5, what a ToF engineer reads (:class:`ToFFigures`, :func:`tof_figures`): the depth
difference (simulated - measured) in millimetres over the mask's pixels that are valid in both
frames and flying in neither (:mod:`sim_core.flying_pixels`): its median, median absolute
deviation and 95th percentile of the absolute difference; and the share of flying and of
invalid pixels of each frame inside the mask. Table 5's depth PSNR uses the 16-bit range of
65,535 mm, so a 100 mm RMSE still reads 56 dB; these figures are in the unit the camera is
specified in.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np
from skimage.metrics import structural_similarity

from sim_core.errors import InvalidInputError
from sim_core.flying_pixels import DEFAULT_RULE, FlyingPixelRule, flying_pixels
from sim_core.frame_io import GREY_FULL_SCALE_PERCENTILE, depth_preview_mm, grey_preview_8bit
from sim_core.json_safe import json_safe
from sim_core.tof import ToFImage

GREY_DATA_RANGE = 255.0
"""Data range R of the 8-bit grey image (PSNR, SSIM)."""

DEPTH_DATA_RANGE = 65535.0
"""Data range R of the 16-bit depth image (PSNR, SSIM)."""

SSIM_WIN_SIZE = 7
"""Side of scikit-image's default (uniform) SSIM window."""

TABLE_HEADER: tuple[str, str, str, str, str] = ("Image", "Index", "Measured", "Simulated", "Error")
"""Column titles of :meth:`ComparisonReport.table_rows` (the layout of seed Table 5)."""

_NOT_APPLICABLE = "—"


# --------------------------------------------------------------------------------------------
# Conversion to the camera tools' conventions (reusing sim_core.frame_io)
# --------------------------------------------------------------------------------------------


def grey_8bit(amplitude: np.ndarray, full_scale: float) -> np.ndarray:
    """8-bit grey image ``round(amplitude / full_scale * 255)``, clipped to [0, 255].

    Same conversion as :func:`sim_core.frame_io.grey_preview_8bit` (which it calls), but the full
    scale is mandatory, so that two images converted with the same full scale are comparable.
    Non-finite amplitudes give 0.

    >>> grey_8bit(np.array([0.0, 0.5, 2.0, np.nan]), full_scale=1.0).tolist()
    [0, 128, 255, 0]

    Raises
    ------
    InvalidInputError
        ``full_scale`` not a finite number > 0.
    """
    fs = _positive_finite("full_scale", full_scale)
    amp = np.asarray(amplitude, dtype=np.float64)
    img, _ = grey_preview_8bit(amp, np.isfinite(amp), fs)
    return img


def depth_mm_16bit(range_m: np.ndarray) -> np.ndarray:
    """16-bit depth image in millimetres, 0 where invalid (NaN), clipped to [0, 65535].

    This is :func:`sim_core.frame_io.depth_preview_mm`, re-exported under the name used here.
    """
    return depth_preview_mm(np.asarray(range_m, dtype=np.float64))


def depth_16bit(range_m: np.ndarray, unit_m: float = 1e-3) -> np.ndarray:
    """16-bit depth image ``round(range / unit_m)``, 0 where invalid, clipped to [0, 65535].

    ``unit_m = 1e-3`` (the default) is exactly :func:`depth_mm_16bit`; other units (e.g. 1e-4 for
    0.1 mm steps) rescale before the same conversion.

    >>> depth_16bit(np.array([1.5, np.nan, 70.0])).tolist()  # mm; NaN -> 0; 70 m clips
    [1500, 0, 65535]
    >>> depth_16bit(np.array([1.5]), unit_m=1e-4).tolist()  # 0.1 mm steps
    [15000]
    >>> depth_16bit(np.array([1.5]), unit_m=0.0)
    Traceback (most recent call last):
    ...
    sim_core.errors.InvalidInputError: depth_unit: got 0.0; allowed: a finite number > 0
    """
    unit = _positive_finite("depth_unit", unit_m)
    rng = np.asarray(range_m, dtype=np.float64)
    if unit == 1e-3:
        return depth_mm_16bit(rng)
    return depth_mm_16bit(rng * (1e-3 / unit))


# --------------------------------------------------------------------------------------------
# Masks
# --------------------------------------------------------------------------------------------


def mask_by_depth_window(range_m: np.ndarray, near_m: float, far_m: float) -> np.ndarray:
    """Pixels whose range lies in the closed window [near_m, far_m]; NaN (invalid) gives False.

    Raises
    ------
    InvalidInputError
        ``near_m`` or ``far_m`` NaN, or ``far_m <= near_m``.
    """
    near = float(near_m)
    far = float(far_m)
    if math.isnan(near):
        raise InvalidInputError("near_m", "got NaN; allowed: a number < far_m")
    if math.isnan(far) or not far > near:
        raise InvalidInputError("far_m", f"got {far!r}; allowed: a number > near_m = {near!r}")
    rng = np.asarray(range_m, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return (rng >= near) & (rng <= far)


def mask_by_region(
    shape: tuple[int, int], rows: tuple[int, int], cols: tuple[int, int]
) -> np.ndarray:
    """Rectangle ``rows[0] <= r < rows[1]``, ``cols[0] <= c < cols[1]`` (half-open, as slices).

    Raises
    ------
    InvalidInputError
        ``shape`` not two positive ints, or a bound outside ``0 <= start < stop <= size``.
    """
    if len(shape) != 2 or any(int(s) != s or s <= 0 for s in shape):
        raise InvalidInputError("shape", f"got {tuple(shape)!r}; allowed: (height, width) > 0")
    h, w = int(shape[0]), int(shape[1])
    for name, (start, stop), size in (("rows", rows, h), ("cols", cols, w)):
        if not (int(start) == start and int(stop) == stop and 0 <= start < stop <= size):
            raise InvalidInputError(
                name, f"got ({start!r}, {stop!r}); allowed: integers 0 <= start < stop <= {size}"
            )
    mask = np.zeros((h, w), dtype=bool)
    mask[int(rows[0]) : int(rows[1]), int(cols[0]) : int(cols[1])] = True
    return mask


def mask_from_objects(object_id: np.ndarray, ids: Iterable[int]) -> np.ndarray:
    """Pixels whose ``object_id`` (the render's per-pixel object index, -1 for none) is in ``ids``.

    Raises
    ------
    InvalidInputError
        ``object_id`` not an integer array, or ``ids`` empty or not integers.
    """
    obj = np.asarray(object_id)
    if not np.issubdtype(obj.dtype, np.integer):
        raise InvalidInputError(
            "object_id", f"dtype {obj.dtype} not allowed; allowed: an integer array"
        )
    wanted = np.asarray(list(ids))
    if wanted.size == 0 or not np.issubdtype(wanted.dtype, np.integer):
        raise InvalidInputError(
            "ids", f"got {wanted.tolist()!r}; allowed: a non-empty list of integer object ids"
        )
    return np.isin(obj, wanted)


def effective_mask(mask: np.ndarray | None, measured: ToFImage, simulated: ToFImage) -> np.ndarray:
    """``mask & measured.valid & simulated.valid`` (``mask=None`` means the whole frame).

    Raises
    ------
    InvalidInputError
        Frames of different shape, ``mask`` not a boolean array of the frames' shape, or no pixel
        left (field ``"mask"``).
    """
    shape = _check_frames(measured, simulated)
    user = np.ones(shape, dtype=bool) if mask is None else _check_mask(mask, shape)
    eff = user & np.asarray(measured.valid) & np.asarray(simulated.valid)
    if not eff.any():
        raise InvalidInputError(
            "mask",
            f"{int(user.sum())} pixel(s) selected but none is valid in both frames; allowed: a "
            "mask with at least one pixel valid in the measured and the simulated frame",
        )
    return eff


# --------------------------------------------------------------------------------------------
# Scalar metrics
# --------------------------------------------------------------------------------------------


def psnr_db(mse: float, data_range: float) -> float:
    """Peak signal-to-noise ratio 10 log10(R^2 / MSE) in dB (eq. M4).

    Same formula as ``skimage.metrics.peak_signal_noise_ratio`` with an explicit ``data_range``,
    but from a given (masked) MSE. MSE = 0 (identical images) gives ``math.inf``, without a
    division warning.

    Raises
    ------
    InvalidInputError
        ``mse`` negative or NaN, or ``data_range`` not finite > 0.
    """
    r = _positive_finite("data_range", data_range)
    e = float(mse)
    if math.isnan(e) or e < 0.0:
        raise InvalidInputError("mse", f"got {e!r}; allowed: a number >= 0")
    if e == 0.0:
        return math.inf
    return 10.0 * math.log10(r * r / e)


def relative_error(measured: float, simulated: float) -> float:
    """|simulated - measured| / |measured| (eq. M6; multiply by 100 for Table 5's percent).

    Safe at ``measured == 0``: returns 0.0 when ``simulated`` is also exactly equal (no error),
    ``math.inf`` otherwise. Never NaN for finite inputs.
    """
    m, s = float(measured), float(simulated)
    if s == m:
        return 0.0
    if m == 0.0:
        return math.inf
    return abs(s - m) / abs(m)


def masked_mse(measured: np.ndarray, simulated: np.ndarray, mask: np.ndarray) -> float:
    """Mean squared difference over the mask (eq. M3), in float64."""
    _check_pair(measured, simulated, mask)
    a = np.asarray(measured, dtype=np.float64)[mask]
    b = np.asarray(simulated, dtype=np.float64)[mask]
    return float(np.mean((b - a) ** 2))


def masked_ssim(
    measured: np.ndarray,
    simulated: np.ndarray,
    mask: np.ndarray,
    data_range: float,
    win_size: int = SSIM_WIN_SIZE,
) -> float:
    """Mean SSIM restricted to a mask (eq. M5).

    Procedure: (1) both images are set to the same background value, 0, outside the mask;
    (2) the SSIM map is computed over the full images by ``skimage.metrics.structural_similarity``
    (``data_range`` explicit, uniform ``win_size`` window, K1 = 0.01, K2 = 0.03, sample
    covariance: scikit-image's defaults); (3) the map is averaged over the mask pixels that are at
    least ``(win_size - 1) // 2`` pixels from the image border, the strip that scikit-image itself
    leaves out of its mean. With a full mask the result therefore *equals* scikit-image's mean
    SSIM. If the mask lies entirely inside that border strip, the whole mask is averaged.

    Consequences of (1): pixels outside the mask cannot influence the result (their values are
    overwritten), and windows straddling the mask edge see the identical zero background in both
    images, as in the seed, whose measured background was "eliminated manually".
    """
    _check_pair(measured, simulated, mask)
    shape = np.shape(measured)
    if int(win_size) != win_size or win_size < 3 or win_size % 2 == 0 or win_size > min(shape):
        raise InvalidInputError(
            "win_size",
            f"got {win_size!r} for images of shape {shape}; allowed: an odd integer >= 3 and "
            "<= the smaller image side",
        )
    a = np.where(mask, np.asarray(measured, dtype=np.float64), 0.0)
    b = np.where(mask, np.asarray(simulated, dtype=np.float64), 0.0)
    _, ssim_map = structural_similarity(
        a, b, data_range=float(data_range), win_size=win_size, full=True
    )
    pad = (win_size - 1) // 2
    inner = np.zeros_like(mask)
    inner[pad : mask.shape[0] - pad, pad : mask.shape[1] - pad] = True
    sel = mask & inner
    if not sel.any():
        sel = mask
    return float(np.mean(ssim_map[sel], dtype=np.float64))


# --------------------------------------------------------------------------------------------
# Chi-square of radiance (grey) histograms, SLIM paper Sect. 10
# --------------------------------------------------------------------------------------------


def grey_histogram(image: np.ndarray, mask: np.ndarray, bins: int = 256) -> np.ndarray:
    """Normalised histogram (sums to 1) of an 8-bit grey image inside the mask.

    ``bins`` equal-width bins over [0, 256) (256: one bin per grey level), the analogue of the
    SLIM paper's fixed 10 W/sr/m^2 radiance bins.

    Raises
    ------
    InvalidInputError
        ``bins`` not an integer in [1, 256], or an empty mask.
    """
    if int(bins) != bins or not 1 <= bins <= 256:
        raise InvalidInputError("chi_square_bins", f"got {bins!r}; allowed: an integer 1..256")
    values = np.asarray(image, dtype=np.float64)[mask]
    if values.size == 0:
        raise InvalidInputError("mask", "empty; allowed: a mask selecting at least one pixel")
    counts, _ = np.histogram(values, bins=int(bins), range=(0.0, 256.0))
    return counts / counts.sum()


def pearson_chi_square(observed_counts: np.ndarray, expected: np.ndarray) -> float:
    """The SLIM paper's chi2_s = sum_k (f_k - N p_k)^2 / (N p_k) (its Eq. (16), eq. M7).

    Literal form of the planetary seed, Sect. 10 "Statistical Analysis": ``f_k`` absolute
    frequencies (here ``observed_counts``, the measured histogram), ``N = sum f_k``, ``p_k`` the
    relative frequencies of the histogram compared with (``expected``, normalised here).
    (The seed's extracted text drops equation numbers; it cites the cdf F_k as Eq. (15) and
    chi2_s is the next displayed equation.)

    Not symmetric. Empty bins: a bin with ``p_k = 0`` and ``f_k = 0`` contributes 0; ``p_k = 0``
    with ``f_k > 0`` makes the statistic ``math.inf`` (the formula is undefined there). For a
    symmetric distance that is finite with empty bins see :func:`chi_square_distance`.

    Raises
    ------
    InvalidInputError
        Different lengths, negative entries, or all-zero ``observed_counts`` / ``expected``.
    """
    f = _histogram_array("observed_counts", observed_counts)
    p = _histogram_array("expected", expected)
    if f.shape != p.shape:
        raise InvalidInputError(
            "expected", f"{p.size} bins vs {f.size} observed; allowed: the same bins"
        )
    n = f.sum()
    e = n * p / p.sum()
    if np.any((e == 0.0) & (f > 0.0)):
        return math.inf
    used = e > 0.0
    return float(np.sum((f[used] - e[used]) ** 2 / e[used]))


def chi_square_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Symmetric chi-square distance 1/2 sum_k (p_k - q_k)^2 / (p_k + q_k) of two histograms.

    Both histograms are normalised to sum 1 first; bins empty in both are skipped, so the result
    is always finite, in [0, 1]: 0 for identical distributions, 1 for disjoint supports.

    Relation to the SLIM paper's Eq. (16) (:func:`pearson_chi_square`): it is that statistic with
    the expected frequencies taken as the pooled histogram m = (p + q) / 2 instead of one of the
    two, applied to both histograms (Pearson's two-sample homogeneity test) and divided by 2N:
    ``chi2_s(N p, m) + chi2_s(N q, m) = 2 N * chi_square_distance(p, q)``. Unlike Eq. (16) it is
    symmetric and needs no non-empty reference bins, which is why it is the report's verdict.
    """
    a = _histogram_array("p", p)
    b = _histogram_array("q", q)
    if a.shape != b.shape:
        raise InvalidInputError("q", f"{b.size} bins vs {a.size}; allowed: the same bins")
    a = a / a.sum()
    b = b / b.sum()
    s = a + b
    used = s > 0.0
    return float(0.5 * np.sum((a[used] - b[used]) ** 2 / s[used]))


# --------------------------------------------------------------------------------------------
# What a ToF engineer reads: depth difference, flying and invalid pixels
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ToFFigures:
    """The depth difference and the pixel shares of a comparison (:func:`tof_figures`).

    Attributes
    ----------
    depth_diff_median_mm : float or None
        Median of simulated - measured [mm] over the pixels of the mask valid in both frames and
        flying in neither (None: no such pixel). Positive: the simulation sees farther.
    depth_diff_mad_mm : float or None
        Median absolute deviation from that median [mm] (unscaled: for Gaussian differences the
        standard deviation is 1.4826 times it).
    depth_diff_p95_abs_mm : float or None
        95th percentile of |simulated - measured| [mm] (numpy's linear interpolation).
    depth_diff_n_pixels : int
        How many pixels the three figures above are taken over.
    mask_pixels : int
        Pixels of the comparison mask (before validity); the shares below are of these.
    flying_share_measured, flying_share_simulated : float
        Share of the mask's pixels that are flying in each frame
        (:func:`sim_core.flying_pixels.flying_pixels`), 0 to 1.
    invalid_share_measured, invalid_share_simulated : float
        Share of the mask's pixels that are not valid in each frame, 0 to 1.
    flying_rule : dict
        The flying-pixel rule's parameters (:class:`~sim_core.flying_pixels.FlyingPixelRule`).
    """

    depth_diff_median_mm: float | None
    depth_diff_mad_mm: float | None
    depth_diff_p95_abs_mm: float | None
    depth_diff_n_pixels: int
    mask_pixels: int
    flying_share_measured: float
    flying_share_simulated: float
    invalid_share_measured: float
    invalid_share_simulated: float
    flying_rule: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (None stays None)."""
        return json_safe(asdict(self))

    def summary_lines(self) -> list[str]:
        """Two lines for a terminal: the depth difference, then the pixel shares.

        >>> f = ToFFigures(4.2, 12.31, 48.0, 1234, 1500, 0.001, 0.0, 0.123, 0.1, {})
        >>> print("\\n".join(f.summary_lines()))  # doctest: +NORMALIZE_WHITESPACE
        depth sim - meas: median +4.2 mm, MAD 12.3 mm, 95 % of |diff| <= 48.0 mm
        (1234 pixels valid in both frames, flying in neither)
        flying pixels: measured 0.1 %, simulated 0.0 %; invalid: measured 12.3 %,
        simulated 10.0 % (of 1500 mask pixels)
        """
        if self.depth_diff_median_mm is None:
            depth = "depth sim - meas: no pixel valid in both frames and flying in neither"
        else:
            depth = (f"depth sim - meas: median {self.depth_diff_median_mm:+.1f} mm, MAD "
                     f"{self.depth_diff_mad_mm:.1f} mm, 95 % of |diff| <= "
                     f"{self.depth_diff_p95_abs_mm:.1f} mm ({self.depth_diff_n_pixels} pixels "
                     "valid in both frames, flying in neither)")
        shares = (f"flying pixels: measured {100 * self.flying_share_measured:.1f} %, simulated "
                  f"{100 * self.flying_share_simulated:.1f} %; invalid: measured "
                  f"{100 * self.invalid_share_measured:.1f} %, simulated "
                  f"{100 * self.invalid_share_simulated:.1f} % (of {self.mask_pixels} mask pixels)")
        return [depth, shares]


def tof_figures(
    measured: ToFImage,
    simulated: ToFImage,
    mask: np.ndarray | None,
    *,
    depth_source: Literal["range", "z"] = "range",
    rule: FlyingPixelRule = DEFAULT_RULE,
) -> ToFFigures:
    """The depth difference and pixel shares of ``simulated`` against ``measured`` (module
    docstring; :class:`ToFFigures`).

    ``mask``: the pixels to compare (None: all), not yet intersected with validity; flying
    pixels are found on the whole frames (a pixel's neighbours may lie outside the mask).
    ``depth_source``: radial ``range_m`` or ``depth_z_m``, as in :func:`compare_images`.

    Raises
    ------
    InvalidInputError
        Frames of different shape, a mask that is not a boolean array of their shape or selects
        no pixel, an unknown ``depth_source``.
    """
    if depth_source not in ("range", "z"):
        raise InvalidInputError("depth_source", f"got {depth_source!r}; allowed: 'range' or 'z'")
    shape = _check_frames(measured, simulated)
    sel = np.ones(shape, dtype=bool) if mask is None else _check_mask(mask, shape)
    n_mask = int(sel.sum())
    if n_mask == 0:
        raise InvalidInputError("mask", "empty; allowed: a mask selecting at least one pixel")
    attr = "range_m" if depth_source == "range" else "depth_z_m"
    depth_m = np.asarray(getattr(measured, attr), dtype=np.float64)
    depth_s = np.asarray(getattr(simulated, attr), dtype=np.float64)
    valid_m = np.asarray(measured.valid) & np.isfinite(depth_m)
    valid_s = np.asarray(simulated.valid) & np.isfinite(depth_s)
    fly_m = flying_pixels(depth_m, valid_m, rule)
    fly_s = flying_pixels(depth_s, valid_s, rule)
    used = sel & valid_m & valid_s & ~fly_m & ~fly_s
    diff_mm = (depth_s[used] - depth_m[used]) * 1e3
    if diff_mm.size:
        median = float(np.median(diff_mm))
        mad: float | None = float(np.median(np.abs(diff_mm - median)))
        p95: float | None = float(np.percentile(np.abs(diff_mm), 95.0))
        med: float | None = median
    else:
        med = mad = p95 = None
    return ToFFigures(
        depth_diff_median_mm=med,
        depth_diff_mad_mm=mad,
        depth_diff_p95_abs_mm=p95,
        depth_diff_n_pixels=int(diff_mm.size),
        mask_pixels=n_mask,
        flying_share_measured=float(fly_m[sel].sum()) / n_mask,
        flying_share_simulated=float(fly_s[sel].sum()) / n_mask,
        invalid_share_measured=float((~np.asarray(measured.valid))[sel].sum()) / n_mask,
        invalid_share_simulated=float((~np.asarray(simulated.valid))[sel].sum()) / n_mask,
        flying_rule=rule.to_dict(),
    )


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ChannelMetrics:
    """Table 5 indexes of one image kind (grey or depth), over the effective mask.

    Attributes
    ----------
    name : str
        ``"grey"`` or ``"depth"``.
    unit : str
        Unit of means, variances and MSE (``"grey level"`` or e.g. ``"mm"``).
    data_range : float
        R used by PSNR and SSIM.
    mean_measured, mean_simulated : float
        Eq. M1.
    var_measured, var_simulated : float
        Eq. M2 (population variance).
    mse : float
        Eq. M3.
    ssim : float
        Eq. M5, masked (see :func:`masked_ssim`).
    psnr_db : float
        Eq. M4; ``inf`` when ``mse == 0``.
    rel_err_mean, rel_err_var : float
        Eq. M6 as fractions (Table 5 shows percent); ``inf`` if the measured value is 0 and the
        simulated one is not.
    """

    name: str
    unit: str
    data_range: float
    mean_measured: float
    mean_simulated: float
    var_measured: float
    var_simulated: float
    mse: float
    ssim: float
    psnr_db: float
    rel_err_mean: float
    rel_err_var: float


@dataclass(frozen=True)
class ComparisonReport:
    """Result of :func:`compare_images`.

    Attributes
    ----------
    grey, depth : ChannelMetrics
        The rows of seed Table 5.
    grey_chi_square : float
        :func:`chi_square_distance` of the two grey histograms, in [0, 1] (0 = same distribution).
    chi_square_bins : int
        Number of grey histogram bins.
    n_pixels : int
        Pixels of the effective mask.
    grey_full_scale_measured, grey_full_scale_simulated : float
        Amplitude mapped to grey level 255 in each frame.
    depth_unit_m : float
        Metres per count of the 16-bit depth image (1e-3: millimetres).
    depth_source : str
        ``"range"`` (radial range) or ``"z"`` (depth along the optical axis).
    tof : ToFFigures or None
        The depth difference and pixel shares (:func:`tof_figures`); :func:`compare_images`
        always fills it.
    """

    grey: ChannelMetrics
    depth: ChannelMetrics
    grey_chi_square: float
    chi_square_bins: int
    n_pixels: int
    grey_full_scale_measured: float
    grey_full_scale_simulated: float
    depth_unit_m: float
    depth_source: str
    tof: ToFFigures | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dict: plain ints/floats/strings; non-finite floats become the strings
        ``"inf"``, ``"-inf"`` or ``"nan"`` (so ``json.dumps(..., allow_nan=False)`` works)."""
        return json_safe(asdict(self))

    def table_rows(self) -> list[tuple[str, str, str, str, str]]:
        """Rows laid out like seed Table 5 (columns :data:`TABLE_HEADER`), as strings.

        Per image: Mean, Var (measured, simulated, relative error in percent), MSE, SSIM, PSNR
        (simulated column only), then one chi-square row for the grey histograms. Numbers of
        magnitude >= 1e5 are written as ``2.95e+05``, others with two decimals; "—" marks an
        empty cell.
        """
        rows: list[tuple[str, str, str, str, str]] = []
        for ch, label in ((self.grey, "Grey"), (self.depth, "Depth")):
            rows.append(
                (
                    label,
                    "Mean",
                    _fmt(ch.mean_measured),
                    _fmt(ch.mean_simulated),
                    _fmt_percent(ch.rel_err_mean),
                )
            )
            rows.append(
                (
                    label,
                    "Var",
                    _fmt(ch.var_measured),
                    _fmt(ch.var_simulated),
                    _fmt_percent(ch.rel_err_var),
                )
            )
            rows.append((label, "MSE", _NOT_APPLICABLE, _fmt(ch.mse), _NOT_APPLICABLE))
            rows.append((label, "SSIM", _NOT_APPLICABLE, _fmt(ch.ssim), _NOT_APPLICABLE))
            rows.append((label, "PSNR", _NOT_APPLICABLE, _fmt(ch.psnr_db), _NOT_APPLICABLE))
        rows.append(
            ("Grey", "Chi-square", _NOT_APPLICABLE, f"{self.grey_chi_square:.4g}", _NOT_APPLICABLE)
        )
        return rows


def channel_metrics(
    name: str,
    unit: str,
    measured: np.ndarray,
    simulated: np.ndarray,
    mask: np.ndarray,
    data_range: float,
) -> ChannelMetrics:
    """Eqs. M1-M6 for two images (any numeric dtype) over a non-empty boolean mask."""
    _check_pair(measured, simulated, mask)
    a = np.asarray(measured, dtype=np.float64)[mask]
    b = np.asarray(simulated, dtype=np.float64)[mask]
    mean_a, mean_b = float(np.mean(a)), float(np.mean(b))
    var_a, var_b = float(np.var(a)), float(np.var(b))
    mse = float(np.mean((b - a) ** 2))
    return ChannelMetrics(
        name=name,
        unit=unit,
        data_range=float(data_range),
        mean_measured=mean_a,
        mean_simulated=mean_b,
        var_measured=var_a,
        var_simulated=var_b,
        mse=mse,
        ssim=masked_ssim(measured, simulated, mask, data_range),
        psnr_db=psnr_db(mse, data_range),
        rel_err_mean=relative_error(mean_a, mean_b),
        rel_err_var=relative_error(var_a, var_b),
    )


def compare_images(
    measured: ToFImage,
    simulated: ToFImage,
    mask: np.ndarray | None,
    *,
    grey_full_scale: float | tuple[float, float] | None = None,
    depth_unit: float = 1e-3,
    depth_source: Literal["range", "z"] = "range",
    chi_square_bins: int = 256,
) -> ComparisonReport:
    """Seed Table 5 indexes (grey and depth) plus the grey-histogram chi-square.

    Parameters
    ----------
    measured, simulated : ToFImage
        Frames of the same (H, W) shape, at least 7 x 7 (the SSIM window).
    mask : (H, W) bool or None
        Pixels to compare (None: all); intersected with both frames' ``valid``
        (:func:`effective_mask`).
    grey_full_scale : float, (float, float) or None
        Amplitude mapped to grey 255 (:func:`grey_8bit`). One number: the same for both frames
        (same amplitude unit). A pair: (measured, simulated), for frames in different units.
        None: the 99.5th percentile of the measured amplitude inside the effective mask, applied
        to both frames. The service passes each frame's own grey full scale (the pair from
        :func:`sim_core.frame_io.grey_full_scale`, as in the frames' ``grey.png``).
    depth_unit : float
        Metres per count of the 16-bit depth image; 1e-3 (millimetres, the camera tools'
        convention, :func:`depth_mm_16bit`). The data range stays 65535 counts.
    depth_source : "range" or "z"
        Radial ``range_m`` (default) or ``depth_z_m`` along the optical axis.
    chi_square_bins : int
        Bins of the grey histograms over [0, 256) (see :func:`grey_histogram`).

    Grey: 8-bit, R = 255. Depth: 16-bit counts of ``depth_unit``, R = 65535. Means, variances and
    MSE are in those counts (grey levels, millimetres by default), as in Table 5. The report's
    ``tof`` holds :func:`tof_figures` over the same ``mask`` and depth source.

    Raises
    ------
    InvalidInputError
        Frames of different shape or smaller than 7 x 7, a mask that is not a boolean array of
        the frames' shape or leaves no pixel, or invalid keyword values; the error's ``field``
        names the offending input.
    """
    if depth_source not in ("range", "z"):
        raise InvalidInputError("depth_source", f"got {depth_source!r}; allowed: 'range' or 'z'")
    unit = _positive_finite("depth_unit", depth_unit)
    eff = effective_mask(mask, measured, simulated)
    fs_meas, fs_sim = _grey_full_scales(grey_full_scale, measured, eff)

    grey_m = grey_8bit(measured.amplitude, fs_meas)
    grey_s = grey_8bit(simulated.amplitude, fs_sim)
    if depth_source == "range":
        depth_m, depth_s = measured.range_m, simulated.range_m
    else:
        depth_m, depth_s = measured.depth_z_m, simulated.depth_z_m
    dep_m = depth_16bit(depth_m, unit)
    dep_s = depth_16bit(depth_s, unit)

    depth_unit_name = "mm" if unit == 1e-3 else f"{unit:g} m"
    grey = channel_metrics("grey", "grey level", grey_m, grey_s, eff, GREY_DATA_RANGE)
    depth = channel_metrics("depth", depth_unit_name, dep_m, dep_s, eff, DEPTH_DATA_RANGE)
    chi2 = chi_square_distance(
        grey_histogram(grey_m, eff, chi_square_bins), grey_histogram(grey_s, eff, chi_square_bins)
    )
    tof = tof_figures(measured, simulated, mask, depth_source=depth_source)
    return ComparisonReport(
        grey=grey,
        depth=depth,
        grey_chi_square=chi2,
        chi_square_bins=int(chi_square_bins),
        n_pixels=int(eff.sum()),
        grey_full_scale_measured=fs_meas,
        grey_full_scale_simulated=fs_sim,
        depth_unit_m=unit,
        depth_source=depth_source,
        tof=tof,
    )


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------


def _positive_finite(field: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InvalidInputError(field, f"got {value!r}; allowed: a finite number > 0") from None
    if not (math.isfinite(v) and v > 0.0):
        raise InvalidInputError(field, f"got {v!r}; allowed: a finite number > 0")
    return v


def _check_frames(measured: ToFImage, simulated: ToFImage) -> tuple[int, int]:
    shape = np.shape(measured.range_m)
    if len(shape) != 2:
        raise InvalidInputError(
            "measured.range_m", f"shape {shape} not allowed; allowed: a 2-D (H, W) image"
        )
    if shape[0] < SSIM_WIN_SIZE or shape[1] < SSIM_WIN_SIZE:
        raise InvalidInputError(
            "measured.range_m",
            f"shape {shape} too small; allowed: at least {SSIM_WIN_SIZE} x {SSIM_WIN_SIZE} "
            "(the SSIM window)",
        )
    for frame_name, frame in (("measured", measured), ("simulated", simulated)):
        for attr in ("range_m", "depth_z_m", "amplitude", "valid"):
            s = np.shape(getattr(frame, attr))
            if s != shape:
                raise InvalidInputError(
                    f"{frame_name}.{attr}",
                    f"shape {s} differs from measured.range_m {shape}; allowed: both frames "
                    "with all images of one shape",
                )
        if np.asarray(frame.valid).dtype != np.bool_:
            raise InvalidInputError(
                f"{frame_name}.valid",
                f"dtype {np.asarray(frame.valid).dtype} not allowed; allowed: bool",
            )
    return shape


def _check_pair(measured: np.ndarray, simulated: np.ndarray, mask: np.ndarray) -> None:
    shape = np.shape(measured)
    if len(shape) != 2:
        raise InvalidInputError("measured", f"shape {shape} not allowed; allowed: a 2-D image")
    if np.shape(simulated) != shape:
        raise InvalidInputError(
            "simulated",
            f"shape {np.shape(simulated)} differs from measured {shape}; allowed: the same shape",
        )
    _check_mask(mask, shape)
    if not mask.any():
        raise InvalidInputError("mask", "empty; allowed: a mask selecting at least one pixel")


def _check_mask(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    if not isinstance(mask, np.ndarray):
        raise InvalidInputError(
            "mask", f"got {type(mask).__name__}; allowed: a numpy bool array of shape {shape}"
        )
    if mask.dtype != np.bool_:
        raise InvalidInputError(
            "mask",
            f"dtype {mask.dtype} not allowed; allowed: bool (e.g. from mask_by_depth_window, "
            "mask_by_region, mask_from_objects, or `array > 0`)",
        )
    if mask.shape != shape:
        raise InvalidInputError(
            "mask", f"shape {mask.shape} not allowed; allowed: the frames' shape {shape}"
        )
    return mask


def _grey_full_scales(
    grey_full_scale: float | tuple[float, float] | None, measured: ToFImage, mask: np.ndarray
) -> tuple[float, float]:
    if grey_full_scale is None:
        amp = np.asarray(measured.amplitude, dtype=np.float64)[mask]
        amp = amp[np.isfinite(amp)]
        fs = float(np.percentile(amp, GREY_FULL_SCALE_PERCENTILE)) if amp.size else 0.0
        if not fs > 0.0:
            raise InvalidInputError(
                "grey_full_scale",
                "None, but the measured amplitude is <= 0 (or not finite) everywhere in the mask; "
                "allowed: pass a finite number > 0 (or a pair) explicitly",
            )
        return fs, fs
    if isinstance(grey_full_scale, Sequence) and not isinstance(grey_full_scale, str):
        if len(grey_full_scale) != 2:
            raise InvalidInputError(
                "grey_full_scale",
                f"got {grey_full_scale!r}; allowed: a number > 0, a pair (measured, simulated) "
                "or None",
            )
        return (
            _positive_finite("grey_full_scale[0]", grey_full_scale[0]),
            _positive_finite("grey_full_scale[1]", grey_full_scale[1]),
        )
    fs = _positive_finite("grey_full_scale", grey_full_scale)
    return fs, fs


def _histogram_array(field: str, values: np.ndarray) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64)
    if a.ndim != 1 or a.size == 0:
        raise InvalidInputError(field, f"shape {a.shape} not allowed; allowed: a 1-D histogram")
    if not np.all(np.isfinite(a)) or np.any(a < 0.0):
        raise InvalidInputError(field, "allowed: finite, non-negative bin values")
    if a.sum() <= 0.0:
        raise InvalidInputError(field, "all bins are 0; allowed: at least one non-empty bin")
    return a


def _fmt(value: float) -> str:
    if math.isnan(value):
        return "nan"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if abs(value) >= 1e5:
        return f"{value:.2e}"
    return f"{value:.2f}"


def _fmt_percent(fraction: float) -> str:
    if math.isnan(fraction):
        return "nan"
    if math.isinf(fraction):
        return "inf"
    return f"{100.0 * fraction:.2f}%"
