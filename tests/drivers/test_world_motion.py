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
    # lightly damped and a slow clock: the frame after the move lands in the ringing (above
    # 1e-3 deg for 1.1 s of wall time) even on a loaded machine; settled after 1.8 s
    settling = TurntableSettling(amplitude_deg=1.0, frequency_hz=5.0, damping_ratio=0.05)
    world = _world(RealityFile(turntable=TurntableParameters(settling=settling)))
    scale = 4.0  # simulated seconds per wall second
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


def test_an_instant_stage_rings_on_the_lab_clock_until_a_wait_has_settled_it():
    """A world that rings on the lab's clock (an instant stage): a frame right after a move is
    rendered per phase step and stamped with the lab's time, the frame period after the last;
    after a wait on that clock the table is at rest (one render); a stage that rings on its own
    clock is left to it."""
    settling = TurntableSettling(amplitude_deg=0.5, frequency_hz=3.0, damping_ratio=0.1)
    reality = RealityFile(turntable=TurntableParameters(settling=settling))
    world = _world(reality)
    world.rings_on_lab_clock = True

    def frame(index: int, angle: float, **state):
        return world(CameraRequest(UC, index, seed=3, timestamp_s=1.0,
                                   rig_state=SimulatedRigState(angle, 0.0, False, **state)))

    first = frame(0, 0.0)
    assert world.last_rendered_per_step is False
    moved = frame(1, 20.0)  # the move's end is this frame's start: the full amplitude
    assert world.last_rendered_per_step is True
    ends_s, signs = world.clock.moves()
    assert signs.tolist() == [1.0]
    assert moved.timestamp_s - world._epoch_s == pytest.approx(ends_s[0], abs=1e-6)
    assert moved.timestamp_s - first.timestamp_s == pytest.approx(
        1.0 / UC.frame_rate_hz + world.clock.move_duration_s(0.0, 20.0))
    # a stage with a ringing of its own: the world adds none
    frame(2, 20.0, stage_rings=True)
    assert world.last_rendered_per_step is False
    world.clock.wait(settle_time_s(settling, 1e-4), turntable_angle_deg=20.0)
    frame(3, 20.0)
    assert world.last_rendered_per_step is False  # below 1e-3 deg: at rest, one render
    # a move registered by a wait ends before the wait does
    world.clock.wait(0.5, turntable_angle_deg=-10.0)
    assert world.clock.moves()[0][-1] == pytest.approx(world.clock.now_s - 0.5)
    frame(4, -10.0)
    assert world.last_rendered_per_step is True  # 0.5 s after the move: still ringing
