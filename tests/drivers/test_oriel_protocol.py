"""Oriel lamp supply (69907 family) and 68945 exposure controller: reply forms, exact bytes.

Reply forms follow the open-source clients the protocol is documented from (see
docs/devices.md): ``STB80`` / ``ESR20`` (register name + 2 hex digits; RTS2 ``newportlamp.cpp``,
lantz ``Newport69907``), numbers for the readings, ``ESRxx`` in answer to every command that is
not a query, ``RUN?`` -> ``0``/``1`` for the shutter (the 68945 driver of M. H. Richter).
The byte-exact tests run the real driver against scripted peers on real ptys.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from drivers.errors import (
    InterlockError,
    LampFaultError,
    LimitError,
    ProtocolError,
    SolarSimulatorError,
)
from drivers.sim import SimClock
from drivers.sim.oriel import LampSupplySim, ShutterControllerSim
from drivers.solar_simulator import (
    SolarSimulator,
    describe_esr,
    describe_stb,
    parse_register,
    parse_value,
)
from tests.drivers.helpers import ScriptedPeer, fast_solar

pytestmark = pytest.mark.timeout(10)


# -- reply forms ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("name", "line", "value"),
    [("STB", "STB80", 0x80), ("STB", "STBA0\r", 0xA0), ("ESR", "ESR00", 0), ("ESR", "ESR3c", 0x3C)],
)
def test_parse_register(name, line, value):
    assert parse_register(name, line) == value


@pytest.mark.parametrize("line", ["ESR20", "STB", "STB1G", "0x80", "STB 80"])
def test_parse_register_rejects_other_lines(line):
    with pytest.raises(ProtocolError, match="STB followed by 2 hex digits"):
        parse_register("STB", line)


@pytest.mark.parametrize(("line", "value"), [("0400", 400.0), ("21.5", 21.5), ("0412", 412.0)])
def test_parse_value(line, value):
    assert parse_value(line) == value


@pytest.mark.parametrize("line", ["", "ESR00", "12 W", "nan"])
def test_parse_value_rejects_other_lines(line):
    with pytest.raises(ProtocolError):
        parse_value(line)


def test_status_bits_are_named():
    assert describe_stb(0x80 | 0x20 | 0x08 | 0x01) == [
        "lamp on",
        "power mode (else current mode)",
        "fault",
        "interlock",
    ]
    assert describe_esr(0x80 | 0x20 | 0x10) == ["power on", "command error", "execution error"]


# -- the simulators' replies ---------------------------------------------------------------
def test_lamp_supply_replies():
    lamp = LampSupplySim(clock=SimClock(instant=True))
    assert lamp.handle_line("IDN?") == ["69907"]
    assert lamp.handle_line("STB?") == ["STB20"]  # power mode, lamp off
    assert lamp.handle_line("ESR?") == ["ESR80"]  # power-on bit, cleared by reading
    assert lamp.handle_line("ESR?") == ["ESR00"]
    assert lamp.handle_line("WATTS?") == ["0000"]
    assert lamp.handle_line("P-LIM?") == ["0500"]
    assert lamp.handle_line("LAMP HRS?") == ["0412"]
    assert lamp.handle_line("P-PRESET=395") == ["ESR00"]
    assert lamp.handle_line("p-preset 396") == ["ESR00"]  # case and '=' or blank separator
    assert lamp.handle_line("P-PRESET?") == ["0396"]
    assert lamp.handle_line("A-PRESET=7.5") == ["ESR00"]  # lantz writes '{:.1f}'
    assert lamp.handle_line("A-PRESET?") == ["07.5"]
    assert lamp.handle_line("P-PRESET=0600") == ["ESR10"]  # above P-LIM: execution error
    assert lamp.handle_line("P-PRESET=abc") == ["ESR10"]
    assert lamp.handle_line("FOO") == ["ESR20"]  # unknown command: command error
    assert lamp.handle_line("FOO?") == ["ESR20"]
    assert lamp.handle_line("START") == ["ESR00"]
    assert lamp.handle_line("STB?") == ["STBA0"]
    assert lamp.handle_line("WATTS?") == ["0396"]
    assert lamp.handle_line("STOP") == ["ESR00"]
    assert lamp.handle_line("") == []


def test_rts2_newportlamp_transcript():
    """RTS2 reads 'STB?' expecting 'STB' + hex and tests bit 0x80 for 'lamp on'; after START,
    STOP and 'P-PRESET=<int>' it reads a line starting with 'ESR'."""
    lamp = LampSupplySim(clock=SimClock(instant=True))
    assert lamp.handle_line("STB?")[0].startswith("STB")
    assert lamp.handle_line("START")[0].startswith("ESR")
    assert int(lamp.handle_line("STB?")[0][3:], 16) & 0x80
    assert lamp.handle_line("P-PRESET=380")[0].startswith("ESR")
    for query in ("AMPS?", "VOLTS?", "WATTS?", "A-PRESET?", "P-PRESET?", "A-LIM?", "P-LIM?"):
        float(lamp.handle_line(query)[0])
    assert int(lamp.handle_line("IDN?")[0]) == 69907
    assert int(lamp.handle_line("LAMP HRS?")[0]) >= 412


def test_shutter_controller_replies():
    shutter = ShutterControllerSim()
    assert shutter.handle_line("IDN?") == ["68945"]
    assert shutter.handle_line("RUN?") == ["0"]
    assert shutter.handle_line("start") == ["ESR80"]  # first ESR carries the power-on bit
    assert shutter.handle_line("RUN?") == ["1"]
    assert shutter.handle_line("EXPSTATE?") == ["1"]
    assert shutter.handle_line("STOP") == ["ESR00"]
    assert shutter.handle_line("RUN?") == ["0"]
    assert shutter.handle_line("OPEN") == ["ESR20"]


# -- exact exchanges with the real driver on ptys -----------------------------------------
LAMP_CONNECT = [
    (b"IDN?\r", b"69907\r"),
    (b"ESR?\r", b"ESR80\r"),
    (b"STB?\r", b"STB20\r"),
    (b"P-LIM?\r", b"0500\r"),
]
SHUTTER_CONNECT = [(b"IDN?\r", b"68945\r\n"), (b"ESR?\r", b"ESR80\r\n")]


@contextmanager
def _solar_on(
    scripted_peer: type[ScriptedPeer],
    lamp_script: list[tuple[bytes, bytes | None]],
    shutter_script: list[tuple[bytes, bytes | None]] = SHUTTER_CONNECT,
) -> Iterator[SolarSimulator]:
    """The driver on two scripted peers; after the block, each has seen exactly its script."""
    lamp, shutter = scripted_peer(lamp_script), scripted_peer(shutter_script)
    with fast_solar(lamp.path, shutter.path) as solar:
        yield solar
    lamp.check()
    shutter.check()


def test_connect_sends_exactly_these_bytes(scripted_peer):
    with _solar_on(scripted_peer, LAMP_CONNECT) as solar:
        assert (solar.model_id, solar.shutter_model_id, solar.power_limit_w) == (
            "69907",
            "68945",
            500.0,
        )


def test_supply_in_current_mode_is_switched_to_power_mode(scripted_peer):
    lamp_script = [
        (b"IDN?\r", b"69907\r"),
        (b"ESR?\r", b"ESR00\r"),
        (b"STB?\r", b"STB00\r"),  # current mode
        (b"MODE=0\r", b"ESR00\r"),
        (b"P-LIM?\r", b"0500\r"),
    ]
    with _solar_on(scripted_peer, lamp_script):
        pass


def test_set_power_and_suns_exchanges(scripted_peer):
    lamp_script = [
        *LAMP_CONNECT,
        (b"P-PRESET=400\r", b"ESR00\r"),
        (b"P-PRESET?\r", b"0400\r"),
        (b"P-PRESET=436\r", b"ESR00\r"),  # 1.1 suns in the default table
        (b"P-PRESET?\r", b"0436\r"),
    ]
    with _solar_on(scripted_peer, lamp_script) as solar:
        solar.set_power_w(400.0)
        solar.set_suns(1.1)


def test_lamp_on_and_shutter_exchanges(scripted_peer):
    lamp_script = [
        *LAMP_CONNECT,
        (b"STB?\r", b"STB20\r"),
        (b"ESR?\r", b"ESR00\r"),
        (b"START\r", b"ESR00\r"),
        (b"STB?\r", b"STB20\r"),  # not lit yet
        (b"STB?\r", b"STBA0\r"),
    ]
    shutter_script = [
        *SHUTTER_CONNECT,
        (b"START\r", b"ESR00\r\n"),
        (b"RUN?\r", b"1\r\n"),
        (b"STOP\r", b"ESR00\r\n"),
        (b"RUN?\r", b"0\r\n"),
    ]
    with _solar_on(scripted_peer, lamp_script, shutter_script) as solar:
        solar.lamp_on()
        solar.open_shutter()
        solar.close_shutter()


def test_esr_error_after_a_command_raises_naming_the_bits(scripted_peer):
    with (
        _solar_on(scripted_peer, [*LAMP_CONNECT, (b"P-PRESET=450\r", b"ESR20\r")]) as solar,
        pytest.raises(
            SolarSimulatorError, match=r"ESR 0x20 \(command error\) after 'P-PRESET=450'"
        ),
    ):
        solar.set_power_w(450.0)


def test_start_refused_with_interlock_open_raises_interlock_error(scripted_peer):
    lamp_script = [
        *LAMP_CONNECT,
        (b"STB?\r", b"STB20\r"),
        (b"ESR?\r", b"ESR00\r"),
        (b"START\r", b"ESR10\r"),  # execution error
        (b"STB?\r", b"STB21\r"),  # interlock bit
    ]
    with (
        _solar_on(scripted_peer, lamp_script) as solar,
        pytest.raises(InterlockError, match="interlock"),
    ):
        solar.lamp_on()


def test_device_error_in_esr_is_a_lamp_fault(scripted_peer):
    lamp_script = [*LAMP_CONNECT, (b"P-PRESET=400\r", b"ESR08\r"), (b"STB?\r", b"STB28\r")]
    with _solar_on(scripted_peer, lamp_script) as solar, pytest.raises(LampFaultError) as info:
        solar.set_power_w(400.0)
    assert str(info.value) == (
        "lamp supply: ESR 0x08 (device dependent error) after 'P-PRESET=400'; "
        "STB 0x28 (power mode (else current mode), fault)"
    )


def test_lamp_off_after_a_latched_fault_only_logs_it(scripted_peer, caplog):
    with _solar_on(scripted_peer, [*LAMP_CONNECT, (b"STOP\r", b"ESR08\r")]) as solar:
        solar.lamp_off()
    assert "a lamp fault was latched" in caplog.text


@pytest.mark.parametrize("suns", [0.79, 1.21, 0.0, float("nan")])
def test_suns_outside_range_names_field_and_range_and_sends_nothing(scripted_peer, suns):
    with _solar_on(scripted_peer, LAMP_CONNECT) as solar, pytest.raises(LimitError) as info:
        solar.set_suns(suns)
    assert str(info.value).startswith("suns: requested")
    assert "[0.8, 1.2] suns" in str(info.value)


@pytest.mark.parametrize("power", [0.0, -5.0, 501.0])
def test_power_outside_supply_limit_names_field_and_range(scripted_peer, power):
    with _solar_on(scripted_peer, LAMP_CONNECT) as solar, pytest.raises(LimitError) as info:
        solar.set_power_w(power)
    assert str(info.value).startswith("power_w: requested")
    assert "[0, 500] W" in str(info.value)
