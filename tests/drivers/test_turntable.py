"""The Turntable driver against the SMC100 simulator on a real pty: cycles, bad input, faults.

Every injected fault must end in a clear exception or a successful retry, within the test's
timeout, and a returned angle must always be the one the controller reports at the target.
"""

from __future__ import annotations

import dataclasses
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.errors import (
    DeviceDisconnectedError,
    DeviceError,
    DeviceInputError,
    DeviceTimeoutError,
    GarbledReplyError,
    LimitError,
    TurntableError,
)
from drivers.sim.pty_server import SimHandle, start_simulator
from drivers.turntable import Turntable, TurntableProtocol
from tests.drivers.helpers import FAST_SMC100

pytestmark = pytest.mark.timeout(15)


def make_turntable(handle: SimHandle, **kwargs: object) -> Turntable:
    """A driver with fast test settings for ``handle``'s port (connects on ``with``)."""
    options: dict[str, object] = {
        "settle_s": 0.0,
        "poll_interval_s": 0.005,
        "move_timeout_s": 5.0,
        "home_timeout_s": 5.0,
        "stall_timeout_s": 0.5,
        "settings": FAST_SMC100,
    }
    options.update(kwargs)
    return Turntable(handle.ports[0], **options)  # type: ignore[arg-type]


def test_full_home_move_verify_cycle_in_simulated_time():
    """Homing and moves go through HOMING and MOVING in (50x accelerated) simulated time."""
    with start_simulator("turntable", time_scale=50.0) as handle:
        sim = handle.models["turntable"]
        with make_turntable(handle, settle_s=0.02) as tt:
            assert isinstance(tt, TurntableProtocol)
            assert tt.status().state == "0A"
            for target in (30.0, -45.5, 0.0, 169.0):
                reached = tt.move_to(target)  # homes first: the controller is NOT REFERENCED
                assert reached == pytest.approx(target, abs=tt.tolerance_deg)
                assert sim.current_position() == pytest.approx(target, abs=1e-9)
                assert tt.status().state == "33"
            assert tt.setpoint_deg() == pytest.approx(169.0)
        seen = {line[3:] for line in handle.servers["turntable"].device.handle_line("1TS")}
        assert seen == {"000033"}


def test_home_when_already_referenced_sends_no_or(turntable_sim):
    sim = turntable_sim.models["turntable"]
    with make_turntable(turntable_sim) as tt:
        tt.home()
        assert tt.status().state == "32"
        tt.home()  # READY: nothing to do
        assert tt.last_error() == "@"
    assert sim.current_state() == "32"


def test_velocity_and_acceleration_round_trip(turntable_sim):
    with make_turntable(turntable_sim) as tt:
        tt.home()
        tt.set_velocity(12.5)
        tt.set_acceleration(40.0)
        assert (tt.velocity_deg_s(), tt.acceleration_deg_s2()) == (12.5, 40.0)
        with pytest.raises(TurntableError, match=r"TE reply 'C' after '1VA50\.0'"):
            tt.set_velocity(50.0)  # above the stage's maximum
        with pytest.raises(DeviceInputError, match=r"^velocity_deg_s: got -1"):
            tt.set_velocity(-1.0)


# -- bad input ---------------------------------------------------------------------------
@pytest.mark.parametrize("angle", [400.0, -170.5, 1e9])
def test_angle_outside_limits_raises_naming_field_range_and_units(turntable_sim, angle):
    sim = turntable_sim.models["turntable"]
    with make_turntable(turntable_sim) as tt:
        before = sim.commands_seen
        with pytest.raises(LimitError) as info:
            tt.move_to(angle)
        assert sim.commands_seen == before  # nothing was sent
    message = str(info.value)
    assert message.startswith("angle_deg: requested")
    assert "[-170, 170] deg" in message
    assert (info.value.low, info.value.high, info.value.unit) == (-170.0, 170.0, "deg")


def test_user_limits_narrow_the_controller_limits(turntable_sim):
    with make_turntable(turntable_sim, limits_deg=(-90.0, 200.0)) as tt:
        assert tt.limits_deg == (-90.0, 170.0)
        with pytest.raises(LimitError, match=r"\[-90, 170\] deg"):
            tt.move_to(-100.0)


@pytest.mark.parametrize("angle", [float("nan"), float("inf")])
def test_non_finite_angle_is_refused(turntable_sim, angle):
    with make_turntable(turntable_sim) as tt, pytest.raises(DeviceInputError, match="angle_deg"):
        tt.move_to(angle)


@pytest.mark.parametrize("address", [0, 32])
def test_address_outside_1_to_31_is_refused_before_opening_anything(address):
    with pytest.raises(DeviceInputError, match=r"^address: got \d+; .*1\.\.31"):
        Turntable("/dev/does-not-exist", address=address)


def test_other_address_gets_no_reply(turntable_sim):
    with pytest.raises(DeviceTimeoutError, match=r"no reply to '2TE'"):
        make_turntable(turntable_sim, address=2).connect()


# -- faults --------------------------------------------------------------------------------
def test_no_reply_ends_in_a_timeout_error_not_a_hang(turntable_sim):
    with make_turntable(turntable_sim) as tt:
        turntable_sim.servers["turntable"].inject("no-reply")
        start = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match=r"no reply to '1TS'.*3 attempts"):
            tt.move_to(10.0)
        assert time.monotonic() - start < 2.0


