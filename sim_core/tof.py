"""Reconstruction of range, amplitude and intensity from phasors (seed eqs. 4-7).

Shared by measured and simulated frames: whatever produced them, a frame reaches this module as
one complex correlation phasor per modulation frequency, ``A * exp(-1j * phi)`` with phi the
phase delay (seed eq. 4 in complex form: phi = atan2(C3 - C1, C0 - C2)), plus a DC/intensity.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from sim_core.camera import range_to_depth_z
from sim_core.constants import SPEED_OF_LIGHT_M_S

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class ToFImage:
    """What a ToF camera reports per pixel; arrays are (H, W) unless stated.

    Attributes
    ----------
    range_m : float64
        Radial distance [m]; NaN where ``valid`` is False.
    depth_z_m : float64
        Distance along the optical axis [m]; NaN where ``valid`` is False.
    amplitude : float64
        Modulation amplitude (seed eq. 5), in the unit of the input (radiance or electrons).
    intensity : float64
        Offset / DC (seed eq. 6), same unit.
    phase_rad : (n_f, H, W) float64
        Phase delay per frequency in [0, 2*pi).
    valid : bool
    frequencies_hz : (n_f,) float64
    """

    range_m: np.ndarray
    depth_z_m: np.ndarray
    amplitude: np.ndarray
    intensity: np.ndarray
    phase_rad: np.ndarray
    valid: np.ndarray
    frequencies_hz: np.ndarray


def phase_from_phasor(phasor: np.ndarray) -> np.ndarray:
    """Phase delay in [0, 2*pi) of phasors ``A * exp(-1j * phi)``; 0 where the phasor is 0.

    The quadrant is taken from the signs of both parts (atan2), not from a bare arctan.

    >>> phase_from_phasor(np.array([1 + 0j, -1j, -1 + 0j, 1j, 0j])) / np.pi
    array([0. , 0.5, 1. , 1.5, 0. ])
    """
    phi = np.mod(-np.angle(phasor), TWO_PI)
    # mod of a tiny negative number rounds to exactly 2*pi: fold it back to 0.
    return np.where(phi >= TWO_PI, 0.0, phi)


def ambiguity_range_m(frequency_hz: float) -> float:
    """Unambiguous range c / (2 f) of one modulation frequency [m].

    The pico flexx's 60.24 MHz wraps at 2.49 m; a target at 2.60 m reads as 0.11 m.

    >>> round(ambiguity_range_m(60.24e6), 3), round(ambiguity_range_m(80.32e6), 3)
    (2.488, 1.866)
    """
    return SPEED_OF_LIGHT_M_S / (2.0 * frequency_hz)


def range_from_phase(phase_rad: np.ndarray, frequency_hz: float) -> np.ndarray:
    """Range d = c * phi / (4 * pi * f) (seed eq. 7) [m].

    Half a turn of phase is half the ambiguity range:

    >>> f = 60.24e6
    >>> bool(np.isclose(range_from_phase(np.pi, f), ambiguity_range_m(f) / 2))
    True
    """
    return SPEED_OF_LIGHT_M_S * phase_rad / (2.0 * TWO_PI * frequency_hz)


def common_frequency_hz(f1: float, f2: float, max_denominator: int = 64) -> float:
    """Greatest common divisor of two modulation frequencies (e.g. 80.32 and 60.24 -> 20.08 MHz).

    Two frequencies together are unambiguous up to the ambiguity range of this one:

    >>> f = common_frequency_hz(80.32e6, 60.24e6)
    >>> round(f / 1e6, 2), round(ambiguity_range_m(f), 2)
    (20.08, 7.46)
    """
    ratio = Fraction(f1 / f2).limit_denominator(max_denominator)
    return f2 / ratio.denominator


def unwrap_two_frequencies(
    phase1_rad: np.ndarray, f1_hz: float, phase2_rad: np.ndarray, f2_hz: float
) -> np.ndarray:
    """Range from two wrapped phases, unambiguous up to c / (2 * gcd(f1, f2)).

    Tries every pair of wrap counts (n1, n2) inside the extended range and keeps, per pixel, the
    pair whose two ranges agree best; returns their precision-weighted mean (weights f^2, since
    the range noise of each frequency scales with 1/f).
    """
    u1, u2 = ambiguity_range_m(f1_hz), ambiguity_range_m(f2_hz)
    u_ext = ambiguity_range_m(common_frequency_hz(f1_hz, f2_hz))
    r1 = range_from_phase(phase1_rad, f1_hz)
    r2 = range_from_phase(phase2_rad, f2_hz)
    best_err = np.full(np.shape(r1), np.inf)
    best = np.zeros(np.shape(r1))
    w1, w2 = f1_hz**2, f2_hz**2
    for n1 in range(int(np.ceil(u_ext / u1))):
        c1 = r1 + n1 * u1
        for n2 in range(int(np.ceil(u_ext / u2))):
            c2 = r2 + n2 * u2
            # The candidates live on a circle of circumference u_ext: a range just below u_ext
            # and one just above 0 are neighbours, not u_ext apart (signed circular distance).
            diff = c2 - c1
            diff = diff - u_ext * np.round(diff / u_ext)
            err = np.abs(diff)
            better = err < best_err
            best_err = np.where(better, err, best_err)
            best = np.where(better, c1 + w2 / (w1 + w2) * diff, best)
    out = np.mod(best, u_ext)
    # mod of a tiny negative number rounds to exactly u_ext: fold it back to 0.
    return np.where(out >= u_ext, 0.0, out)


def reconstruct(
    phasor: np.ndarray,
    intensity: np.ndarray,
    frequencies_hz: np.ndarray,
    z_over_range: np.ndarray,
    valid: np.ndarray,
) -> ToFImage:
    """Range, depth, amplitude and phase from phasors.

    Parameters
    ----------
    phasor : (n_f, H, W) complex
    intensity : (H, W) float
        DC / offset to report (seed eq. 6).
    frequencies_hz : (n_f,) float
    z_over_range : (H, W) float
        Cosine of each pixel's ray with the optical axis: depth_z = range * z_over_range.
    valid : (H, W) bool
        Pixels to report; others get NaN range and depth.
    """
    freqs = np.asarray(frequencies_hz, dtype=np.float64)
    phase = phase_from_phasor(phasor)
    amplitude = np.abs(phasor[0])
    if freqs.size >= 2:
        rng = unwrap_two_frequencies(phase[0], freqs[0], phase[1], freqs[1])
    else:
        rng = range_from_phase(phase[0], freqs[0])
    ok = valid & np.isfinite(rng)
    rng = np.where(ok, rng, np.nan)
    return ToFImage(
        range_m=rng,
        depth_z_m=range_to_depth_z(rng, z_over_range),
        amplitude=amplitude,
        intensity=np.asarray(intensity, dtype=np.float64),
        phase_rad=phase,
        valid=ok,
        frequencies_hz=freqs,
    )
