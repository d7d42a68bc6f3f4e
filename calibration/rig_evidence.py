"""The rig procedures' results as evidence for their verdicts (:mod:`calibration.rig_verdicts`).

The one place that reads each procedure's result for what its verdicts need: the corners'
noise from the noise model, the reprojection's chi-square per view and per stage, the depth
fit's, the sensor's, the source power's and the solar simulator's.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from calibration.noise_gain import tap_difference_variance_dn2
from calibration.rig_verdicts import (
    GAIN_REL,
    POWER_REL,
    READ_NOISE_REL,
    SOLAR_REL,
    DepthEvidence,
    StageEvidence,
    reduced_chi2,
    relative_verdict,
)
from calibration.verdicts import Verdict, Verdicts
from calibration.warmup import DRIFT_KEY
from sim_core.constants import SPEED_OF_LIGHT_M_S

#: the saddle-point detector's own error per coordinate [px], beyond the image noise it sees:
#: what the bias synthesis leaves (the detector's response to what the twin's render and the
#: camera's image do not share). Measured on reality 101 of the round trip (default plan, 4
#: frames per view): 0.032 px per coordinate through the joint model after the synthesis, of
#: which 0.006 px is the image's noise; 0.04 px keeps that calibration's worst view at a
#: reduced chi-square of 1.5 and its stage at 0.65.
CORNER_DETECTOR_FLOOR_PX = 0.04


def amplitude_std_dn(cap, noise) -> np.ndarray:
    """(H, W) standard deviation of an averaged capture's amplitude [DN]: ``var(C) / 2`` per
    frame (:func:`calibration.noise_gain.tap_difference_variance_dn2`) over its frames."""
    var_c = tap_difference_variance_dn2(cap.intensity, noise.adc_gain_e_per_dn,
                                        noise.read_noise_e)
    return np.sqrt(var_c / 2.0 / max(cap.n_frames, 1))


def corner_std_px(view, cap, noise) -> np.ndarray:
    """(n, 2) standard deviation of a view's corners: the amplitude's noise through the flat
    field and the saddle-point fit the detector ends with, and the detector's own error
    (:data:`CORNER_DETECTOR_FLOOR_PX`) in quadrature."""
    # OpenCV's detector is imported with its use: the service starts without OpenCV
    from calibration.board_detection import flat_field, flat_field_levels, saddle_std_px

    amp = np.asarray(cap.amplitude, dtype=np.float64)
    _, span = flat_field_levels(amp)
    # no contrast (span 0) defines no corner: its noise in the flat field is unbounded
    pixel_std = np.where(span > 0, amplitude_std_dn(cap, noise) / np.where(span > 0, span, 1.0),
                         np.inf)
    noise = saddle_std_px(flat_field(amp), view.image_points_px, pixel_std)
    return np.hypot(noise, CORNER_DETECTOR_FLOOR_PX)


def reprojection_stage(axis, corner_std: dict[str, np.ndarray]) -> dict[str, Any]:
    """The joint adjustment against the corners' noise: its reduced chi-square, each view's,
    and the parameters' standard deviations from its Jacobian at the corners' RMS noise."""
    names = [n for n in axis.residuals_px if n in corner_std]
    r = np.concatenate([axis.residuals_px[n].ravel() for n in names]) if names else np.zeros(0)
    s = np.concatenate([corner_std[n].ravel() for n in names]) if names else np.zeros(0)
    n_params = len(axis.parameter_names)
    per_view = {n: reduced_chi2(axis.residuals_px[n], corner_std[n]) for n in names}
    finite = s[np.isfinite(s) & (s > 0)]
    sigma = float(np.sqrt(np.mean(finite**2))) if finite.size else math.inf
    cov = axis.unit_covariance
    std: dict[str, float] = {}
    if cov is not None and math.isfinite(sigma):
        diag = np.sqrt(np.maximum(np.diag(cov), 0.0)) * sigma
        std = {n: float(d) for n, d in zip(axis.parameter_names, diag, strict=True)}
    return {"chi2": reduced_chi2(r, s, n_params), "per_view": per_view, "std": std}


def free_stage_chi2(free, corner_std: dict[str, np.ndarray]) -> float:
    """OpenCV's free-pose stage against the corners' noise: each view's RMS point distance
    squared against twice its corners' mean variance, weighted by its corners, over the
    degrees of freedom (8 camera parameters, 6 a view)."""
    num = den = 0.0
    n_corners = 0
    for name, rms in free.per_view_rms_px.items():
        s = corner_std.get(name)
        if s is None:
            continue
        ok = np.all(np.isfinite(s), axis=1)
        if not ok.any():
            continue
        num += s.shape[0] * rms**2
        den += s.shape[0] * float(np.sum(s[ok] ** 2, axis=1).mean())
        n_corners += s.shape[0]
    dof = 2 * n_corners - 8 - 6 * len(free.per_view_rms_px)
    if den <= 0 or dof <= 0:
        return math.inf
    return float(num / den * 2 * n_corners / dof)


def corner_radius(views, intr) -> float:
    """The largest normalised radius (pixel offset from the principal point over the focal
    length) of the corners the views saw: how far out the distortion was measured."""
    k = intr.intrinsics
    pts = np.concatenate([v.image_points_px for v, _, _ in views])
    x = (pts[:, 0] - k.cx_px) / k.fx_px
    y = (pts[:, 1] - k.cy_px) / k.fy_px
    return float(np.max(np.hypot(x, y)))


def drift_carried_std_rad(frequencies_hz, drift_std_mm_per_c, mean_rise_c: float) -> list[float]:
    """Per frequency, the phase error the drift coefficient's own error leaves in the depth
    model [rad]: the board views' drift is removed at ``k (T - T_start)``
    (:func:`calibration.captures.drift_free_phase_rad`), so an error ``s_k`` of ``k`` moves their
    common range by ``s_k * mean(T - T_start)`` (``mean_rise_c``), which the phase offset takes
    up: ``4 pi f s_k mean_rise / c`` (the seed's range-phase relation). One ``s_k`` for all
    frequencies is used for each; a NaN or infinite ``s_k`` carries as infinite (a NaN
    ``mean_rise_c`` too), views at the reference temperature as 0.

    >>> [round(v, 6) for v in drift_carried_std_rad([60.24e6], [0.02], 10.0)]  # 0.2 mm
    [0.000505]
    """
    f = np.asarray(frequencies_hz, dtype=np.float64).ravel()
    s = np.abs(np.asarray(drift_std_mm_per_c, dtype=np.float64).ravel())
    if s.size not in (1, f.size):
        s = np.full(1, float(np.max(s)) if s.size else math.inf)
    s = np.broadcast_to(s, f.shape)
    rise_c = abs(float(mean_rise_c))
    if not math.isfinite(rise_c):
        return [math.inf] * f.size
    if rise_c == 0.0:  # the views at the reference temperature: the coefficient moves nothing
        return [0.0] * f.size
    # an unknown coefficient error carries as unbounded whatever the rise (no inf * 0 = NaN
    # when a tiny rise underflows in the product)
    phase_per_mm = 4.0 * math.pi * f * 1e-3 / SPEED_OF_LIGHT_M_S
    return [math.inf if not math.isfinite(sk) else float(k * sk * rise_c)
            for k, sk in zip(phase_per_mm, s, strict=True)]


def depth_evidence(depth, frequencies_hz, drift_std_rad=None) -> DepthEvidence:
    """The depth fit's chi-square and standard deviations as the verdicts read them; with
    ``drift_std_rad`` (:func:`drift_carried_std_rad`) the drift coefficient's error is added to
    the model's standard deviation in quadrature (the fit alone does not see it)."""
    model_std = [float(v) for v in depth.model_std_rad]
    if drift_std_rad is not None and len(drift_std_rad):
        # one per frequency; a model of another length takes the largest for each (never none)
        drift = (list(drift_std_rad) if len(drift_std_rad) == len(model_std)
                 else [max(drift_std_rad)] * len(model_std))
        model_std = [math.hypot(m, d) for m, d in zip(model_std, drift, strict=True)]
    bad = [n for n, c in depth.per_view_reduced_chi2.items() if not c <= 2.0]
    where = "the depth model on the board (range residual against the phase noise)"
    if bad:
        where += f"; views above 2: {', '.join(bad[:6])}" + (" ..." if len(bad) > 6 else "")
    return DepthEvidence(
        stage=StageEvidence(depth.reduced_chi2, where),
        model_std_rad=model_std, pixel_offset_std_m=depth.pixel_offset_std_m,
        frequencies_hz=list(np.asarray(frequencies_hz, dtype=float).ravel()),
        phase_span_rad=depth.phase_span_rad, range_span_m=depth.range_span_m,
        coverage=depth.coverage)


#: the sensor's gain key
GAIN_KEY = "camera.sensor.adc_gain_e_per_dn"


def other_verdicts(noise, power, solar) -> dict[str, Verdict]:
    """The sensor's, the source power's and the solar simulator's keys."""
    ptc = StageEvidence(noise.reduced_chi2, "the photon transfer line (bins' variance against "
                        "their standard errors)")
    out = {
        GAIN_KEY: relative_verdict(
            noise.adc_gain_e_per_dn, noise.gain_std_error, GAIN_REL, ptc, " e-/DN"),
        "camera.sensor.read_noise_e": relative_verdict(
            noise.read_noise_e, noise.read_noise_std_error, READ_NOISE_REL, ptc, " e-"),
    }
    # The twin predicts in DN through the calibrated gain: the power's and the solar scale's
    # ratios carry the gain's relative error too (electrons = DN x gain).
    gain_rel = noise.gain_std_error / noise.adc_gain_e_per_dn
    chi2 = power.regions_reduced_chi2 if math.isfinite(power.regions_reduced_chi2) else 1.0
    ratio_rel = max(power.ratio_std_error, power.regions_std_error
                    if math.isfinite(power.regions_std_error) else 0.0) / power.ratio
    out["illumination.power_w"] = relative_verdict(
        power.power_w, power.power_w * math.hypot(ratio_rel, gain_rel), POWER_REL,
        StageEvidence(chi2, f"the source power: {power.n_regions} white squares' ratios of "
                            "measured to predicted amplitude against one another (a small "
                            "shift of the twin's image fitted out)",
                      dof=max(power.regions_dof, 1)), " W")
    if solar is not None:
        if solar.method == "frames":
            scale = solar.irradiance_scale
            out["solar_simulator.irradiance_scale"] = through_gain(relative_verdict(
                scale, scale * math.hypot(solar.std_error / scale, gain_rel), SOLAR_REL,
                StageEvidence(solar.reduced_chi2, "the solar simulator's intensity response")),
                out[GAIN_KEY])
        else:
            out["solar_simulator.irradiance_scale"] = Verdict(
                "not determined", None, f"the frames do not determine it ({solar.reason}); the "
                "value is the reference cell's reading, with the cell's own uncertainty")
    out["illumination.power_w"] = through_gain(out["illumination.power_w"], out[GAIN_KEY])
    return out


def through_gain(verdict: Verdict, gain: Verdict) -> Verdict:
    """A key the twin predicts through the calibrated gain (DN to electrons) claims no more than
    the gain does: its own verdict while the gain is determined, else the gain's (``unexplained``
    or ``not determined``), saying so. A wrong gain moves the power and the solar scale alike
    and their own residuals cannot see it (the rig sweep's reality 203: the photon transfer line
    unexplained at reduced chi-square 1,430, the gain 58 % off, and both keys 58 % off at 134 and
    190 standard deviations of their own)."""
    return through(verdict, GAIN_KEY, gain, ("unexplained", "not determined"))


def through(verdict: Verdict, upstream_key: str, upstream: Verdict,
            inherit: tuple[str, ...]) -> Verdict:
    """``verdict`` of a key measured through ``upstream_key``: the upstream's verdict when that
    is one of ``inherit`` and the key's own is ``determined``, saying why; else its own."""
    if not verdict.determined or upstream.verdict not in inherit:
        return verdict
    return Verdict(upstream.verdict, verdict.std,
                   f"measured through {upstream_key}, which is {upstream.verdict}: "
                   f"{upstream.reason}")


def depth_through_drift(verdicts: Verdicts) -> Verdicts:
    """The depth keys claim nothing while the warm-up drift they are fitted without is
    ``unexplained``: its model is then not written nor removed, and the board views, captured at
    other temperatures than the start, leave the drift in the depth model (the rig sweep's
    reality 204: the drift unexplained at reduced chi-square 3.0, the phase offset 12.8 mm off
    at 370 standard deviations). A drift ``not determined`` (none above the noise) leaves them."""
    drift = verdicts.get(DRIFT_KEY)
    if drift is None:
        return verdicts
    return Verdicts({k: through(v, DRIFT_KEY, drift, ("unexplained",))
                     if k.startswith("camera.depth.") else v for k, v in verdicts.items()})
