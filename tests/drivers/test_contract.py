"""Contract suites: what the rest of the code may rely on from a turntable and a solar simulator.

Each suite runs against every backend: the simulators on a pty and on a loopback socket, and real
hardware when its ports are given in the environment (otherwise that backend is not collected):

    TOFTWIN_TURNTABLE_PORT=/dev/ttyUSB0 [TOFTWIN_TURNTABLE_ADDRESS=1]
    TOFTWIN_LAMP_PORT=/dev/ttyUSB1 TOFTWIN_SHUTTER_PORT=/dev/ttyUSB2 [TOFTWIN_WARMUP_S=1800]

The tests only use the Protocol interfaces, move the stage within +-20 deg and keep the lamp
between 0.8 and 1.2 suns.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterator
from typing import TypeVar

import pytest

from drivers.errors import LimitError
from drivers.sim.pty_server import SimHandle, start_simulator
from drivers.solar_simulator import SUNS_RANGE, SolarSimulator, SolarSimulatorProtocol
from drivers.turntable import Turntable, TurntableProtocol
from tests.drivers.helpers import FAST_SMC100, fast_solar

pytestmark = pytest.mark.timeout(20)

_HARDWARE = pytest.param("hardware", marks=pytest.mark.timeout(3600))
# The hardware backend is collected only where its ports are configured, so a machine without
# the rig runs the simulator backends and reports no skipped tests.
TURNTABLE_BACKENDS = ["sim-pty", "sim-tcp"] + (
    [_HARDWARE] if "TOFTWIN_TURNTABLE_PORT" in os.environ else []
)
SOLAR_BACKENDS = ["sim-pty", "sim-tcp"] + (
    [_HARDWARE] if {"TOFTWIN_LAMP_PORT", "TOFTWIN_SHUTTER_PORT"} <= set(os.environ) else []
)


DeviceT = TypeVar("DeviceT", Turntable, SolarSimulator)


def _connected(device: DeviceT) -> Iterator[DeviceT]:
    """``device`` connected for one test, closed after it."""
    device.connect()
    yield device
    device.close()


def _device(
    backend: str,
    *,
    hardware: Callable[[], DeviceT],
    simulator: str,
    time_scale: float,
    on_simulator: Callable[[SimHandle], DeviceT],
) -> Iterator[DeviceT]:
    """The device of ``backend`` connected for one test, closed after it: the rig's
    (``hardware()``), or ``on_simulator(handle)`` on a fresh ``simulator`` on a pty or a socket."""
    if backend == "hardware":
        yield from _connected(hardware())
        return
    transport = "pty" if backend == "sim-pty" else "tcp"
    with start_simulator(simulator, transport=transport, time_scale=time_scale) as handle:
        yield from _connected(on_simulator(handle))


@pytest.fixture(params=TURNTABLE_BACKENDS)
def turntable(request: pytest.FixtureRequest) -> Iterator[TurntableProtocol]:
    yield from _device(
        request.param,
        hardware=lambda: Turntable(
            os.environ["TOFTWIN_TURNTABLE_PORT"],
            address=int(os.environ.get("TOFTWIN_TURNTABLE_ADDRESS", "1")),
        ),
        simulator="turntable",
        time_scale=50.0,
        on_simulator=lambda handle: Turntable(
            handle.ports[0],
            settle_s=0.0,
            poll_interval_s=0.005,
            stall_timeout_s=0.5,
            settings=FAST_SMC100,
        ),
    )


@pytest.fixture(params=SOLAR_BACKENDS)
def solar(request: pytest.FixtureRequest) -> Iterator[SolarSimulatorProtocol]:
    yield from _device(
        request.param,
        hardware=lambda: SolarSimulator(
            os.environ["TOFTWIN_LAMP_PORT"],
            os.environ["TOFTWIN_SHUTTER_PORT"],
            warmup_s=float(os.environ.get("TOFTWIN_WARMUP_S", "1800")),
        ),
        simulator="solar-simulator",
        time_scale=5000.0,
        on_simulator=lambda handle: fast_solar(*handle.ports, warmup_s=0.2),
    )


def _stable_timeout(device: SolarSimulatorProtocol) -> float:
    warmup = getattr(device, "warmup_s", 0.0)
    return 2.0 * warmup + 60.0 if warmup > 10 else 5.0


# -- turntable -----------------------------------------------------------------------------
def test_turntable_implements_the_protocol(turntable):
    assert isinstance(turntable, TurntableProtocol)
    low, high = turntable.limits_deg
    assert math.isfinite(low) and math.isfinite(high) and low < high


def test_turntable_homes_and_reaches_verified_angles(turntable):
    turntable.home()
    low, high = turntable.limits_deg
    for angle in (0.0, 20.0, -20.0, 7.25):
        target = min(max(angle, low), high)
        reached = turntable.move_to(target)
        assert abs(reached - target) <= 0.01
        assert abs(turntable.position_deg() - target) <= 0.01


def test_turntable_refuses_targets_outside_its_limits_without_moving(turntable):
    turntable.home()
    before = turntable.position_deg()
    low, high = turntable.limits_deg
    for target in (high + 1.0, low - 1.0):
        with pytest.raises(LimitError, match=r"^angle_deg: requested .* deg"):
            turntable.move_to(target)
    assert abs(turntable.position_deg() - before) <= 0.01


def test_turntable_stop_when_idle_is_harmless(turntable):
    turntable.home()
    turntable.stop()
    target = min(max(5.0, turntable.limits_deg[0]), turntable.limits_deg[1])
    assert abs(turntable.move_to(target) - target) <= 0.01


# -- solar simulator -----------------------------------------------------------------------
def test_solar_simulator_implements_the_protocol(solar):
    assert isinstance(solar, SolarSimulatorProtocol)
    hours = solar.lamp_hours()
    assert math.isfinite(hours) and hours >= 0


def test_solar_simulator_power_and_suns_round_trip(solar):
    solar.lamp_on()
    try:
        solar.set_suns(1.0)
        power = solar.wait_until_stable(_stable_timeout(solar))
        assert solar.read_power_w() == pytest.approx(power, abs=5.0)
        assert solar.read_suns() == pytest.approx(1.0, abs=0.01)
        for suns in SUNS_RANGE:
            solar.set_suns(suns)
            solar.wait_until_stable(_stable_timeout(solar))
            assert solar.read_suns() == pytest.approx(suns, abs=0.01)
        assert solar.status().lamp_on
    finally:
        solar.lamp_off()
    assert not solar.is_lamp_on()
    assert solar.read_suns() == 0.0


def test_solar_simulator_refuses_levels_outside_range(solar):
    for suns in (SUNS_RANGE[0] - 0.01, SUNS_RANGE[1] + 0.01):
        with pytest.raises(LimitError, match=r"^suns: requested .*\[0\.8, 1\.2\] suns"):
            solar.set_suns(suns)


def test_solar_simulator_shutter_round_trip(solar):
    solar.open_shutter()
    assert solar.shutter_is_open()
    solar.close_shutter()
    assert not solar.shutter_is_open()
    assert solar.status().shutter_open is False
