"""Accuracy as a knob: sample until the range error is small enough, or until time runs out.

The Monte Carlo standard error of a pixel's range follows from the spread of its samples'
phasors (``LightField.phasor_standard_error``): the phasor component perpendicular to the mean
moves the phase, sigma_phi = sigma_perp / |mean|, and sigma_range = c / (4 pi f) sigma_phi
(seed eq. 7). Sampling works in rounds; every round gives more samples only to the pixels that
matter (their centre ray hits a surface that returns light) and whose estimate is still above
the target, as many as the 1/sqrt(n) law says they need (at most 4x per round, since the
estimate itself is noisy at low counts).

A second target ties the render to the camera it simulates (``target_noise_fraction``): the
Monte Carlo standard error of the phasor, across and along its mean (phase and amplitude, the
depth and grey images), at most that fraction of the sensor's own shot and read noise
(:func:`sim_core.sensor.predicted_phase_std_rad`, the relative noise of the phasor). A twin
compared with a capture then adds little to the capture's noise: at a fraction k the twin's
error variance is (1 + k^2) times the sensor's, instead of the unbounded Monte Carlo variance
of glints and edges at a fixed spp. Bright glints get samples; pixels drowned in sensor noise
(dark ones, or in sunlight) get none.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.errors import InvalidInputError
from sim_core.render import LightField, ProgressiveRenderer, RenderResult, RenderSettings
from sim_core.scene import Scene
from sim_core.sensor import mean_electrons, predicted_phase_std_rad
from sim_core.tracing import RayTracer

#: samples every pixel gets before any estimate is trusted
INITIAL_SPP = 16
#: hard cap of samples per pixel, so dark or pathological pixels cannot stall the render
MAX_SPP = 16384
#: growth of a pixel's sample count per round, at most
MAX_GROWTH = 4.0
#: the Monte Carlo error targets a user may ask for, as a fraction of the sensor's noise
#: (below 0.05 a render costs 400x the samples of 1; above 2 it adds 5x the sensor's variance)
NOISE_FRACTION_RANGE = (0.05, 2.0)


@dataclass(frozen=True)
class AdaptiveReport:
    """What adaptive sampling did and reached; ``to_dict`` goes into frame.json."""

    target_range_error_mm: float | None
    time_budget_s: float | None
    achieved_range_error_mm: float
    achieved_range_error_p95_mm: float
    fraction_meeting_target: float
    seconds: float
    rounds: int
    pixels_that_matter: int
    spp_min: int
    spp_mean: float
    spp_max: int
    #: the target as a fraction of the sensor's noise, and the largest fraction reached (the
    #: Monte Carlo standard error over the sensor's standard deviation, over the pixels that
    #: matter)
    target_noise_fraction: float | None = None
    achieved_noise_fraction: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)


def range_standard_error_m(lf: LightField, k: int = 0) -> np.ndarray:
    """Monte Carlo standard error of range per pixel [m]; inf where there is no signal."""
    mag = np.abs(lf.phasor[k])
    se_perp = lf.phasor_standard_error()[k]
    sigma_phi = np.where(mag > 0.0, se_perp / np.where(mag > 0.0, mag, 1.0), np.inf)
    return SPEED_OF_LIGHT_M_S / (4.0 * np.pi * lf.frequencies_hz[k]) * sigma_phi


def pixels_that_matter(lf: LightField) -> np.ndarray:
    """Pixels whose centre ray hits geometry that returns the camera's light, (H, W) bool."""
    return lf.hit & (lf.dc_active > 0.0)