def test_single_dropped_reply_is_retried(turntable_sim):
    with make_turntable(turntable_sim) as tt:
        turntable_sim.servers["turntable"].inject("no-reply:1")
        assert tt.move_to(10.0) == pytest.approx(10.0)


@pytest.mark.parametrize("fault", ["garbled:1", "truncated:1", "garbled:2@3", "truncated:1@6"])
def test_occasional_bad_reply_is_retried_and_the_move_succeeds(turntable_sim, fault):
    with make_turntable(turntable_sim) as tt:
        turntable_sim.servers["turntable"].inject(fault)
        assert tt.move_to(-20.0) == pytest.approx(-20.0)
        assert turntable_sim.servers["turntable"].faults.fired


def test_persistently_garbled_replies_raise_a_garbled_reply_error(turntable_sim):
    with make_turntable(turntable_sim) as tt:
        turntable_sim.servers["turntable"].inject("garbled")
        with pytest.raises(GarbledReplyError, match="garbled reply to '1TS'"):
            tt.move_to(10.0)


def test_persistently_truncated_replies_raise_showing_the_partial_reply(turntable_sim):
    with make_turntable(turntable_sim) as tt:
        turntable_sim.servers["turntable"].inject("truncated")
        with pytest.raises(DeviceTimeoutError, match=r"partial reply b'1TS0'"):
            tt.move_to(10.0)


def test_stall_raises_naming_the_following_error_and_never_reports_the_target():
    with start_simulator("turntable", time_scale=50.0, faults=["stall:1"]) as handle:
        sim = handle.models["turntable"]
        with make_turntable(handle) as tt:
            tt.home()
            with pytest.raises(TurntableError) as info:
                tt.move_to(100.0)
            message = str(info.value)
            assert "DISABLE from MOVING" in message and "following error" in message
            assert info.value.state == "3D"
            assert 0.0 < sim.current_position() < 100.0
            tt.enable()  # MM1: back to READY from DISABLE
            assert tt.move_to(100.0) == pytest.approx(100.0)


def test_stall_without_error_is_detected_and_stopped():
    with start_simulator("turntable", time_scale=50.0, faults=["stall-hang:1"]) as handle:
        sim = handle.models["turntable"]
        with make_turntable(handle, stall_timeout_s=0.3) as tt:
            tt.home()
            with pytest.raises(TurntableError, match=r"stalled at .* deg .*stop \(ST\) sent"):
                tt.move_to(100.0)
            assert sim.current_state() == "33"  # the driver's ST ended the hung move
            assert sim.current_position() < 100.0


def test_move_timeout_stops_the_stage_and_raises():
    with (
        start_simulator("turntable", time_scale=1.0) as handle,
        make_turntable(handle, move_timeout_s=0.3, home_timeout_s=0.3) as tt,
    ):
        with pytest.raises(TurntableError, match=r"homing: not READY within 0\.3 s"):
            tt.home()  # 12.5 deg at 10 deg/s takes more than 0.3 s
        time.sleep(0.2)  # braking from 10 deg/s at 80 deg/s^2 takes 0.125 s
        assert handle.models["turntable"].current_state() == "0B"  # ST aborted the homing


def test_disconnect_during_a_move_reconnects_and_completes():
    with start_simulator("turntable", time_scale=20.0) as handle:
        server = handle.servers["turntable"]
        with make_turntable(handle) as tt:
            tt.home()
            server.faults.inject("disconnect:1@3", downtime_s=0.3)
            assert tt.move_to(60.0) == pytest.approx(60.0)
            assert server.disconnects == 1


def test_disconnect_longer_than_the_reconnect_timeout_raises():
    settings_ = dataclasses.replace(FAST_SMC100, reconnect_timeout_s=0.3)
    with start_simulator("turntable", instant=True) as handle:
        server = handle.servers["turntable"]
        with make_turntable(handle, settings=settings_) as tt:
            server.faults.inject("disconnect:1", downtime_s=5.0)
            with pytest.raises(DeviceDisconnectedError, match=r"not back within 0\.3 s"):
                tt.move_to(60.0)


@settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    target=st.floats(-170.0, 170.0, allow_nan=False),
    fault=st.sampled_from(["garbled", "truncated", "no-reply", None]),
    count=st.integers(1, 4),
    skip=st.integers(0, 8),
)
def test_a_returned_angle_is_always_the_target(turntable_sim, target, fault, count, skip):
    """Whatever link fault hits, ``move_to`` returns the target (within tolerance) or raises."""
    server = turntable_sim.servers["turntable"]
    server.faults.clear()
    if fault is not None:
        server.inject(f"{fault}:{count}@{skip}")
    tt = Turntable(
        turntable_sim.ports[0],
        settle_s=0.0,
        poll_interval_s=0.001,
        stall_timeout_s=None,
        settings=dataclasses.replace(FAST_SMC100, timeout_s=0.05),
    )
    try:
        tt.connect()
        reached = tt.move_to(target)
    except DeviceError:
        return  # a clear exception is an acceptable outcome; a wrong angle is not
    finally:
        tt.close()
        server.faults.clear()
    assert abs(reached - target) <= tt.tolerance_deg
    assert turntable_sim.models["turntable"].current_position() == pytest.approx(target, abs=1e-6)
