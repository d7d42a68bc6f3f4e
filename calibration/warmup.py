"""The warm-up drift coefficient from a warm-up sequence of a fixed target (issue 27).

Procedure (the real rig and the simulated lab alike): power the camera on cold, point it at a
fixed target (nothing on the rig moves), and capture frames while the illumination warms, each
with its reported illumination temperature (royale's ``RawData.illuminationTemperature``,
``RawFrame.illumination_temperature_c``). The range of a patch of the target then follows the
temperature linearly (TI's calibration model, :mod:`sim_core.warmup`):

    r_k(T) = r_k(T_0) + k_f (T - T_0)

per modulation frequency. Each frame's patch range is measured as the change of every pixel's
phase against its mean phasor over the sequence, ``arg(z_frame conj(mean z))`` (no wrap for
drifts below a quarter of the ambiguity range), turned into a range (seed eq. 7) and averaged
over the patch; its standard error comes from the frames' own temporal noise (each pixel's
scatter about its mean over the sequence, after the patch's common change is removed). A
weighted straight-line fit of those ranges against the temperatures gives ``k_f`` with its
standard error, and the fit's reduced chi-square says whether a straight line explains them;
the verdict comes from :func:`calibration.verdicts.judge` (the standard error made honest by
the residual; the chi-square's limit :func:`calibration.verdicts.chi2_limit_for` the line's
degrees of freedom).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibration.verdicts import Verdict, chi2_limit_for, honest_std, judge
from sim_core.errors import InvalidInputError
from sim_core.raw import RawFrame
from sim_core.tof import range_from_phase

#: the key the drift is reported under (the calibration file's)
DRIFT_KEY = "camera.temperature.depth_drift_mm_per_c"
#: the largest standard deviation of a determined drift [mm/degC] (a tenth of a typical 0.3)
DRIFT_STD_LIMIT_MM_PER_C = 0.03
#: the least temperature span a sequence must cover to determine a drift [degC]
MIN_TEMPERATURE_SPAN_C = 2.0
#: frames a sequence needs (two for the line, one for its residual)
MIN_FRAMES = 3
#: the least standard error of a frame's patch range [mm]: a micrometre, far below any
#: camera's, keeps the weights finite for noise-free frames (their float32 rounding remains)
FRAME_STD_FLOOR_MM = 1e-3


@dataclass(frozen=True)
class WarmupFit:
    """The drift per frequency with its honest standard deviation and the fit's evidence.

    Attributes
    ----------
    drift_mm_per_c : (n_f,) float
        Range change per degree, per modulation frequency [mm/degC].
    drift_std_mm_per_c : (n_f,) float
        Its standard deviation, scaled by the residual where it exceeds the noise.
    reduced_chi2 : (n_f,) float
    temperatures_c : (n,) float
        The frames' reported temperatures.
    patch_range_mm : (n_f, n) float
        Each frame's patch range against the sequence's mean phasor [mm].
    patch_range_std_mm : (n_f, n) float
    verdict : Verdict
        Of :data:`DRIFT_KEY` (the worst frequency decides).
    """

    drift_mm_per_c: np.ndarray
    drift_std_mm_per_c: np.ndarray
    reduced_chi2: np.ndarray
    temperatures_c: np.ndarray
    patch_range_mm: np.ndarray
    patch_range_std_mm: np.ndarray
    verdict: Verdict

    def temperature_key(self, start_c: float, end_c: float, time_constant_s: float) -> dict:
        """The calibration file's ``camera.temperature``: the fitted drift (one per frequency)
        with the temperature at which the calibration's other depth errors hold (``start_c``)
        and the warm-up's end and time constant as observed (the twin uses each measured
        frame's reported temperature, not the curve)."""
        return {"illumination_start_c": float(start_c), "illumination_end_c": float(end_c),
                "time_constant_s": float(time_constant_s),
                "depth_drift_mm_per_c": [round(float(k), 4) for k in self.drift_mm_per_c]}


def _temperatures(frames: Sequence[RawFrame]) -> np.ndarray:
    out = []
    for i, f in enumerate(frames):
        t = f.illumination_temperature_c
        if t is None or not math.isfinite(t):
            raise InvalidInputError(f"frames[{i}].illumination_temperature_c",
                                    f"is {t!r}: every frame of a warm-up sequence must report "
                                    "its illumination temperature")
        out.append(float(t))
    return np.asarray(out)