def noise_fraction(lf: LightField, scene: Scene) -> np.ndarray:
    """Monte Carlo standard error of the phasor over the sensor's noise, per pixel (H, W):
    the larger of the error across the mean (phase) and along it (amplitude), relative to
    |phasor|, over :func:`sim_core.sensor.predicted_phase_std_rad`, the worst frequency.

    0 where the sensor sees no modulated light (its noise is infinite there), inf where the
    pixel has signal but no samples. The optics' blur is not applied: the sensor's noise is
    predicted from the light field itself, which is what sampling can change.
    """
    e = mean_electrons(lf.dc_active, lf.dc_ambient, lf.phasor, scene.camera, scene.sensor)
    mag = np.abs(lf.phasor)
    perp = lf.phasor_standard_error("perpendicular")
    par = lf.phasor_standard_error("parallel")
    out = np.zeros(lf.shape)
    for k in range(mag.shape[0]):
        sensor_rel = predicted_phase_std_rad(e, scene.sensor, k)
        signal = mag[k] > 0.0
        # A huge error over a subnormal phasor overflows to inf (the pixel is all noise);
        # inf / inf where the sensor sees nothing either is discarded by the where.
        with np.errstate(over="ignore", invalid="ignore"):
            rel_mc = np.where(signal,
                              np.maximum(perp[k], par[k]) / np.where(signal, mag[k], 1.0), 0.0)
            ratio = np.where(np.isfinite(sensor_rel), rel_mc / sensor_rel, 0.0)
        out = np.maximum(out, ratio)
    return out


def render_adaptive(
    scene: Scene,
    settings: RenderSettings,
    target_range_error_m: float | None = None,
    time_budget_s: float | None = None,
    tracer: RayTracer | None = None,
    initial_spp: int = INITIAL_SPP,
    max_spp: int = MAX_SPP,
    target_noise_fraction: float | None = None,
    clock: Callable[[], float] = time.perf_counter,
) -> tuple[RenderResult, AdaptiveReport]:
    """Render until every pixel that matters has a range standard error below the target
    and/or a Monte Carlo error below ``target_noise_fraction`` of the sensor's noise (module
    docstring), or (with ``time_budget_s``) spend the budget on the worst pixels; any
    combination may be given. Every pixel gets ``initial_spp`` samples first, none more than
    ``max_spp``.

    ``clock`` measures the budget and the reported seconds: wall time by default (what a user
    waits for); ``time.process_time`` makes a budget one of CPU seconds, which other processes
    on the machine do not eat into (the tests use it, so that they hold under load).
    """
    if target_range_error_m is None and time_budget_s is None and target_noise_fraction is None:
        raise InvalidInputError(
            "target_range_error_mm",
            "give a target range error, a target noise fraction or a time budget",
        )
    if target_range_error_m is not None and not 0.0 < target_range_error_m < 1e3:
        raise InvalidInputError(
            "target_range_error_mm", f"{target_range_error_m * 1e3} mm is outside (0, 1e6) mm"
        )
    lo, hi = NOISE_FRACTION_RANGE
    if target_noise_fraction is not None and not lo <= target_noise_fraction <= hi:
        raise InvalidInputError(
            "target_noise_fraction", f"{target_noise_fraction} is outside [{lo:g}, {hi:g}]"
        )
    if time_budget_s is not None and not 0.0 < time_budget_s <= 86_400.0:
        raise InvalidInputError("time_budget_s", f"{time_budget_s} s is outside (0, 86400] s")
    if not 1 <= initial_spp <= max_spp:
        raise InvalidInputError("spp", f"initial {initial_spp} must be in [1, {max_spp}]")
    t0 = clock()
    r = ProgressiveRenderer(scene, settings, tracer)
    try:
        r.add_samples(initial_spp)
        rounds = 1
        while True:
            lf = r.light_field()
            matter = pixels_that_matter(lf).ravel()
            n = r.acc.n
            elapsed = clock() - t0
            if time_budget_s is not None and elapsed >= time_budget_s:
                break
            open_ = matter & (n < max_spp)
            ratio = _error_ratio(lf, scene, target_range_error_m, target_noise_fraction)
            # what the budget spends on first: the worst ratio, or without a target the worst
            # range error
            worst = ratio if ratio is not None else range_standard_error_m(lf).ravel()
            if ratio is not None:
                open_ &= ratio > 1.0
                want = np.where(open_, n * ratio**2, n)
            else:
                # Budget only: halve the error of the worse half of the pixels each round.
                if not open_.any():
                    break
                open_ &= worst >= np.median(worst[open_])
                want = np.where(open_, 4.0 * n, n)
            if not open_.any():
                break
            grow = np.clip(want, n + 1, np.minimum(MAX_GROWTH * n, max_spp)) - n
            extra = np.where(open_, np.ceil(grow), 0).astype(np.int64)
            if time_budget_s is not None:
                per_sample = (clock() - t0) / max(int(n.sum()), 1)
                extra = _fit_budget(extra, worst, per_sample, time_budget_s - elapsed)
                if not extra.any():
                    break
            _add_grouped(r, extra, n, max_spp)
            rounds += 1
        result = r.result()
    finally:
        r.close()
    return result, _report(result.light_field, scene, target_range_error_m,
                           target_noise_fraction, time_budget_s, clock() - t0,
                           rounds)


