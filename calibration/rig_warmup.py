"""The rig calibration's warm-up stage: the drift measured first, then removed from every depth
fit (issue 27).

Procedure (:func:`calibration.rig_sequence.rig_capture_plan` plans it first, as on a real rig:
from power-on, before anything else): the first board fixture as mounted, nothing moves, and
:data:`~calibration.rig_sequence.RigCalibrationPlan.warmup_captures` captures of a few frames
each are taken :data:`~calibration.rig_sequence.RigCalibrationPlan.warmup_interval_s` apart
(:class:`calibration.capture_plan.WaitStep`: a real rig sleeps, the simulated lab advances its
clock). Every frame keeps its reported illumination temperature; :func:`calibration.warmup.
fit_warmup` fits the range drift per degree on the board's bright pixels.

The key written (``camera.temperature``, :meth:`calibration.warmup.WarmupFit.temperature_key`)
holds the drift and the first capture's temperature as the start: every later depth fit of the
rig calibration removes the drift at its capture's temperature
(:func:`calibration.captures.drift_free_phase_rad`),
so the depth model is the one at the start temperature, as the twin applies it
(:mod:`sim_core.warmup`). The end temperature is the last capture's, and the time constant the
exponential through the captures' temperatures at the plan's times (the twin does not use it:
it applies each frame's reported temperature).

No key is written, and nothing is removed, when the drift is not determined: the camera reports
no temperature, the temperatures span too little, the drift's standard deviation is above its
limit, or no drift stands above the noise (:data:`MIN_DRIFT_SIGMAS`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibration.captures import AveragedCapture
from calibration.verdicts import Verdict, Verdicts
from calibration.warmup import DRIFT_KEY, WarmupFit, fit_warmup
from sim_core.twin_file import CameraTemperature

__all__ = ["MIN_DRIFT_SIGMAS", "RigWarmup", "fit_rig_warmup", "no_warmup",
           "observed_time_constant_s", "warmup_patch"]

#: the keys of ``camera.temperature`` besides the drift
START_KEY = "camera.temperature.illumination_start_c"
END_KEY = "camera.temperature.illumination_end_c"
TIME_CONSTANT_KEY = "camera.temperature.time_constant_s"
#: a drift is reported only when it stands this many standard deviations above zero
MIN_DRIFT_SIGMAS = 3.0
#: the patch: pixels whose amplitude is above this share of the image's bright end
PATCH_SHARE = 0.25
#: the image's bright end: this percentile of the amplitude (a few hot pixels do not set it)
BRIGHT_PERCENTILE = 99.5
#: time constants searched, as multiples of the sequence's span (1/20 .. 200 spans)
TIME_CONSTANT_SPANS = np.geomspace(0.05, 200.0, 400)
#: the file's largest time constant [s] (sim_core.twin_file.CameraTemperature)
MAX_TIME_CONSTANT_S = 1e6


@dataclass(frozen=True)
class RigWarmup:
    """The warm-up stage's outcome.

    Attributes
    ----------
    temperature : CameraTemperature or None
        The key to write; None unless the drift is determined.
    verdicts : Verdicts
        Of :data:`calibration.warmup.DRIFT_KEY` always, and of the other keys of
        ``camera.temperature`` when it is written.
    fit : WarmupFit or None
        The estimator's figures (None when the frames report no temperature).
    summary : dict
        Plain figures for the report.
    """

    temperature: CameraTemperature | None
    verdicts: Verdicts
    fit: WarmupFit | None
    summary: dict


def warmup_patch(capture: AveragedCapture) -> np.ndarray:
    """(H, W) bool: the capture's bright, valid pixels (the board's white squares), where the
    phase is well measured: amplitude above :data:`PATCH_SHARE` of its
    :data:`BRIGHT_PERCENTILE`-th percentile."""
    amp = np.asarray(capture.amplitude, dtype=np.float64)
    top = float(np.percentile(amp, BRIGHT_PERCENTILE))
    return np.asarray(capture.valid, dtype=bool) & (amp > PATCH_SHARE * top) & (top > 0.0)


def observed_time_constant_s(times_s: Sequence[float], temperatures_c: Sequence[float]) -> float:
    """The time constant of ``T(t) = a + b exp(-t / tau)`` through the temperatures [s].

    For each ``tau`` of :data:`TIME_CONSTANT_SPANS` times the span the line in ``exp(-t/tau)``
    is solved by least squares; the ``tau`` of the smallest residual wins (clipped to the
    file's range). A sequence that is still straight at its end finds the largest searched.

    >>> t = np.arange(10) * 120.0
    >>> round(observed_time_constant_s(t, 45 - 20 * np.exp(-t / 600)) / 600, 1)
    1.0
    """
    t = np.asarray(times_s, dtype=np.float64)
    y = np.asarray(temperatures_c, dtype=np.float64)
    if t.size < 3 or t.shape != y.shape:
        raise ValueError(f"times_s and temperatures_c: {t.shape} and {y.shape}; two series of "
                         "the same length >= 3")
    span = float(t.max() - t.min())
    if not span > 0.0:  # every capture at one time: no curve to see
        raise ValueError("times_s: every time is the same; a curve needs a span")
    best_tau, best = math.inf, math.inf
    for tau in TIME_CONSTANT_SPANS * span:
        a = np.stack([np.ones_like(t), np.exp(-(t - t.min()) / tau)], axis=1)
        coef, *_ = np.linalg.lstsq(a, y, rcond=None)
        r = float(np.sum((a @ coef - y) ** 2))
        if r < best:
            best, best_tau = r, float(tau)
    return float(min(best_tau, MAX_TIME_CONSTANT_S))


def no_warmup(reason: str) -> RigWarmup:
    """The stage's outcome when there is nothing to fit: the drift not determined, for
    ``reason``; no key written, nothing removed."""
    return RigWarmup(None, Verdicts({DRIFT_KEY: Verdict("not determined", None, reason)}),
                     None, {"determined": False, "reason": reason})


def fit_rig_warmup(captures: Sequence[AveragedCapture], times_s: Sequence[float]) -> RigWarmup:
    """The warm-up stage fitted from its captures (in order, each with its frames kept) taken at
    the plan's ``times_s`` after the first (module docstring)."""
    frames = [f for c in captures for f in c.frames]
    temps = [c.illumination_temperature_c for c in captures]
    if not frames or any(t is None for t in temps):
        return no_warmup("the camera reports no illumination temperature with its frames: no "
                         "drift can be measured, none is removed")
    fit = fit_warmup(frames, warmup_patch(captures[0]))
    drift, std = fit.drift_mm_per_c, fit.drift_std_mm_per_c
    verdict = fit.verdict
    sigmas = float(np.min(np.abs(drift) / np.where(std > 0, std, np.inf))) if np.all(
        np.isfinite(drift)) else 0.0
    if verdict.determined and not sigmas >= MIN_DRIFT_SIGMAS:
        verdict = Verdict("not determined", verdict.std,
                          f"no drift above the noise: {', '.join(f'{k:+.4f}' for k in drift)} "
                          f"mm/degC is {sigmas:.2g} of its standard deviations from 0 (a drift "
                          f"needs {MIN_DRIFT_SIGMAS:g})")
    summary = {"drift_mm_per_c": drift.tolist(), "drift_std_mm_per_c": std.tolist(),
               "reduced_chi2": fit.reduced_chi2.tolist(),
               "temperatures_c": [float(t) for t in temps], "times_s": [float(t) for t in times_s],
               "frames": len(frames), "patch_px": int(warmup_patch(captures[0]).sum()),
               "determined": verdict.determined}
    if not verdict.determined:
        return RigWarmup(None, Verdicts({DRIFT_KEY: verdict}), fit,
                         {**summary, "reason": verdict.reason})
    tau = observed_time_constant_s(times_s, temps)
    temperature = CameraTemperature(**fit.temperature_key(temps[0], temps[-1], tau))
    reading = "a reading: the {} capture's reported illumination temperature (its frames' mean)"
    verdicts = Verdicts({
        START_KEY: Verdict("determined", None, reading.format("first") + ", at which the "
                           "calibration's depth errors hold"),
        END_KEY: Verdict("determined", None, reading.format("last")),
        TIME_CONSTANT_KEY: Verdict(
            "not determined", None, f"the warm-up's curve as observed over {times_s[-1]:.0f} s "
            "of the plan's time: a description, not a fit with error bars (the twin applies "
            "each frame's reported temperature, not the curve)"),
        DRIFT_KEY: verdict,
    })
    return RigWarmup(temperature, verdicts, fit, summary)
