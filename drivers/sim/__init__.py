"""Byte-level simulators of the rig's serial devices, served on a pty or a loopback socket.

- :class:`~drivers.sim.smc100.Smc100Sim`: Newport SMC100CC controller with a rotation stage
  (homing, trapezoidal moves in simulated time, software limits, every controller state, ``TE``
  letters).
- :class:`~drivers.sim.oriel.LampSupplySim` (Oriel 69907-family arc-lamp supply) and
  :class:`~drivers.sim.oriel.ShutterControllerSim` (Oriel 68945 digital exposure controller),
  bundled as :class:`~drivers.sim.oriel.SolarRigSim`: two ports, one shared physical state.
- :mod:`drivers.sim.faults`: fault names and the injector (no reply, garbled, truncated,
  stall, disconnect, lamp fault, interlock).
- :mod:`drivers.sim.pty_server`: runs a simulator on a pseudo-terminal (``os.openpty``) or on
  TCP 127.0.0.1 for ``socket://`` URLs; :func:`~drivers.sim.pty_server.serve` is the CLI entry.

Every simulator works in *simulated time* from a :class:`SimClock`: ``time_scale`` runs it
faster than the wall clock, ``instant=True`` completes every motion, reboot and warm-up at once
(fast tests), and state is computed lazily from the clock whenever a command arrives.
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable


class SimClock:
    """Simulated time in seconds since construction.

    Parameters
    ----------
    time_scale : float
        Simulated seconds per wall-clock second (10 = ten times faster than real).
    instant : bool
        When true, :meth:`duration` returns 0: every timed process completes immediately.
    clock : callable
        Wall clock in seconds (``time.monotonic`` by default; tests may pass their own).
    """

    def __init__(
        self,
        time_scale: float = 1.0,
        instant: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not time_scale > 0:
            raise ValueError(f"time_scale must be > 0, got {time_scale!r}")
        self.time_scale = float(time_scale)
        self.instant = instant
        self._clock = clock
        self._t0 = clock()

    def now(self) -> float:
        """Simulated seconds elapsed."""
        return (self._clock() - self._t0) * self.time_scale

    def duration(self, seconds: float) -> float:
        """How long a process of nominal length ``seconds`` takes here (0 when instant)."""
        return 0.0 if self.instant else seconds


# Exports are loaded on first use, so that ``python -m drivers.sim.pty_server`` does not import
# the server module twice and the submodules can import SimClock from here.
_EXPORTS = {
    "FAULTS": "drivers.sim.faults",
    "FAULT_NAMES": "drivers.sim.faults",
    "SOLAR_FAULTS": "drivers.sim.faults",
    "TURNTABLE_FAULTS": "drivers.sim.faults",
    "FaultInjector": "drivers.sim.faults",
    "FaultSpec": "drivers.sim.faults",
    "parse_fault": "drivers.sim.faults",
    "LampSupplySim": "drivers.sim.oriel",
    "ShutterControllerSim": "drivers.sim.oriel",
    "SolarRigSim": "drivers.sim.oriel",
    "DeviceServer": "drivers.sim.pty_server",
    "SimHandle": "drivers.sim.pty_server",
    "serve": "drivers.sim.pty_server",
    "start_simulator": "drivers.sim.pty_server",
    "Smc100Sim": "drivers.sim.smc100",
}


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'drivers.sim' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


__all__ = ["SimClock", *_EXPORTS]
