"""The simulated world renders a table that moves during a frame at each phase step's angle."""

from __future__ import annotations

import time

import numpy as np
import pytest

from drivers.rig import RigState
from drivers.sim.rig import SimulatedRigState, simulated_rig
from drivers.sim.usb_camera import CameraRequest
from sim_core.settling import settle_time_s
from sim_core.twin_file import RealityFile, TurntableParameters, TurntableSettling
from tests.drivers.test_world import UC, _world

pytestmark = pytest.mark.timeout(120)


def _moving_request(speed_deg_s: float, angle: float = 30.0) -> CameraRequest:
    state = SimulatedRigState(angle, 1.0, True,
                              table_angle_after_deg=lambda dt: angle + speed_deg_s * dt)
    return CameraRequest(UC, 0, seed=3, rig_state=state)


def test_a_turning_table_is_rendered_per_phase_step_and_a_still_one_once():
    world = _world()
    static = world(CameraRequest(UC, 0, seed=3, rig_state=RigState(30.0, 1.0, True)))
    still = world(_moving_request(0.01))  # 0.01 deg/s: 4.5e-5 deg in a frame
    assert world.last_rendered_per_step is False
    np.testing.assert_array_equal(still.phase_images, static.phase_images)
    turning = world(_moving_request(20.0))  # the stage's top speed: 0.09 deg in a frame
    assert world.last_rendered_per_step is True
    assert turning.meta["rig"]["turntable_angle_deg"] == 30.0  # the frame's start
    assert not np.array_equal(turning.phase_images, static.phase_images)


def test_frames_of_a_ringing_table_differ_until_it_has_settled():
    settling = TurntableSettling(amplitude_deg=1.0, frequency_hz=5.0, damping_ratio=0.3)
    world = _world(RealityFile(turntable=TurntableParameters(settling=settling)))
    scale = 20.0  # simulated seconds per wall second
    rendered: list[dict] = []  # what the world rendered, frame by frame (the wire drops it)

    def source(request: CameraRequest):
        frame = world(request)
        rendered.append({**frame.meta, "per_step": world.last_rendered_per_step})
        return frame

    with simulated_rig(frame_source=source, seed=3, turntable_instant=False, time_scale=scale,
                       turntable_settling=settling) as rig:
        rig.apply(RigState(5.0, 0.0, False))
        rig.capture(1)
        ringing = rendered[-1]
        assert ringing["per_step"] is True
        assert abs(ringing["rig"]["turntable_angle_deg"] - 5.0) > 1e-3
        # the controller saw none of it: on target, READY
        assert rig.turntable.position_deg() == pytest.approx(5.0, abs=1e-3)
        time.sleep(settle_time_s(settling, 1e-5) / scale + 0.05)
        rig.capture(1)
        settled = rendered[-1]
        assert settled["per_step"] is False
        assert settled["rig"]["turntable_angle_deg"] == pytest.approx(5.0, abs=1e-5)
