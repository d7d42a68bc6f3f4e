"""The SolarSimulator driver against the Oriel simulators on real ptys: levels, warm-up, faults."""

from __future__ import annotations

import time

import pytest

from drivers.errors import (
    DeviceTimeoutError,
    GarbledReplyError,
    InterlockError,
    LampFaultError,
    SolarSimulatorError,
)
from drivers.sim.pty_server import start_simulator
from drivers.solar_simulator import SolarSimulatorProtocol, SunsCalibration
from tests.drivers.helpers import fast_solar

pytestmark = pytest.mark.timeout(15)


def test_power_set_and_read_back(solar_sim):
    with fast_solar(*solar_sim.ports) as solar:
        assert isinstance(solar, SolarSimulatorProtocol)
        solar.lamp_on()
        solar.set_power_w(380.0)
        assert solar.power_preset_w() == 380.0
        assert solar.wait_until_stable(timeout_s=2.0) == pytest.approx(380.0, abs=2.0)
        assert solar.read_power_w() == pytest.approx(380.0, abs=2.0)
        assert solar.read_current_a() * solar.read_voltage_v() == pytest.approx(380.0, rel=0.01)


@pytest.mark.parametrize("suns", [0.8, 0.95, 1.0, 1.2])
def test_suns_level_set_and_read_back(solar_sim, suns):
    with fast_solar(*solar_sim.ports) as solar:
        solar.lamp_on()
        solar.set_suns(suns)
        solar.wait_until_stable(timeout_s=2.0)
        assert solar.read_suns() == pytest.approx(suns, abs=0.005)  # 1 W preset resolution
        solar.open_shutter()
        assert solar_sim.models["rig"].irradiance_suns() == pytest.approx(suns, abs=0.005)


def test_read_suns_is_zero_with_the_lamp_off(solar_sim):
    with fast_solar(*solar_sim.ports) as solar:
        assert not solar.is_lamp_on()
        assert solar.read_suns() == 0.0
        solar.lamp_on()
        solar.lamp_off()
        assert solar.read_suns() == 0.0


def test_shutter_open_close_and_irradiance(solar_sim):
    rig = solar_sim.models["rig"]
    with fast_solar(*solar_sim.ports) as solar:
        solar.lamp_on()
        solar.set_suns(1.0)
        assert rig.irradiance_suns() == 0.0  # shutter closed
        solar.open_shutter()
        assert solar.shutter_is_open() and solar.status().shutter_open
        assert rig.irradiance_suns() == pytest.approx(1.0)
        solar.close_shutter()
        assert not solar.shutter_is_open()
        assert rig.irradiance_suns() == 0.0


def test_lamp_hours_accumulate_in_simulated_time():
    with (
        start_simulator("solar-simulator", time_scale=36000.0) as handle,  # 0.1 s = 1 h
        fast_solar(*handle.ports) as solar,
    ):
        hours = solar.lamp_hours()
        solar.lamp_on()
        time.sleep(0.25)
        assert solar.lamp_hours() >= hours + 2


def test_warm_up_is_waited_for_and_reported():
    """tau = 360 s simulated = 0.18 s real at 2000x: power climbs from 85 % to the preset."""
    with (
        start_simulator("solar-simulator", time_scale=2000.0) as handle,
        fast_solar(*handle.ports, warmup_s=0.5, power_tolerance_w=1.0) as solar,
    ):
        solar.set_power_w(400.0)
        solar.lamp_on()
        assert solar.read_power_w() < 390.0  # cold lamp
        assert not solar.is_stable()
        assert solar.warmup_remaining_s() > 0
        with pytest.raises(SolarSimulatorError, match=r"not stable within 0\.1 s.*warm-up"):
            solar.wait_until_stable(timeout_s=0.1)
        assert solar.wait_until_stable(timeout_s=3.0) == pytest.approx(400.0, abs=1.0)
        assert solar.is_stable()


def test_wait_until_stable_with_the_lamp_off_raises(solar_sim):
    with (
        fast_solar(*solar_sim.ports) as solar,
        pytest.raises(SolarSimulatorError, match="lamp is off"),
    ):
        solar.wait_until_stable(timeout_s=1.0)


def test_custom_calibration_table_is_used(solar_sim, tmp_path):
    path = tmp_path / "lab.yaml"
    path.write_text("suns: [0.8, 1.2]\npower_w: [300, 460]\n")
    with fast_solar(*solar_sim.ports, calibration=path) as solar:
        solar.set_suns(1.0)
        assert solar.power_preset_w() == 380.0
        assert isinstance(solar.calibration, SunsCalibration)


