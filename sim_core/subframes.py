"""When each raw sub-frame of a frame is exposed, and whether the scene moved in between.

A pico flexx frame is a sequence of raw sub-frames (issue 27; ``drivers.camera.wire.UseCase``):
a grey one, then four phase steps per modulation frequency in the use case's order (5 for
``MODE_5_*``: grey + 4 at 60.24 MHz; 9 for ``MODE_9_*``: grey + 4 at 80.32 + 4 at 60.24 MHz).
Sub-frame ``k`` is exposed at

    t_k = t0 + k (exposure + readout)

(CamSim's timing, ``marlam/camsim`` ``libcamsim/simulator.cpp``; WurblPT uses the same), so
anything that moves during a frame is seen at another place by each phase step and smears
across the phases: the four-step demodulation (seed eq. 4) then mixes the phases of different
surfaces at an edge. The readout time per sub-frame is not in pmd's use-case table; CamSim's PMD
example uses 1 ms (:data:`READOUT_S`). The simulator's grey image is the phase steps' tap sum
(:func:`sim_core.sensor.expose`), so the grey sub-frame's slot only delays the phase steps.

A frame is rendered once per phase step only when the scene moves by more than
:data:`MOTION_TOLERANCE_DEG` during it (:func:`moves_during_frame`): "simulate only the effects a
scene calls for".
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from sim_core.errors import InvalidInputError

__all__ = [
    "MOTION_TOLERANCE_DEG",
    "N_PHASE_STEPS",
    "READOUT_S",
    "moves_during_frame",
    "phase_step_angles_deg",
    "phase_step_times_s",
    "subframe_times_s",
]

#: readout time of one raw sub-frame [s] (CamSim's PMD example; not in pmd's use-case table)
READOUT_S = 1e-3
#: phase steps per modulation frequency (seed eq. 3)
N_PHASE_STEPS = 4
#: a turn during a frame above which each phase step is rendered at its own angle [deg]: at
#: 0.15 m from the axis 1e-3 deg is 2.6 um, far below any depth noise the camera has
MOTION_TOLERANCE_DEG = 1e-3


def subframe_times_s(n_frequencies: int, exposure_s: float,
                     readout_s: float = READOUT_S) -> np.ndarray:
    """Start of every raw sub-frame after the frame's start, ``k (exposure + readout)`` [s].

    Returns ``(1 + 4 n_f,)`` float64: the grey sub-frame first, then the phase steps of each
    frequency in the use case's order.

    >>> subframe_times_s(1, 500e-6).round(9).tolist()
    [0.0, 0.0015, 0.003, 0.0045, 0.006]
    """
    if not (isinstance(n_frequencies, int) and 1 <= n_frequencies <= 4):
        raise InvalidInputError("n_frequencies", f"got {n_frequencies!r}; allowed: 1..4")
    for name, value in (("exposure_s", exposure_s), ("readout_s", readout_s)):
        if not (math.isfinite(value) and 0.0 <= value <= 1.0):
            raise InvalidInputError(name, f"got {value!r}; allowed: 0..1 s")
    k = np.arange(1 + N_PHASE_STEPS * n_frequencies, dtype=np.float64)
    return k * (exposure_s + readout_s)


def phase_step_times_s(n_frequencies: int, exposure_s: float,
                       readout_s: float = READOUT_S) -> np.ndarray:
    """Start of each phase step after the frame's start, ``(n_f, 4)`` [s] (the grey sub-frame
    left out).

    >>> phase_step_times_s(2, 1e-3).shape
    (2, 4)
    """
    times = subframe_times_s(n_frequencies, exposure_s, readout_s)
    return times[1:].reshape(n_frequencies, N_PHASE_STEPS)


def phase_step_angles_deg(angle_after_deg: Callable[[float], float], n_frequencies: int,
                          exposure_s: float, readout_s: float = READOUT_S) -> np.ndarray:
    """The turntable's angle at each phase step, ``(n_f, 4)`` [deg].

    ``angle_after_deg(dt_s)`` is the table's angle ``dt_s`` seconds after the frame's start (the
    simulated stage's physical angle, or the twin's model of the rig's motion).

    >>> phase_step_angles_deg(lambda dt: 10.0 + 20.0 * dt, 1, 500e-6).round(3).tolist()
    [[10.03, 10.06, 10.09, 10.12]]
    """
    times = phase_step_times_s(n_frequencies, exposure_s, readout_s)
    return np.array([[float(angle_after_deg(float(t))) for t in row] for row in times])


def moves_during_frame(angles_deg: np.ndarray,
                       tolerance_deg: float = MOTION_TOLERANCE_DEG) -> bool:
    """Whether the phase steps see angles more than ``tolerance_deg`` apart.

    >>> moves_during_frame(np.array([[10.0, 10.0005, 10.0009, 10.0]]))
    False
    >>> moves_during_frame(np.array([[10.0, 10.01, 10.02, 10.03]]))
    True
    """
    a = np.asarray(angles_deg, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise InvalidInputError("angles_deg", "every phase step's angle must be finite")
    return bool(np.ptp(a) > tolerance_deg)