def _line_fit(x: np.ndarray, y: np.ndarray, sigma: np.ndarray) -> tuple[float, float, float]:
    """Weighted straight line ``y = a + b x``: slope, its standard error, reduced chi-square.

    ``sigma > 0`` is the caller's guarantee (a floor on the noise); the normal matrix is
    singular only when every ``x`` is equal, which :func:`fit_warmup` refuses first.
    """
    w = 1.0 / sigma**2
    sw, sx, sy = w.sum(), (w * x).sum(), (w * y).sum()
    sxx, sxy = (w * x * x).sum(), (w * x * y).sum()
    det = sw * sxx - sx * sx  # > 0 when the x are not all equal
    b = (sw * sxy - sx * sy) / det
    a = (sy - b * sx) / sw
    chi2 = float((w * (y - a - b * x) ** 2).sum())
    dof = x.size - 2
    return float(b), float(math.sqrt(sw / det)), chi2 / dof if dof > 0 else math.inf


def fit_warmup(frames: Sequence[RawFrame], patch: np.ndarray) -> WarmupFit:
    """The drift coefficient from a warm-up sequence of a fixed target (module docstring).

    Parameters
    ----------
    frames : sequence of RawFrame
        In capture order, each reporting its illumination temperature.
    patch : (H, W) bool
        The target's pixels to average (a flat, bright, well-exposed patch).
    """
    if len(frames) < MIN_FRAMES:
        raise InvalidInputError("frames", f"{len(frames)} frames; a warm-up sequence needs at "
                                f"least {MIN_FRAMES}")
    temps = _temperatures(frames)
    mask = np.asarray(patch, dtype=bool)
    if mask.shape != frames[0].shape or not mask.any():
        raise InvalidInputError("patch", f"a {mask.shape} mask with {int(mask.sum())} pixels; "
                                f"the frames are {frames[0].shape}: it needs at least one pixel")
    freqs = np.asarray(frames[0].frequencies_hz, dtype=np.float64)
    z = np.stack([f.phasor()[:, mask] for f in frames])  # (n, n_f, n_px)
    # Phase change against each pixel's mean phasor over the sequence (its noise is common to
    # every frame and averaged down; no frame is special): wrap-free for drifts below a quarter
    # of the ambiguity range.
    dphi = -np.angle(z * np.conj(z.mean(axis=0)))
    dr_mm = np.stack([range_from_phase(dphi[:, k], f) for k, f in enumerate(freqs)],
                     axis=1) * 1e3  # (n, n_f, n_px)
    patch_mm = dr_mm.mean(axis=2)  # (n, n_f)
    # Temporal noise: each pixel about its own mean, the patch's common change removed.
    resid = dr_mm - patch_mm[:, :, None] - (dr_mm - patch_mm[:, :, None]).mean(axis=0)
    n, n_px = len(frames), int(mask.sum())
    pixel_std = np.sqrt((resid**2).sum(axis=(0, 2)) / max(1, (n - 1) * max(n_px - 1, 1)))
    # The reference's noise is common to all frames: it moves the line, not its slope. The
    # floor keeps the weights finite for noise-free frames.
    frame_std = np.maximum(pixel_std / math.sqrt(n_px), FRAME_STD_FLOOR_MM)  # (n_f,)
    span = float(temps.max() - temps.min())
    drift, std, chi2 = [], [], []
    if span > 0.0:
        for k in range(freqs.size):
            b, s, c = _line_fit(temps, patch_mm[:, k], np.full(n, frame_std[k]))
            drift.append(b)
            std.append(s)
            chi2.append(c)
    else:
        drift, std, chi2 = [math.nan] * freqs.size, [math.inf] * freqs.size, [
            math.inf] * freqs.size
    if span < MIN_TEMPERATURE_SPAN_C:
        verdict = Verdict("not determined", None,
                          f"the sequence's temperatures span {span:.3g} degC, below the "
                          f"{MIN_TEMPERATURE_SPAN_C:g} degC a drift needs (capture longer after "
                          "power-on)")
    else:
        # a straight line through n frames leaves n - 2 degrees of freedom: with few frames
        # the chi-square itself is noisy, and its limit the chi-square's 0.1 % tail
        verdict = judge(std, DRIFT_STD_LIMIT_MM_PER_C, reduced_chi2=max(chi2),
                        chi2_limit=chi2_limit_for(n - 2), unit=" mm/degC",
                        where=f"the warm-up sequence ({n} frames)")
    honest = [honest_std(s, c) for s, c in zip(std, chi2, strict=True)]
    return WarmupFit(np.asarray(drift), np.asarray(honest), np.asarray(chi2), temps,
                     patch_mm.T.copy(), np.repeat(frame_std[:, None], n, axis=1), verdict)
