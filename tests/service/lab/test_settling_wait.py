"""The service waits for the calibrated ringing to decay before it captures, unless a campaign
asks for motion; the simulated lab's frames then see a table at rest."""

from __future__ import annotations

import time

import pytest

from calibration.rig_settling import ringing_bound
from drivers.rig import RigState
from drivers.sim.rig import simulated_rig
from drivers.sim.usb_camera import CameraRequest
from service.lab.settling import SETTLE_TOLERANCE_DEG, settle_wait_s, settled_moves
from sim_core.settling import envelope_deg
from sim_core.twin_file import (
    CalibrationFile,
    RealityFile,
    TurntableParameters,
    TurntableSettling,
)
from tests.drivers.test_world import _world

pytestmark = pytest.mark.timeout(60)

SETTLING = TurntableSettling(amplitude_deg=1.0, frequency_hz=5.0, damping_ratio=0.3)
CALIBRATION = CalibrationFile(turntable=TurntableParameters(settling=SETTLING))


def test_the_wait_is_until_the_envelope_s_bound_is_below_the_tolerance():
    """The calibrated amplitude is the fit's at its first frame; the wait outlasts the larger
    one a move end half a damped period earlier would have (:func:`ringing_bound`)."""
    wait = settle_wait_s(CALIBRATION)
    bound = ringing_bound(SETTLING)
    assert bound.amplitude_deg > SETTLING.amplitude_deg
    assert float(envelope_deg(bound, wait)) == pytest.approx(SETTLE_TOLERANCE_DEG)
    assert float(envelope_deg(SETTLING, wait)) < SETTLE_TOLERANCE_DEG
    assert settle_wait_s(None) == 0.0
    assert settle_wait_s(CalibrationFile()) == 0.0


def test_a_table_seen_ringing_but_not_known_rests_after_every_move():
    """``turntable.rest_after_move_s`` (a calibration that saw the table ring without learning
    how): every move rests that long, the longer of it and a known ringing's wait."""
    rest = CalibrationFile(turntable=TurntableParameters(rest_after_move_s=120.0))
    assert settle_wait_s(rest) == 120.0
    both = CalibrationFile(turntable=TurntableParameters(settling=SETTLING,
                                                         rest_after_move_s=0.5))
    assert settle_wait_s(both) == settle_wait_s(CALIBRATION) > 0.5
    with simulated_rig(seed=1, turntable_instant=False, time_scale=1000.0) as rig:
        with settled_moves(rig, rest) as wait:
            assert wait == rig.turntable.settle_s == 120.0
            t0 = time.perf_counter()
            rig.apply(RigState(5.0, 0.0, False))
            elapsed = time.perf_counter() - t0
        assert rig.turntable.settle_s < 1.0  # the driver's own wait again
    assert elapsed >= 120.0 / 1000.0  # the rest passed on the stage's clock


def test_moves_wait_for_the_settling_only_inside_and_not_when_motion_is_asked_for():
    with simulated_rig(seed=1) as rig:
        base = rig.turntable.settle_s
        with settled_moves(rig, CALIBRATION) as wait:
            assert wait == rig.turntable.settle_s == pytest.approx(settle_wait_s(CALIBRATION))
            t0 = time.perf_counter()
            rig.apply(RigState(10.0, 0.0, False))
            # an instant clock's table has settled at once: the wait costs no wall time
            assert time.perf_counter() - t0 < 0.5 * wait
        assert rig.turntable.settle_s == base  # restored
        with settled_moves(rig, CALIBRATION, motion=True) as wait:
            assert wait == base == rig.turntable.settle_s
        with settled_moves(rig, None):
            assert rig.turntable.settle_s == base  # never lowered, never raised for nothing


def test_the_wait_is_spent_on_the_simulated_stage_s_clock():
    with (simulated_rig(seed=1, turntable_instant=False, time_scale=4.0) as rig,
          settled_moves(rig, CALIBRATION) as wait):
        t0 = time.perf_counter()
        rig.turntable.sleep(wait)  # what a move ends with
        elapsed = time.perf_counter() - t0
    assert wait / 4.0 <= elapsed < wait  # simulated seconds at four times the wall's pace


def test_a_capture_after_a_settled_move_sees_the_table_at_rest():
    world = _world(RealityFile(turntable=TurntableParameters(settling=SETTLING)))
    at_rest: list[bool] = []

    def source(request: CameraRequest):
        frame = world(request)
        at_rest.append(not world.last_rendered_per_step)
        return frame

    with simulated_rig(frame_source=source, seed=3, turntable_instant=False,
                       time_scale=4.0, turntable_settling=SETTLING) as rig:
        rig.apply(RigState(2.0, 0.0, False))
        rig.capture(1)  # no wait: the table still rings
        with settled_moves(rig, CALIBRATION):
            rig.apply(RigState(4.0, 0.0, False))
            rig.capture(1)
    assert at_rest == [False, True]