def _error_ratio(lf: LightField, scene: Scene, target_range_error_m: float | None,
                 target_noise_fraction: float | None) -> np.ndarray | None:
    """Per pixel (flat), the largest error over its target among the targets given; None
    without a target (budget only). Above 1: the pixel needs more samples."""
    ratios = []
    if target_range_error_m is not None:
        ratios.append(range_standard_error_m(lf).ravel() / target_range_error_m)
    if target_noise_fraction is not None:
        ratios.append(noise_fraction(lf, scene).ravel() / target_noise_fraction)
    return np.maximum.reduce(ratios) if ratios else None


def _report(lf: LightField, scene: Scene, target_range_error_m: float | None,
            target_noise_fraction: float | None, time_budget_s: float | None, seconds: float,
            rounds: int) -> AdaptiveReport:
    se = range_standard_error_m(lf)
    matter = pixels_that_matter(lf)
    se_m = se[matter]
    finite = se_m[np.isfinite(se_m)]
    spp = lf.samples_per_pixel[matter] if matter.any() else lf.samples_per_pixel.ravel()
    meeting = 1.0
    achieved_fraction = None
    if matter.any():
        ok = np.ones(se_m.shape, dtype=bool)
        if target_range_error_m is not None:
            ok &= se_m <= target_range_error_m
        if target_noise_fraction is not None:
            frac = noise_fraction(lf, scene)[matter]
            ok &= frac <= target_noise_fraction
            achieved_fraction = float(frac.max())
        meeting = float(np.mean(ok))
    return AdaptiveReport(
        target_range_error_mm=None if target_range_error_m is None else target_range_error_m * 1e3,
        time_budget_s=time_budget_s,
        achieved_range_error_mm=float(finite.max() * 1e3) if finite.size else 0.0,
        achieved_range_error_p95_mm=float(np.percentile(finite, 95) * 1e3) if finite.size else 0.0,
        fraction_meeting_target=meeting,
        seconds=seconds,
        rounds=rounds,
        pixels_that_matter=int(matter.sum()),
        spp_min=int(spp.min()) if spp.size else 0,
        spp_mean=float(spp.mean()) if spp.size else 0.0,
        spp_max=int(spp.max()) if spp.size else 0,
        target_noise_fraction=target_noise_fraction,
        achieved_noise_fraction=achieved_fraction,
    )


def _fit_budget(extra: np.ndarray, se: np.ndarray, per_sample_s: float, left_s: float):
    """Keep the worst pixels' extra samples that fit in the time left."""
    cost = extra * per_sample_s
    if cost.sum() <= left_s:
        return extra
    order = np.argsort(-np.where(extra > 0, se, -np.inf))
    fits = np.cumsum(cost[order]) <= left_s
    out = np.zeros_like(extra)
    out[order[fits]] = extra[order[fits]]
    return out


def _add_grouped(r: ProgressiveRenderer, extra: np.ndarray, n: np.ndarray, max_spp: int) -> None:
    """Give each pixel ``extra`` more samples, in batches of pixels that want the same count.

    Counts are rounded up to powers of two so that there are few batches (each one a request
    to the renderer for its pixels), or down where rounding up would pass ``max_spp`` (a
    pixel's samples so far are ``n``).
    """
    need = extra > 0
    levels = np.zeros_like(extra)
    up = 2 ** np.ceil(np.log2(extra[need])).astype(np.int64)
    down = 2 ** np.floor(np.log2(extra[need])).astype(np.int64)
    levels[need] = np.where(n[need] + up <= max_spp, up, down)
    for k in np.unique(levels[need]):
        r.add_samples(int(k), np.flatnonzero(levels == k))