def test_calibration_needing_more_than_p_lim_is_refused_at_connect(solar_sim, tmp_path):
    path = tmp_path / "hot.yaml"
    path.write_text("suns: [0.8, 1.2]\npower_w: [400, 600]\n")
    with pytest.raises(Exception, match=r"calibration\.power_w: 600 W needed .*P-LIM 500 W"):
        fast_solar(*solar_sim.ports, calibration=path).connect()


# -- faults ----------------------------------------------------------------------------------
def test_interlock_fault_refuses_the_lamp():
    with (
        start_simulator("solar-simulator", instant=True, faults=["interlock"]) as handle,
        fast_solar(*handle.ports) as solar,
    ):
        with pytest.raises(InterlockError, match=r"interlock open \(STB 0x21"):
            solar.lamp_on()
        assert not handle.models["lamp"].lamp_on


@pytest.mark.parametrize(
    ("fault", "error", "match", "timeout_s"),
    [
        ("interlock", InterlockError, "interlock open", 1.0),
        ("lamp-fault:1@2", LampFaultError, "fault", 2.0),
    ],
)
def test_a_fault_while_lit_is_raised_by_the_stability_wait(
    solar_sim, fault, error, match, timeout_s
):
    with fast_solar(*solar_sim.ports) as solar:
        solar.lamp_on()
        solar_sim.servers["lamp"].inject(fault)
        with pytest.raises(error, match=match):
            solar.wait_until_stable(timeout_s=timeout_s)
        assert not solar_sim.models["lamp"].lamp_on


def test_lamp_fault_is_raised_and_a_restart_recovers(solar_sim):
    with fast_solar(*solar_sim.ports) as solar:
        solar_sim.servers["lamp"].inject("lamp-fault:1")
        with pytest.raises(LampFaultError, match=r"lamp fault after START: STB 0x28 \(.*fault"):
            solar.lamp_on()
        solar.lamp_off()
        solar.lamp_on()  # the fault was a single event
        assert solar.wait_until_stable(timeout_s=2.0) > 0


@pytest.mark.parametrize("device", ["lamp", "shutter"])
def test_no_reply_ends_in_a_timeout_error(solar_sim, device):
    with fast_solar(*solar_sim.ports) as solar:
        solar_sim.servers[device].inject("no-reply")
        start = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match="no reply"):
            solar.open_shutter() if device == "shutter" else solar.set_power_w(350.0)
        assert time.monotonic() - start < 2.0


@pytest.mark.parametrize("fault", ["garbled:1", "truncated:1", "no-reply:1", "garbled:2@1"])
def test_occasional_bad_reply_is_retried(solar_sim, fault):
    with fast_solar(*solar_sim.ports) as solar:
        solar_sim.servers["lamp"].inject(fault)
        solar_sim.servers["shutter"].inject(fault)
        solar.lamp_on()
        solar.set_suns(1.0)
        solar.open_shutter()
        assert solar.shutter_is_open()
        assert solar.wait_until_stable(timeout_s=2.0) == pytest.approx(400.0, abs=2.0)


def test_persistently_garbled_replies_raise(solar_sim):
    with fast_solar(*solar_sim.ports) as solar:
        solar_sim.servers["lamp"].inject("garbled")
        with pytest.raises(GarbledReplyError, match="garbled reply to 'STB\\?'"):
            solar.lamp_on()


def test_disconnect_and_reconnect_of_the_lamp_port(solar_sim):
    with fast_solar(*solar_sim.ports) as solar:
        server = solar_sim.servers["lamp"]
        server.faults.inject("disconnect:1", downtime_s=0.3)
        solar.lamp_on()
        solar.set_power_w(410.0)
        assert solar.power_preset_w() == 410.0
        assert server.disconnects == 1


def test_shutter_close_fault_closes_an_open_shutter_by_itself(solar_sim):
    with fast_solar(*solar_sim.ports) as solar:
        solar.open_shutter()
        solar_sim.servers["shutter"].inject("shutter-close:1")
        assert not solar.shutter_is_open()  # closed before the query was answered
        assert not solar_sim.models["shutter"].is_open
        solar.open_shutter()
        assert solar.shutter_is_open()


def test_an_interlock_that_put_the_lamp_out_stays_on_the_status_until_relit(solar_sim):
    """A short interlock opening (one command) latches the STB interlock bit: a lamp found out
    afterwards is reported as put out by the interlock, not as merely off."""
    with fast_solar(*solar_sim.ports) as solar:
        solar.lamp_on()
        solar_sim.servers["lamp"].inject("interlock:1")
        with pytest.raises(InterlockError, match=r"interlock open \(or tripped"):
            solar.wait_until_stable(timeout_s=1.0)
        assert solar.status().interlock and not solar.is_lamp_on()
        solar.lamp_on()  # the interlock is closed again: START clears the latch and lights
        assert solar.is_lamp_on() and not solar.status().interlock
