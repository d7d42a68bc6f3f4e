"""The simulated stage's table rings after a move; its controller (encoder on the motor) does not
see it: TP, TS and the set-point are those of a stage without settling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.sim import SimClock
from drivers.sim.faults import FaultInjector
from drivers.sim.smc100 import Smc100Config, Smc100Sim
from sim_core.settling import ringing_deg
from sim_core.twin_file import TurntableSettling
from tests.drivers.test_smc100_sim import StepClock, ask, home, make_homed_sim

pytestmark = pytest.mark.timeout(10)

SETTLING = TurntableSettling(amplitude_deg=0.3, frequency_hz=2.0, damping_ratio=0.1)


def _move_duration_s(sim: Smc100Sim, distance_deg: float) -> float:
    return float(ask(sim, f"1PT{distance_deg}")[3:])


def test_the_table_rings_after_a_move_along_the_damped_oscillation():
    sim, wall = make_homed_sim(settling=SETTLING)
    wall.t += 1000.0  # the homing's ringing has decayed
    t_start = sim.clock.now()
    duration_s = _move_duration_s(sim, 40.0)
    ask(sim, "1PA40")
    for after_s in (0.0, 0.1, 0.37, 1.2):
        wall.t = t_start + duration_s + after_s
        expected = 40.0 + float(ringing_deg(SETTLING, after_s))
        assert sim.table_angle_deg() == pytest.approx(expected, abs=1e-9)
    # a move in the negative direction swings the other way
    wall.t += 1000.0
    t_start = sim.clock.now()
    duration_s = _move_duration_s(sim, 30.0)
    ask(sim, "1PA10")
    wall.t = t_start + duration_s + 0.05
    assert sim.table_angle_deg() - 10.0 == pytest.approx(-float(ringing_deg(SETTLING, 0.05)))


def test_the_controller_does_not_see_the_ringing():
    ringing, wall = make_homed_sim(settling=SETTLING)
    still, wall_still = make_homed_sim()
    for sim, clock in ((ringing, wall), (still, wall_still)):
        clock.t += 1000.0
        ask(sim, "1PA25")
        clock.t += _move_duration_s(sim, 25.0) + 0.05
    replies = [(ask(s, "1TP"), ask(s, "1TS"), ask(s, "1TH")) for s in (ringing, still)]
    assert replies[0] == replies[1] == ("1TP25", "1TS000033", "1TH25")
    assert abs(ringing.table_angle_deg() - 25.0) > 0.1  # while the table is 0.1+ deg off
    assert still.table_angle_deg() == 25.0


def test_the_table_angle_ahead_of_now_follows_the_profile_then_the_ringing():
    sim, wall = make_homed_sim(settling=SETTLING)
    wall.t += 1000.0
    t_start = sim.clock.now()
    duration_s = _move_duration_s(sim, 20.0)
    ask(sim, "1PA20")
    wall.t = t_start + 0.5 * duration_s
    mid = sim.table_angle_deg()
    assert 0.0 < mid < 20.0 and mid == sim.current_position()  # moving: no ringing yet
    ahead = [sim.table_angle_deg(t_start + duration_s + dt) for dt in (0.0, 0.2)]
    np.testing.assert_allclose(ahead, 20.0 + ringing_deg(SETTLING, np.array([0.0, 0.2])))
    wall.t = t_start + duration_s + 0.2  # and now that time has come, the same
    assert sim.table_angle_deg() == pytest.approx(ahead[1], abs=1e-12)


def test_ringings_of_successive_moves_add_and_decay():
    sim, wall = make_homed_sim(settling=SETTLING)
    wall.t += 1000.0
    ends = []
    for target in (5.0, 10.0):
        ask(sim, f"1PA{target}")
        wall.t += _move_duration_s(sim, 5.0)
        ends.append(sim.clock.now())
        sim.current_position()  # the controller notices the end of the move
    wall.t += 0.3
    expected = 10.0 + sum(float(ringing_deg(SETTLING, sim.clock.now() - e)) for e in ends)
    assert sim.table_angle_deg() == pytest.approx(expected, abs=1e-9)
    wall.t += 1000.0
    assert sim.table_angle_deg() == 10.0


def test_without_settling_or_with_an_instant_clock_the_table_stops_dead():
    instant = Smc100Sim(Smc100Config(settling=SETTLING), clock=SimClock(instant=True))
    ask(instant, "1OR")
    ask(instant, "1PA12")
    assert instant.table_angle_deg() == 12.0
    sim, wall = make_homed_sim()
    ask(sim, "1PA12")
    wall.t += _move_duration_s(sim, 12.0)
    assert sim.table_angle_deg() == 12.0


def test_a_stalled_move_does_not_ring():
    wall = StepClock()
    sim = Smc100Sim(Smc100Config(settling=SETTLING), clock=SimClock(clock=wall),
                    faults=FaultInjector(["stall:1"]))
    home(sim, wall)
    wall.t += 1000.0
    ask(sim, "1PA30")
    wall.t += 100.0
    assert ask(sim, "1TS") == "1TS00203D"  # following error, DISABLE
    assert math.isclose(sim.table_angle_deg(), sim.current_position())


def test_the_simulated_rig_gives_the_camera_the_physical_angle_and_its_motion_ahead():
    from drivers.rig import RigState
    from drivers.sim.rig import SimulatedRigState, simulated_rig

    with simulated_rig(turntable_instant=False, time_scale=4.0,
                       turntable_settling=SETTLING) as rig:
        rig.apply(RigState(3.0, 0.0, False))
        provider = rig.sims["camera"].device.state_provider
        state = provider()
        assert isinstance(state, SimulatedRigState)
        reported = rig.turntable.position_deg()
        assert reported == pytest.approx(3.0, abs=1e-3)  # the controller: on target
        # the table still rings (4x faster than real: the move ended < 0.3 simulated s ago)
        assert abs(state.turntable_angle_deg - 3.0) > 1e-3
        after = [state.table_angle_after_deg(dt) for dt in (0.0, 0.125, 0.25)]
        assert after[0] == pytest.approx(state.turntable_angle_deg, abs=1e-12)
        assert len(set(after)) == 3  # it moves within a frame's time
