"""The simulated lab's clock: what time it is in the simulated world when a frame is exposed.

The simulated devices run on wall-clock time scaled or made instant (:class:`drivers.sim.
SimClock`), so the wall clock says nothing about how long the simulated lab has been running:
an instant rig takes a campaign of an hour in seconds. The world's slow processes (the
illumination's warm-up, :mod:`sim_core.warmup`) need the time a real lab would have spent:
:class:`LabClock` counts it from the service's start (the world's creation), advancing by one
frame period for every frame the camera exposes and by the stage's time for every move between
two frames (its trapezoidal profile at the SMC100's velocity and acceleration,
:func:`drivers.sim.smc100.trapezoid`). It keeps when each move ended and which way it went
(:meth:`LabClock.moves`): an instant stage's table rings on this clock
(:class:`drivers.sim.world.SimulatedWorld`).

What it does not count: the operator's time (mounting), the solar simulator's warm-up and
waiting for its level, the host's time between captures; so it is a lower bound on a real lab's
time, which makes the simulated warm-up a slow one (the drift within a campaign is smaller than
in a real lab that waits for its lamp, never larger).
"""

from __future__ import annotations

import math
import threading

import numpy as np

from drivers.sim.smc100 import Smc100Config, trapezoid

__all__ = ["MOVES_KEPT", "LabClock"]

#: the moves a clock remembers, the oldest forgotten first (a table's ringing from a move this
#: many moves ago has long decayed: each move is followed by at least one frame)
MOVES_KEPT = 64


class LabClock:
    """Simulated seconds since the service's start, advanced by frames and moves.

    Parameters
    ----------
    velocity_deg_s, acceleration_deg_s2 : float
        The stage's speed and acceleration for the moves (the SMC100's defaults).

    Examples
    --------
    >>> clock = LabClock()
    >>> clock.frame_time_s(0.0, frame_rate_hz=5.0), clock.frame_time_s(0.0, frame_rate_hz=5.0)
    (0.0, 0.2)
    >>> round(clock.frame_time_s(40.0, frame_rate_hz=5.0), 3)  # 0.4 s + a 2.25 s move
    2.65
    """

    def __init__(self, velocity_deg_s: float = Smc100Config.velocity_deg_s,
                 acceleration_deg_s2: float = Smc100Config.acceleration_deg_s2) -> None:
        for name, value in (("velocity_deg_s", velocity_deg_s),
                            ("acceleration_deg_s2", acceleration_deg_s2)):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} = {value!r} must be finite and > 0")
        self.velocity_deg_s = float(velocity_deg_s)
        self.acceleration_deg_s2 = float(acceleration_deg_s2)
        self._now_s = 0.0
        self._angle_deg: float | None = None
        #: (end [s], direction +1 or -1) of the moves between two frames, oldest first
        self._moves: list[tuple[float, float]] = []
        self._lock = threading.Lock()

    @property
    def now_s(self) -> float:
        """Simulated seconds since the service's start."""
        return self._now_s

    def wait(self, seconds: float, turntable_angle_deg: float | None = None) -> None:
        """Let ``seconds`` pass with nothing captured (an operator waiting, a warm-up sequence's
        pause between captures, the turntable driver's wait after a move).

        ``turntable_angle_deg``: where the stage is now, when the wait follows a move (the
        driver's post-move wait): a move since the last frame then takes its time first, and
        ends before the wait does (its ringing decays during it).
        """
        if not (math.isfinite(seconds) and seconds >= 0.0):
            raise ValueError(f"seconds = {seconds!r} must be finite and >= 0")
        with self._lock:
            if turntable_angle_deg is not None:
                self._move_to(float(turntable_angle_deg))
            self._now_s += float(seconds)

    def _move_to(self, turntable_angle_deg: float) -> None:
        """The stage at ``turntable_angle_deg``: a move from the last angle seen takes its
        time, and its end and direction are kept (the lock held)."""
        if self._angle_deg is not None and self._angle_deg != turntable_angle_deg:
            self._now_s += self.move_duration_s(self._angle_deg, turntable_angle_deg)
            self._moves.append((self._now_s, math.copysign(
                1.0, turntable_angle_deg - self._angle_deg)))
            del self._moves[:-MOVES_KEPT]
        self._angle_deg = turntable_angle_deg

    def move_duration_s(self, from_deg: float, to_deg: float) -> float:
        """The stage's time for a rest-to-rest move [s] (0 for no move)."""
        if from_deg == to_deg:
            return 0.0
        last = trapezoid(from_deg, to_deg, self.velocity_deg_s, self.acceleration_deg_s2)[-1]
        return last.t0 + last.duration

    def frame_time_s(self, turntable_angle_deg: float, frame_rate_hz: float) -> float:
        """The time the next frame is exposed at, then one frame period later for the next.

        A turntable angle other than the last frame's means the stage moved in between: its
        move's time passes first.
        """
        if not (math.isfinite(frame_rate_hz) and frame_rate_hz > 0.0):
            raise ValueError(f"frame_rate_hz = {frame_rate_hz!r} must be finite and > 0")
        with self._lock:
            self._move_to(float(turntable_angle_deg))
            t = self._now_s
            self._now_s += 1.0 / frame_rate_hz
            return t

    def moves(self) -> tuple[np.ndarray, np.ndarray]:
        """The moves it saw between frames, oldest first: when each ended [s] and which way
        it went (+1, -1), for the table's ringing on this clock (:mod:`sim_core.settling`).

        >>> clock = LabClock()
        >>> for angle in (0.0, 10.0, 10.0, 4.0):
        ...     _ = clock.frame_time_s(angle, frame_rate_hz=5.0)
        >>> ends, signs = clock.moves()
        >>> ends.round(3).tolist(), signs.tolist()
        ([0.95, 1.9], [1.0, -1.0])
        """
        with self._lock:
            return (np.array([m[0] for m in self._moves], dtype=np.float64),
                    np.array([m[1] for m in self._moves], dtype=np.float64))
