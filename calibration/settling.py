"""The turntable's settling from frames after a move: frequency, damping and amplitude (issue 27).

Input: the table's angle seen in the frames taken after a move (a board's or a patch's angle
per frame, e.g. from its plane's normal: :func:`plane_yaw_deg`), against the frames' times,
with the angle's noise. Model (:mod:`sim_core.settling`, the key ``turntable.settling``):

    angle(t) = offset + A exp(-zeta omega (t - t0)) cos(omega_d (t - t0)),  t >= t0

``omega = 2 pi f``, ``omega_d = omega sqrt(1 - zeta^2)``; ``t0`` is the move's end, fitted
(the controller's READY is polled, so it is known only roughly); before it, no ringing.
Weighted least squares (:func:`scipy.optimize.least_squares`) from a start found by the series'
spectrum (several starts of the move's end and the sign: the nearest minimum is not always the
best); the standard deviations from the whitened Jacobian, made honest by the residual and
judged (:func:`calibration.verdicts.judge`): frequency to 2 % (so that it is within the 5 %
target at 2.5 sigma), damping ratio to 30 %, amplitude to 20 %. A series whose ringing the
noise hides gives ``not determined``; one the model does not explain, ``unexplained``.

The estimator sees only the measured series, never the simulated lab's reality.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from calibration.verdicts import CHI2_UNEXPLAINED, Verdict, Verdicts, honest_std, judge
from sim_core.errors import InvalidInputError
from sim_core.twin_file import TurntableSettling

__all__ = ["SettlingFit", "fit_settling", "plane_yaw_deg"]

#: relative standard deviations a determined key may have
FREQUENCY_LIMIT = 0.02
DAMPING_LIMIT = 0.3
AMPLITUDE_LIMIT = 0.2
#: a ringing is seen when its amplitude stands this many standard deviations above zero
RINGING_SIGMAS = 3.0
#: fewest frames per damped period the series must have (Nyquist is 2; a fit needs more)
MIN_SAMPLES_PER_PERIOD = 4.0
KEY = "turntable.settling"


@dataclass(frozen=True)
class SettlingFit:
    """The settling to write (None unless every key is determined), the verdict of each key,
    and the fit's figures: the estimate whatever its verdicts (``estimate``: printed, not to be
    trusted unless determined; None when it is outside the key's ranges), the reduced
    chi-square, the fitted move end and rest angle."""

    settling: TurntableSettling | None
    verdicts: Verdicts
    reduced_chi2: float
    t0_s: float
    offset_deg: float
    estimate: TurntableSettling | None = None


def _model(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    offset, amp, f, zeta, t0 = p
    tau = t - t0
    omega = 2.0 * math.pi * f
    # zeta stays in (0, 1) by the bounds: the square root's argument is positive
    omega_d = omega * math.sqrt(1.0 - zeta * zeta)
    # tau < 0 clipped inside exp so it never overflows; no ringing before the move's end, as
    # sim_core.settling.ringing_deg has it
    ring = amp * np.exp(-zeta * omega * np.maximum(tau, 0.0)) * np.cos(omega_d * tau)
    return offset + np.where(tau >= 0.0, ring, 0.0)


def _start(t: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Frequency, amplitude and rest angle to start from: the spectrum's peak of the series
    (detrended by its last third's mean, the table nearly at rest there)."""
    rest = float(np.mean(y[2 * len(y) // 3:]))
    d = y - rest
    dt = float(np.median(np.diff(t)))
    spectrum = np.abs(np.fft.rfft(d * np.hanning(len(d))))
    freqs = np.fft.rfftfreq(len(d), dt)
    k = int(np.argmax(spectrum[1:])) + 1  # not the DC bin
    return float(freqs[k]), float(d[0]), rest


def fit_settling(t_s: np.ndarray, angle_deg: np.ndarray, angle_std_deg: float) -> SettlingFit:
    """Fit the settling to the table's angle ``angle_deg`` at times ``t_s`` after a move.

    ``angle_std_deg`` is one frame's angle noise (> 0). Needs at least 12 frames, sampled
    evenly enough that the median step resolves the ringing (at least
    :data:`MIN_SAMPLES_PER_PERIOD` frames per period of the frequency found).
    """
    t = np.asarray(t_s, dtype=np.float64)
    y = np.asarray(angle_deg, dtype=np.float64)
    if t.ndim != 1 or t.shape != y.shape or t.size < 12:
        raise InvalidInputError("t_s", f"times and angles must be two series of the same length "
                                f">= 12; got {t.shape} and {y.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise InvalidInputError("angle_deg", "every time and angle must be finite")
    if not np.all(np.diff(t) > 0.0):
        raise InvalidInputError("t_s", "the times must increase strictly")
    if not (math.isfinite(angle_std_deg) and angle_std_deg > 0.0):
        raise InvalidInputError("angle_std_deg",
                                f"got {angle_std_deg!r}; allowed: a finite angle > 0 deg")
    f0, a0, rest0 = _start(t, y)
    nyquist = 0.5 / float(np.median(np.diff(t)))
    p0 = np.array([rest0, a0 if a0 != 0.0 else angle_std_deg, f0, 0.05, float(t[0])])
    lo = np.array([-np.inf, -np.inf, 1e-3, 1e-3, float(t[0]) - 1.0 / f0])
    hi = np.array([np.inf, np.inf, nyquist, 0.9, float(t[0]) + 0.5 / f0])
    res = None
    # the move's end and the ringing's sign are ambiguous by a period: start from a few of
    # each and keep the best fit (least squares finds the nearest minimum only)
    for shift in (0.0, -0.25, -0.5, -0.75):
        for sign in (1.0, -1.0):
            start = p0.copy()
            start[1] = sign * abs(p0[1])
            start[4] = p0[4] + shift / f0
            start = np.clip(start, lo + 1e-9, hi - 1e-9)
            r = least_squares(lambda p: (_model(p, t) - y) / angle_std_deg, start,
                              bounds=(lo, hi), x_scale="jac")
            if res is None or r.cost < res.cost:
                res = r
    dof = max(t.size - 5, 1)
    chi2 = float(np.sum(res.fun**2) / dof)
    offset, amp, f, zeta, t0 = (float(v) for v in res.x)
    jtj = res.jac.T @ res.jac
    # a singular J^T J (no ringing to fit): every direction unbounded
    cov = np.linalg.pinv(jtj) if np.linalg.matrix_rank(jtj) == 5 else np.full((5, 5), np.inf)
    std = np.sqrt(np.abs(np.diag(cov)))
    where = f"the series of {t.size} frames after the move"
    verdicts = Verdicts()
    amp_abs = abs(amp)
    amp_std = honest_std(float(std[1]), chi2)
    explained = math.isfinite(chi2) and chi2 <= CHI2_UNEXPLAINED  # else judge says unexplained
    if explained and not (math.isfinite(amp_std) and amp_abs > RINGING_SIGMAS * amp_std):
        # No ringing the series can tell from its noise: the frequency and damping of a
        # ringing that is not there are the noise's (a table that settled at once gave
        # "determined" frequencies with 2 % errors bars in the rig's round trips).
        reason = (f"{where}: no ringing above the yaw's noise (amplitude {amp_abs:.2g} +- "
                  f"{amp_std:.2g} deg, less than {RINGING_SIGMAS:g} standard deviations)")
        for key in ("amplitude_deg", "frequency_hz", "damping_ratio"):
            verdicts.add(f"{KEY}.{key}", Verdict("not determined", None, reason))
        return SettlingFit(None, verdicts, chi2, t0, offset, _estimate(amp_abs, f, zeta))
    samples_per_period = 1.0 / (f * float(np.median(np.diff(t))))
    if samples_per_period < MIN_SAMPLES_PER_PERIOD:
        reason = (f"{samples_per_period:.2g} frames per period of the {f:.3g} Hz found; at least "
                  f"{MIN_SAMPLES_PER_PERIOD:g} are needed (take frames faster)")
        for key in ("amplitude_deg", "frequency_hz", "damping_ratio"):
            verdicts.add(f"{KEY}.{key}", Verdict("not determined", None, reason))
        return SettlingFit(None, verdicts, chi2, t0, offset, _estimate(amp_abs, f, zeta))
    verdicts.add(f"{KEY}.amplitude_deg",
                 judge(std[1], AMPLITUDE_LIMIT * amp_abs, reduced_chi2=chi2, unit=" deg",
                       where=where))
    verdicts.add(f"{KEY}.frequency_hz",
                 judge(std[2], FREQUENCY_LIMIT * f, reduced_chi2=chi2, unit=" Hz", where=where))
    verdicts.add(f"{KEY}.damping_ratio",
                 judge(std[3], DAMPING_LIMIT * zeta, reduced_chi2=chi2, where=where))
    estimate = _estimate(amp_abs, f, zeta)
    determined = all(v.determined for v in verdicts.values())
    return SettlingFit(estimate if determined else None, verdicts, chi2, t0, offset, estimate)


def _estimate(amplitude_deg: float, frequency_hz: float,
              damping_ratio: float) -> TurntableSettling | None:
    """The fitted values as the key, or None where they leave its ranges."""
    try:
        return TurntableSettling(amplitude_deg=amplitude_deg, frequency_hz=frequency_hz,
                                 damping_ratio=damping_ratio)
    except ValueError:  # pydantic's ValidationError: e.g. an amplitude above 5 deg
        return None


def plane_yaw_deg(points_m: np.ndarray) -> float:
    """The yaw of a plane through ``points_m`` (n, 3) in the camera frame [deg]: the angle of
    its normal about the camera's y axis (image down), ``atan2(n_x, -n_z)``, 0 for a board
    facing the camera. A turntable with a vertical axis turns a board about it: the series of
    yaws after a move is what :func:`fit_settling` takes.

    >>> pts = np.array([[x, y, 1.0 + 0.1 * x] for x in (-0.1, 0.0, 0.1) for y in (-0.1, 0.1)])
    >>> round(plane_yaw_deg(pts), 3)
    5.711
    """
    p = np.asarray(points_m, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 3 or not np.all(np.isfinite(p)):
        raise InvalidInputError("points_m", f"need (n >= 3, 3) finite points; got {p.shape}")
    centred = p - p.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    if s[1] <= 1e-12 * max(s[0], 1e-300):  # collinear points: no plane
        raise InvalidInputError("points_m", "the points are collinear: they define no plane")
    n = vt[2]
    if n[2] > 0.0:  # the normal towards the camera
        n = -n
    return math.degrees(math.atan2(n[0], -n[2]))
