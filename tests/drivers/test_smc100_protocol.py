"""SMC100 protocol: encoding, every reply form, and the exact bytes the driver exchanges.

Reply examples are the ones of the "SMC100CC & SMC100PP User's Manual" (Newport, V3.0.x,
EDH0206En2054 06/23), section 5.5: ``1TS00000A``, ``1TP0``, ``1TH0``, ``1AC500``, ``1PT0.25``,
``1TE@``, ``1TB@ No error``, ``1IDURS100CC``, and the TS error maps ``0013`` and ``004C``.
The byte-exact tests run the real driver against a scripted peer on a real pty.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from drivers.errors import DeviceInputError, LimitError, ProtocolError, TurntableError
from drivers.turntable import (
    POSITIONER_ERROR_BITS,
    STATE_NAMES,
    TE_ERRORS,
    ControllerStatus,
    Turntable,
    describe_positioner_errors,
    encode_command,
    format_number,
    parse_number,
    parse_reply,
    parse_te,
    parse_ts,
    validate_address,
)
from tests.drivers.helpers import FAST_SMC100, ScriptedPeer

pytestmark = pytest.mark.timeout(10)


# -- encoding ------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("args", "line"),
    [
        ((1, "PA", 2.2), "1PA2.2"),  # manual, PA example
        ((1, "PA", 45), "1PA45.0"),
        ((1, "PR", -12.5), "1PR-12.5"),
        ((1, "VA", "?"), "1VA?"),  # manual: "1VA? sends the response 1VA10"
        ((1, "TS", None), "1TS"),
        ((31, "TP", None), "31TP"),
        ((1, "SL", -100), "1SL-100.0"),
        ((1, "PA", 1e-7), "1PA0.0"),
        ((1, "PA", -0.0), "1PA0.0"),
    ],
)
def test_encode_command(args, line):
    assert encode_command(*args) == line


@pytest.mark.parametrize("address", [0, 32, -1, True, 1.0, "1"])
def test_address_outside_1_to_31_names_field_and_range(address):
    with pytest.raises(DeviceInputError, match=r"^address: got .*1\.\.31"):
        validate_address(address)


def test_non_finite_value_is_refused():
    with pytest.raises(DeviceInputError, match="finite"):
        format_number(float("nan"))


# -- reply forms ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("line", "command", "value"),
    [
        ("1TS00000A", "TS", "00000A"),
        ("1TP0", "TP", "0"),
        ("1TH0", "TH", "0"),
        ("1AC500", "AC", "500"),
        ("1PT0.25", "PT", "0.25"),
        ("1TE@", "TE", "@"),
        ("1TB@ No error", "TB", "@ No error"),
        ("1IDURS100CC", "ID", "URS100CC"),
        ("1TP45.0000", "TP", "45.0000"),
        ("1TP-6.3e-05\r\n", "TP", "-6.3e-05"),
    ],
)
def test_parse_reply_returns_the_value(line, command, value):
    assert parse_reply(1, command, line) == value


@pytest.mark.parametrize(
    ("line", "why"),
    [
        ("2TS000033", "answers 2TS"),
        ("1TP000033", "answers 1TP"),
        ("TS000033", "not of the form"),
        ("", "not of the form"),
    ],
)
def test_parse_reply_rejects_replies_to_something_else(line, why):
    with pytest.raises(ProtocolError, match=why):
        parse_reply(1, "TS", line)


@pytest.mark.parametrize(
    ("value", "expected"),
    [("0", 0.0), ("45.0000", 45.0), ("-0.5", -0.5), ("1.76994e-05", 1.76994e-05), ("+3600", 3600)],
)
def test_parse_number(value, expected):
    assert parse_number(value) == expected


@pytest.mark.parametrize("value", ["", "xyz", "1.2.3", "nan", "inf", "4 5"])
def test_parse_number_rejects_non_numbers(value):
    with pytest.raises(ProtocolError):
        parse_number(value)


@pytest.mark.parametrize(
    ("value", "bits", "state"),
    [("00000A", 0, "0A"), ("000033", 0, "33"), ("00203D", 0x20, "3D"), ("00000a", 0, "0A")],
)
def test_parse_ts(value, bits, state):
    assert parse_ts(value) == (bits, state)


@pytest.mark.parametrize("value", ["0033", "0000033", "00G033", ""])
def test_parse_ts_rejects_malformed_values(value):
    with pytest.raises(ProtocolError, match="6 hex digits"):
        parse_ts(value)


def test_ts_error_maps_of_the_manual():
    assert describe_positioner_errors(0x0000) == []
    assert describe_positioner_errors(0x0013) == [
        "short circuit detection",
        "positive end of run",
        "negative end of run",
    ]
    assert describe_positioner_errors(0x004C) == [
        "homing time out",
        "RMS current limit",
        "peak current limit",
    ]
    assert describe_positioner_errors(0x8000) == ["undocumented bits 0x8000"]


def test_tables_match_the_manual():
    assert set(STATE_NAMES) == {
        "0A", "0B", "0C", "0D", "0E", "0F", "10", "11", "14", "1E", "1F", "28",
        "32", "33", "34", "35", "3C", "3D", "3E", "46", "47",
    }  # fmt: skip
    assert set(TE_ERRORS) == set("@ABCDEFGHIJKLMNSUVWX")
    assert POSITIONER_ERROR_BITS[9] == "80 W output power exceeded"
    assert ControllerStatus(0x20, "3D").describe() == (
        "3D DISABLE from MOVING, positioner errors 0x0020: following error"
    )


@pytest.mark.parametrize(("value", "code"), [("@", "@"), ("C", "C"), ("G", "G")])
def test_parse_te(value, code):
    assert parse_te(value) == code


@pytest.mark.parametrize("value", ["", "CC", "1", "c"])
def test_parse_te_rejects_other_values(value):
    with pytest.raises(ProtocolError):
        parse_te(value)


# -- exact exchanges with the real driver on a pty ------------------------------------------
CONNECT = [
    (b"1TE\r\n", b"1TE@\r\n"),
    (b"1TS\r\n", b"1TS000033\r\n"),
    (b"1ID?\r\n", b"1IDURS100CC\r\n"),
    (b"1SL?\r\n", b"1SL-170\r\n"),
    (b"1SR?\r\n", b"1SR170\r\n"),
]


@contextmanager
def _turntable_on(
    scripted_peer: type[ScriptedPeer], script: list[tuple[bytes, bytes | None]]
) -> Iterator[Turntable]:
    """The driver on a scripted peer; after the block, the peer has seen exactly the script."""
    peer = scripted_peer(script)
    with Turntable(peer.path, settle_s=0.0, poll_interval_s=0.01, settings=FAST_SMC100) as tt:
        yield tt
    peer.check()


def test_connect_sends_exactly_these_bytes(scripted_peer):
    with _turntable_on(scripted_peer, CONNECT) as tt:
        assert tt.stage_name == "URS100CC"
        assert tt.limits_deg == (-170.0, 170.0)


def test_position_query_and_its_reply(scripted_peer):
    with _turntable_on(scripted_peer, [*CONNECT, (b"1TP\r\n", b"1TP45.0000\r\n")]) as tt:
        assert tt.position_deg() == 45.0


def test_move_exchange_from_ready(scripted_peer):
    script = [
        *CONNECT,
        (b"1TS\r\n", b"1TS000033\r\n"),
        (b"1PA30.0\r\n", None),
        (b"1TE\r\n", b"1TE@\r\n"),
        (b"1TS\r\n", b"1TS000028\r\n"),
        (b"1TP\r\n", b"1TP15.2\r\n"),  # stall watch while MOVING
        (b"1TS\r\n", b"1TS000033\r\n"),
        (b"1TP\r\n", b"1TP30\r\n"),  # verification
        (b"1TP\r\n", b"1TP30\r\n"),  # after the settle time
    ]
    with _turntable_on(scripted_peer, script) as tt:
        assert tt.move_to(30.0) == 30.0


def test_homing_exchange_when_not_referenced(scripted_peer):
    script = [
        (b"1TE\r\n", b"1TE@\r\n"),
        (b"1TS\r\n", b"1TS00000A\r\n"),  # manual: NOT REFERENCED from reset
        (b"1ID?\r\n", b"1IDURS100CC\r\n"),
        (b"1SL?\r\n", b"1SL-170\r\n"),
        (b"1SR?\r\n", b"1SR170\r\n"),
        (b"1TS\r\n", b"1TS00000A\r\n"),
        (b"1OR\r\n", None),
        (b"1TE\r\n", b"1TE@\r\n"),
        (b"1TS\r\n", b"1TS00001E\r\n"),
        (b"1TS\r\n", b"1TS000032\r\n"),
    ]
    with _turntable_on(scripted_peer, script) as tt:
        tt.home()


@pytest.mark.parametrize(
    ("code", "meaning"),
    [("C", "parameter missing or out of range"), ("H", "NOT REFERENCED"), ("G", "out of limits")],
)
def test_te_error_after_a_command_raises_naming_the_letter(scripted_peer, code, meaning):
    script = [
        *CONNECT,
        (b"1VA25.0\r\n", None),
        (b"1TE\r\n", f"1TE{code}\r\n".encode()),
        (b"1TS\r\n", b"1TS000033\r\n"),
    ]
    with _turntable_on(scripted_peer, script) as tt, pytest.raises(TurntableError) as info:
        tt.set_velocity(25.0)
    assert f"TE reply {code!r} after '1VA25.0'" in str(info.value)
    assert meaning in str(info.value)
    assert info.value.te_code == code


def test_positioner_error_during_a_move_raises_naming_the_bits(scripted_peer):
    script = [
        *CONNECT,
        (b"1TS\r\n", b"1TS000033\r\n"),
        (b"1PA90.0\r\n", None),
        (b"1TE\r\n", b"1TE@\r\n"),
        (b"1TS\r\n", b"1TS00203D\r\n"),
        (b"1TP\r\n", b"1TP44.9\r\n"),
    ]
    with _turntable_on(scripted_peer, script) as tt, pytest.raises(TurntableError) as info:
        tt.move_to(90.0)
    message = str(info.value)
    assert "3D DISABLE from MOVING" in message and "following error" in message
    assert "44.9 deg" in message
    assert (info.value.state, info.value.error_bits) == ("3D", 0x20)


def test_limit_error_sends_nothing(scripted_peer):
    # the peer is checked to have seen nothing after the connect exchange
    with _turntable_on(scripted_peer, CONNECT) as tt, pytest.raises(LimitError) as info:
        tt.move_to(400.0)
    assert str(info.value) == (
        "angle_deg: requested 400 deg is outside the allowed range [-170, 170] deg "
        "(turntable software limits SL/SR)"
    )
