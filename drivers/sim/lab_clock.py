"""The simulated lab's clock: what time it is in the simulated world when a frame is exposed.

The simulated devices run on wall-clock time scaled or made instant (:class:`drivers.sim.
SimClock`), so the wall clock says nothing about how long the simulated lab has been running:
an instant rig takes a campaign of an hour in seconds. The world's slow processes (the
illumination's warm-up, :mod:`sim_core.warmup`) need the time a real lab would have spent:
:class:`LabClock` counts it from the service's start (the world's creation), advancing by one
frame period for every frame the camera exposes and by the stage's time for every move between
two frames (its trapezoidal profile at the SMC100's velocity and acceleration,
:func:`drivers.sim.smc100.trapezoid`).

What it does not count: the operator's time (mounting), the solar simulator's warm-up and
waiting for its level, the host's time between captures; so it is a lower bound on a real lab's
time, which makes the simulated warm-up a slow one (the drift within a campaign is smaller than
in a real lab that waits for its lamp, never larger).
"""

from __future__ import annotations

import math
import threading

from drivers.sim.smc100 import Smc100Config, trapezoid

__all__ = ["LabClock"]


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
        self._lock = threading.Lock()

    @property
    def now_s(self) -> float:
        """Simulated seconds since the service's start."""
        return self._now_s

    def wait(self, seconds: float) -> None:
        """Let ``seconds`` pass with nothing captured (an operator waiting, a warm-up sequence's
        pause between captures)."""
        if not (math.isfinite(seconds) and seconds >= 0.0):
            raise ValueError(f"seconds = {seconds!r} must be finite and >= 0")
        with self._lock:
            self._now_s += float(seconds)

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
            if self._angle_deg is not None:
                self._now_s += self.move_duration_s(self._angle_deg, turntable_angle_deg)
            self._angle_deg = float(turntable_angle_deg)
            t = self._now_s
            self._now_s += 1.0 / frame_rate_hz
            return t
