"""Flying (mixed) pixels of a range image: pure functions over arrays.

A pixel that sees the edge of an object collects light from the object and from what lies
behind it; its phasor is the sum of both, so its range lies *between* foreground and background
and belongs to neither surface. In a point cloud such pixels fly in the air between the two.
A comparison should not count them as the twin's depth error (they depend on where exactly the
edge falls on the pixel), but it should say how many there are.

The rule (:func:`flying_pixels`)
--------------------------------
Along each of four directions d (horizontal, vertical and the two diagonals) a valid pixel p with
range r(p) has neighbours a = p - d and b = p + d. The pixel is *flying along d* when

1. it lies on neither neighbour's surface: the second differences centred at both neighbours,
   ``c(a) = r(p - 2d) - 2 r(a) + r(p)`` and ``c(b) = r(p) - 2 r(b) + r(p + 2d)``, exceed the
   threshold T(p) in magnitude. On a flat side ``c(a) = r(p) - r(a)``, the plain difference;
   on a slanted or grazing side the neighbour's slope is extrapolated instead, so a steep but
   smooth surface (a floor seen at a grazing angle) is not a jump;
2. it lies *between* them: ``c(a)`` and ``c(b)`` have opposite signs (a single pixel above or
   below both neighbours is an outlier, e.g. a phase-unwrapping error, not a mixed pixel).

A pixel is flying when it is flying along at least one direction. Every pixel of the five-pixel
stencil must be valid with a finite range: an invalid or NaN/inf neighbour, or the image border,
gives no evidence, so such a pixel is never called flying on that direction.

The threshold
-------------
T(p) = max(t(r(p)), k * s(p)) metres:

* t(r): PMD royale's flying-pixel threshold (its "FlyingPixel Flag", documented in the SDK's
  ``royale/ProcessingFlag.hpp``): royale compares a pixel's depth with its left and right (or top
  and bottom) neighbours and flags it when both absolute differences exceed a threshold that grows
  linearly with depth from ``flyingPixel_f_0`` = 0.018 m at ``nearDist`` = 1.0 m or closer to
  ``flyingPixel_f_1`` = 0.14 m at ``farDist`` = 4.5 m or farther (its defaults for the pico
  flexx). So t = 18 mm + 3.49 % of (r - 1 m), between 18 and 140 mm. The range noise of an AMCW
  pixel grows with distance (less light), which is why the threshold has a part that grows with
  range. These are our defaults (:class:`FlyingPixelRule`).
* k * s(p): royale applies its flag after its adaptive noise filter (which reduces the distance
  noise 2.5-3.5 times) and after invalidating pixels whose distance noise exceeds 70 mm. Our
  reconstruction does neither, so the threshold also stands above the local noise: s(p) is a
  robust standard deviation of the second differences around p (:func:`second_difference_noise_m`)
  and k = 4 (``noise_factor``): for Gaussian noise both neighbours' second differences beyond
  4 standard deviations, with opposite signs, on one of four directions, is a chance of about
  1e-8 a pixel.

Measured on single renders of the example scenes (``toftwin simulate``, default settings):
royale's rule as it stands (left/right and top/bottom differences, its threshold) flags 66 % of
the valid pixels of the satellite ground test at 1 sun (its range noise is about 70 mm a pixel),
4 % of the plain wall 2 m away (``plane``), and 14 % of a noise-free (``--ideal``) frame of the
satellite scene, whose floor, seen at a grazing angle, is a steep ramp. This rule flags 0.06 %,
0.01 % and 0.6 % of them; in the noise-free frame, the satellite's outline against the
background. Its rate on a noisy frame is low because a mixed pixel cannot be told from noise
there: the count is of the pixels that stand out of it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from sim_core.errors import InvalidInputError

#: the four directions (row step, column step): horizontal, vertical, the two diagonals
DIRECTIONS: tuple[tuple[int, int], ...] = ((0, 1), (1, 0), (1, 1), (1, -1))

#: 1 / Phi^-1(3/4): a median absolute value of zero-mean Gaussian samples times this is their
#: standard deviation
MAD_TO_SIGMA = 1.482602218505602

#: the local noise is the median over NOISE_SAMPLES x NOISE_SAMPLES samples taken on every
#: NOISE_STRIDE-th row and column, a window of (NOISE_SAMPLES - 1) * NOISE_STRIDE + 1 = 13 pixels
NOISE_SAMPLES = 5
NOISE_STRIDE = 3


@dataclass(frozen=True)
class FlyingPixelRule:
    """The threshold of :func:`flying_pixels` (see the module docstring for why these defaults).

    Attributes
    ----------
    near_threshold_m, far_threshold_m : float
        Threshold at ``near_range_m`` or closer and at ``far_range_m`` or farther; linear in
        between (royale's ``flyingPixel_f_0`` = 0.018 m and ``flyingPixel_f_1`` = 0.14 m).
    near_range_m, far_range_m : float
        Where the ramp starts and ends (royale's ``nearDist`` = 1.0 m, ``farDist`` = 4.5 m).
    noise_factor : float
        k: the threshold is at least k local noise standard deviations of the second
        differences (0: royale's threshold alone).
    """

    near_threshold_m: float = 0.018
    far_threshold_m: float = 0.14
    near_range_m: float = 1.0
    far_range_m: float = 4.5
    noise_factor: float = 4.0

    def __post_init__(self) -> None:
        for name in ("near_threshold_m", "far_threshold_m", "near_range_m"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0.0):
                raise InvalidInputError(name, f"got {v!r}; allowed: a finite number > 0 [m]")
        if not (isinstance(self.far_range_m, int | float) and math.isfinite(self.far_range_m)
                and self.far_range_m > self.near_range_m):
            raise InvalidInputError(
                "far_range_m", f"got {self.far_range_m!r}; allowed: a finite number > "
                f"near_range_m = {self.near_range_m!r} [m]")
        k = self.noise_factor
        if not (isinstance(k, int | float) and math.isfinite(k) and k >= 0.0):
            raise InvalidInputError("noise_factor", f"got {k!r}; allowed: a finite number >= 0")

    def threshold_m(self, range_m: np.ndarray) -> np.ndarray:
        """Royale's range-dependent part t(r) [m] (NaN where the range is NaN).

        >>> FlyingPixelRule().threshold_m(np.array([0.5, 1.0, 2.75, 4.5, 9.0])).round(4).tolist()
        [0.018, 0.018, 0.079, 0.14, 0.14]
        """
        r = np.asarray(range_m, dtype=np.float64)
        frac = np.clip((r - self.near_range_m) / (self.far_range_m - self.near_range_m), 0.0, 1.0)
        return self.near_threshold_m + (self.far_threshold_m - self.near_threshold_m) * frac

    def to_dict(self) -> dict[str, Any]:
        """The rule's parameters (for a report)."""
        return asdict(self)


DEFAULT_RULE = FlyingPixelRule()


def _finite_range(range_m: np.ndarray, valid: np.ndarray) -> np.ndarray:
    r = np.asarray(range_m, dtype=np.float64)
    if r.ndim != 2:
        raise InvalidInputError("range_m", f"shape {r.shape} not allowed; allowed: a 2-D image")
    v = np.asarray(valid)
    if v.shape != r.shape:
        raise InvalidInputError(
            "valid", f"shape {v.shape} not allowed; allowed: the range image's shape {r.shape}")
    if v.dtype != np.bool_:
        raise InvalidInputError("valid", f"dtype {v.dtype} not allowed; allowed: bool")
    with np.errstate(invalid="ignore"):
        return np.where(v & np.isfinite(r), r, np.nan)


def _second_differences(r: np.ndarray) -> np.ndarray:
    """(4, H, W): along each of :data:`DIRECTIONS`, r(p - d) - 2 r(p) + r(p + d); NaN where a
    pixel of the stencil is missing (NaN or outside the image)."""
    h, w = r.shape
    p = np.pad(r, 1, constant_values=np.nan)
    out = np.empty((len(DIRECTIONS), h, w))
    for i, (dy, dx) in enumerate(DIRECTIONS):
        before = p[1 - dy:1 - dy + h, 1 - dx:1 - dx + w]
        after = p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
        out[i] = before - 2.0 * r + after
    return out


def _noise_from_second_differences(d2: np.ndarray) -> np.ndarray:
    """Local robust standard deviation [m] of the second differences ``d2`` (4, H, W)."""
    _, h, w = d2.shape
    a = np.abs(d2)
    n = np.sum(np.isfinite(a), axis=0)
    s = np.sort(a, axis=0)  # NaN sort last: the first n of each pixel are its values
    lo = np.take_along_axis(s, np.clip((n - 1) // 2, 0, 3)[None], 0)[0]
    hi = np.take_along_axis(s, np.clip(n // 2, 0, 3)[None], 0)[0]
    per_pixel = np.where(n > 0, 0.5 * (lo + hi), np.nan)  # median over the directions
    known = np.isfinite(per_pixel)
    if not known.any():
        return np.full((h, w), np.nan)
    # where a pixel has no second difference, the frame's median stands in (neither raises nor
    # lowers its neighbours' estimate)
    filled = np.where(known, per_pixel, np.median(per_pixel[known]))
    k = NOISE_STRIDE
    sub = ndimage.median_filter(filled[::k, ::k], size=NOISE_SAMPLES, mode="nearest")
    full = np.repeat(np.repeat(sub, k, axis=0), k, axis=1)[:h, :w]
    return MAD_TO_SIGMA * full


def second_difference_noise_m(range_m: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Local noise [m]: a robust standard deviation of the range's second differences near each
    pixel.

    Per pixel the median of |second difference| over the directions where it exists; then the
    median of those over a 13 x 13 window sampled on every third row and column (5 x 5
    samples, each standing for its 3 x 3 block; a straight edge crossing the window holds about
    a fifth of them, too few to move the median much; a full median filter costs six times as
    much); times 1.4826, the ratio of a Gaussian's standard deviation to its median absolute
    value. For independent Gaussian range noise of standard deviation sigma the second
    differences have sqrt(6) sigma, and this estimates that within a few per cent (a test
    checks it). Pixels with no second difference of their own take the frame's median. NaN
    everywhere when the image has no second difference at all.
    """
    return _noise_from_second_differences(_second_differences(_finite_range(range_m, valid)))


def flying_pixels(
    range_m: np.ndarray, valid: np.ndarray, rule: FlyingPixelRule = DEFAULT_RULE
) -> np.ndarray:
    """Boolean (H, W) mask of the flying (mixed) pixels of a range image (module docstring).

    Parameters
    ----------
    range_m : (H, W) float
        Range [m] (radial, or depth along the optical axis as royale uses: the threshold is in
        the same metres); NaN or inf where there is none.
    valid : (H, W) bool
        The frame's validity mask; invalid pixels are never flying and give no evidence.
    rule : FlyingPixelRule
        The threshold.

    Raises
    ------
    InvalidInputError
        ``range_m`` not 2-D, ``valid`` not a boolean array of its shape.

    >>> row = [1.0] * 5 + [1.5] + [2.0] * 6  # foreground | mixed | background
    >>> r = np.array([row] * 9)
    >>> np.argwhere(flying_pixels(r, np.ones(r.shape, bool)))[:, 1].tolist()  # every row
    [5, 5, 5, 5, 5, 5, 5, 5, 5]
    """
    r = _finite_range(range_m, valid)
    d2 = _second_differences(r)
    threshold = rule.threshold_m(r)
    if rule.noise_factor > 0.0:
        noise = _noise_from_second_differences(d2)
        with np.errstate(invalid="ignore"):
            threshold = np.fmax(threshold, rule.noise_factor * noise)
    h, w = r.shape
    padded = np.pad(d2, ((0, 0), (1, 1), (1, 1)), constant_values=np.nan)
    out = np.zeros((h, w), dtype=bool)
    with np.errstate(invalid="ignore"):
        for i, (dy, dx) in enumerate(DIRECTIONS):
            at_a = padded[i, 1 - dy:1 - dy + h, 1 - dx:1 - dx + w]  # centred at p - d
            at_b = padded[i, 1 + dy:1 + dy + h, 1 + dx:1 + dx + w]  # centred at p + d
            out |= ((np.abs(at_a) > threshold) & (np.abs(at_b) > threshold)
                    & (at_a * at_b < 0.0))
    return out & np.isfinite(r)
