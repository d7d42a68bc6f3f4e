"""Capture while turning (issue 27): one sweep through a campaign's poses without stopping.

The table is brought (settled) to a lead-in angle before the first pose, set to the campaign's
speed and sent to a lead-out angle past the last; as it passes each pose's angle one frame is
captured. The angle recorded with a frame is the table's angle at the frame's start: the
controller's position read just before the capture, advanced at the speed to the frame's
timestamp (the camera stamps a frame when it starts it). The twin then simulates each frame with
its sub-frames at their times (``Measurement.turning_deg_s``). Afterwards the stage's speed is
restored.

:func:`stop_and_go_s` and :func:`turning_s` give the time a pose takes either way from the
stage's motion profile, the settling wait and the frame time, so that a campaign report can
compare poses per minute on the real rig (the simulated lab's wall time is its renderer's).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

from drivers.errors import TurntableError
from drivers.rig import Rig, RigState
from service.lab.poses import Measurement, PosePlan, store_measurement
from service.lab.settling import settle_wait_s, settled_moves
from service.store.frame_files import FrameStore
from sim_core.errors import InvalidInputError

__all__ = ["LEAD_MARGIN_DEG", "capture_turning", "lead_deg", "stop_and_go_s", "turning_s"]

#: extra turn before the first pose and after the last, beyond the stage's run-up [deg]
LEAD_MARGIN_DEG = 0.5
#: period of the position polls while waiting for the next pose's angle [s]
POLL_S = 0.002


def lead_deg(speed_deg_s: float, acceleration_deg_s2: float) -> float:
    """The turn the stage needs to reach ``speed`` from rest (``v^2 / 2a``), doubled, plus
    :data:`LEAD_MARGIN_DEG` [deg].

    >>> lead_deg(10.0, 80.0)
    1.75
    """
    if not (math.isfinite(acceleration_deg_s2) and acceleration_deg_s2 > 0.0):
        raise InvalidInputError("acceleration_deg_s2",
                                f"got {acceleration_deg_s2!r}; allowed: a finite value > 0")
    return speed_deg_s**2 / acceleration_deg_s2 + LEAD_MARGIN_DEG


def _move_s(distance_deg: float, v_max: float, a_max: float) -> float:
    """Duration of a rest-to-rest trapezoid (triangle when short) over ``distance_deg``."""
    d = abs(distance_deg)
    if d * a_max >= v_max * v_max:  # reaches v_max: accelerate, cruise, decelerate
        return d / v_max + v_max / a_max
    return 2.0 * math.sqrt(d / a_max)


def stop_and_go_s(angles_deg: Sequence[float], v_max: float, a_max: float, settle_s: float,
                  frame_s: float) -> float:
    """Seconds for the poses stop and go: each move, the settling wait, one frame.

    >>> round(stop_and_go_s([0.0, 10.0], 20.0, 80.0, 1.0, 0.02), 3)
    2.79
    """
    moves = sum(_move_s(b - a, v_max, a_max) for a, b in itertools.pairwise(angles_deg))
    return moves + len(angles_deg) * (settle_s + frame_s)


def turning_s(angles_deg: Sequence[float], speed_deg_s: float, a_max: float,
              frame_s: float) -> float:
    """Seconds for the poses in one sweep at ``speed``: run-up, the turn from the first pose's
    angle to the last, the last frame.

    >>> turning_s([0.0, 10.0], 10.0, 80.0, 0.02)
    1.195
    """
    span = abs(angles_deg[-1] - angles_deg[0])
    return lead_deg(speed_deg_s, a_max) / speed_deg_s + span / speed_deg_s + frame_s


def _wait_past(rig: Rig, angle_deg: float, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while rig.turntable.position_deg() < angle_deg:
        if time.monotonic() > deadline:
            raise TurntableError(f"capture while turning: the table did not reach "
                                 f"{angle_deg:g} deg within {timeout_s:g} s")
        time.sleep(POLL_S)


def capture_turning(
    rig: Rig, store: FrameStore, plans: Sequence[PosePlan], speed_deg_s: float,
    stop: Callable[[], bool], current: Callable[[PosePlan], None],
) -> list[tuple[PosePlan, Measurement]]:
    """One sweep at ``speed_deg_s`` through ``plans`` (sorted by angle, increasing): a frame
    stored per pose as the table passes it. Stops before the next pose when ``stop()``.

    The first move waits for the calibrated settling (the sweep starts from rest); the sweep
    itself does not (the campaign asked for motion). Device faults propagate, the stage stopped.
    """
    plans = sorted(plans, key=lambda p: p.turntable_deg)
    tt: Any = rig.turntable
    low, high = tt.limits_deg
    lead = lead_deg(speed_deg_s, tt.acceleration_deg_s2())
    start, end = plans[0].turntable_deg - lead, plans[-1].turntable_deg + lead
    if start < low or end > high:
        raise InvalidInputError(
            "turning_deg_s", f"the sweep needs {start:g} to {end:g} deg ({lead:g} deg of run-up "
            f"at {speed_deg_s:g} deg/s each side); the stage allows {low:g} to {high:g} deg")
    first = plans[0]
    done: list[tuple[PosePlan, Measurement]] = []
    with rig.hold():
        with settled_moves(rig, first.twin.calibration):
            rig.apply(RigState(start, first.solar_suns, first.target.shutter_open))
        base_speed = tt.velocity_deg_s()
        tt.set_velocity(speed_deg_s)
        try:
            tt.start_move(end)
            span_s = (end - start) / speed_deg_s + 10.0
            for plan in plans:
                if stop():
                    break
                current(plan)
                t0 = time.perf_counter()
                _wait_past(rig, plan.turntable_deg, span_s)
                t_read = time.time()
                read_deg = tt.position_deg()
                t1 = time.perf_counter()
                raws = rig.capture(1)  # no target: the table is meant to move
                angle = read_deg + speed_deg_s * (raws[0].timestamp_s - t_read)
                state = RigState(angle, plan.solar_suns, plan.target.shutter_open)
                m = store_measurement(store, plan, state, raws, rig.camera.use_case, t0, t1,
                                      turning_deg_s=speed_deg_s)
                done.append((plan, m))
        except BaseException:
            tt.stop()
            raise
        finally:
            with settled_moves(rig, None, motion=True):
                tt.move_to(end)  # waits for READY (the sweep's end)
            tt.set_velocity(base_speed)
    return done


def turning_figures(angles_deg: Sequence[float], speed_deg_s: float, rig: Rig,
                    calibration: Any, frame_rate_hz: float) -> dict[str, float]:
    """Poses per minute of the sweep against stop and go, on the stage's own motion profile
    (its programmed speed and acceleration, the calibrated settling, one frame per pose)."""
    tt: Any = rig.turntable
    a_max, v_max = tt.acceleration_deg_s2(), tt.velocity_deg_s()
    frame_s = 1.0 / frame_rate_hz
    angles = sorted(angles_deg)
    go = stop_and_go_s(angles, v_max, a_max, max(settle_wait_s(calibration),
                                                 getattr(tt, "settle_s", 0.0)), frame_s)
    turn = turning_s(angles, speed_deg_s, a_max, frame_s)
    n = len(angles)
    return {"turning_deg_s": speed_deg_s, "poses": n,
            "turning_poses_per_min": 60.0 * n / turn, "stop_and_go_poses_per_min": 60.0 * n / go,
            "turning_s": turn, "stop_and_go_s": go,
            "settle_wait_s": settle_wait_s(calibration)}
