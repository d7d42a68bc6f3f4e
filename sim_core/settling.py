"""The turntable's ringing after a move: a damped oscillation of the table's angle (issue 27).

The one home of the formula (:class:`sim_core.twin_file.TurntableSettling` holds its keys):
``t`` seconds after the end of a move the table is off its commanded angle by

    theta(t) = A exp(-zeta omega t) cos(omega_d t),
    omega = 2 pi f,  omega_d = omega sqrt(1 - zeta^2)

(a second-order system's free response released at its amplitude: the table, carried by a
compliant drive train, overshoots in the direction it moved). ``A = amplitude_deg``,
``f = frequency_hz`` (natural frequency), ``zeta = damping_ratio``. Before the move ends
(``t < 0``) there is no ringing. The envelope ``A exp(-zeta omega t)`` decays below a tolerance
after :func:`settle_time_s`: what the service waits before it captures.
"""

from __future__ import annotations

import math

import numpy as np

from sim_core.errors import InvalidInputError
from sim_core.twin_file import TurntableSettling

__all__ = ["damped_frequency_hz", "envelope_deg", "ringing_deg", "ringing_of_moves_deg",
           "settle_time_s"]


def damped_frequency_hz(settling: TurntableSettling) -> float:
    """The frequency the table is seen to ring at, ``f sqrt(1 - zeta^2)`` [Hz].

    The key's range keeps ``zeta <= 0.9``, so the square root's argument is at least 0.19.

    >>> round(damped_frequency_hz(TurntableSettling(amplitude_deg=0.1, frequency_hz=2.0,
    ...                                             damping_ratio=0.6)), 6)
    1.6
    """
    return settling.frequency_hz * math.sqrt(1.0 - settling.damping_ratio**2)


def envelope_deg(settling: TurntableSettling, t_s: np.ndarray | float) -> np.ndarray:
    """``A exp(-zeta omega t)`` for ``t >= 0``, 0 before the move ends [deg]."""
    t = np.asarray(t_s, dtype=np.float64)
    rate_per_s = settling.damping_ratio * 2.0 * math.pi * settling.frequency_hz
    # exp of a large negative number underflows to 0 (fine); t < 0 is clipped so exp never
    # overflows for times long before the move's end.
    decay = np.exp(-rate_per_s * np.maximum(t, 0.0))
    return np.where(t >= 0.0, settling.amplitude_deg * decay, 0.0)


def ringing_deg(settling: TurntableSettling, t_s: np.ndarray | float) -> np.ndarray:
    """The table's angle off its commanded one, ``t_s`` seconds after a move ended [deg].

    The free response of the module docstring; 0 for ``t_s < 0``. Positive is the move's
    direction (the caller multiplies by the move's sign).

    >>> s = TurntableSettling(amplitude_deg=0.2, frequency_hz=2.0, damping_ratio=0.05)
    >>> float(ringing_deg(s, 0.0)), float(ringing_deg(s, -1.0))
    (0.2, 0.0)
    """
    t = np.asarray(t_s, dtype=np.float64)
    omega_d = 2.0 * math.pi * damped_frequency_hz(settling)
    return envelope_deg(settling, t) * np.cos(omega_d * np.maximum(t, 0.0))


def ringing_of_moves_deg(settling: TurntableSettling, t_s: float,
                         ends_s: np.ndarray, signs: np.ndarray) -> float:
    """The table's angle off its commanded one at ``t_s`` from every move that ended [deg].

    ``ends_s`` are the moves' end times and ``signs`` their directions (+1, -1; 0 for a move
    that ended at rest): the free responses add (the system is linear), each from its own end.

    >>> s = TurntableSettling(amplitude_deg=0.2, frequency_hz=2.0, damping_ratio=0.05)
    >>> ringing_of_moves_deg(s, 5.0, np.array([5.0, 9.0]), np.array([-1.0, 1.0]))
    -0.2
    """
    ends = np.asarray(ends_s, dtype=np.float64)
    if ends.size == 0:
        return 0.0
    return float(np.sum(np.asarray(signs, dtype=np.float64)
                        * ringing_deg(settling, float(t_s) - ends)))


def settle_time_s(settling: TurntableSettling | None, tolerance_deg: float) -> float:
    """Seconds after a move until the ringing's envelope is below ``tolerance_deg``.

    ``ln(A / tol) / (zeta omega)``; 0 when there is no settling or ``A <= tol`` (the log's
    argument is then <= 1: nothing to wait for). ``tolerance_deg`` must be > 0 (the envelope
    reaches 0 only after an infinite time).

    >>> s = TurntableSettling(amplitude_deg=0.2, frequency_hz=2.0, damping_ratio=0.05)
    >>> round(settle_time_s(s, 0.002), 3), settle_time_s(None, 0.002), settle_time_s(s, 0.5)
    (7.329, 0.0, 0.0)
    """
    if not (math.isfinite(tolerance_deg) and tolerance_deg > 0.0):
        raise InvalidInputError("tolerance_deg",
                                f"got {tolerance_deg!r}; allowed: a finite angle > 0 deg")
    if settling is None or settling.amplitude_deg <= tolerance_deg:
        return 0.0
    rate_per_s = settling.damping_ratio * 2.0 * math.pi * settling.frequency_hz
    return math.log(settling.amplitude_deg / tolerance_deg) / rate_per_s
