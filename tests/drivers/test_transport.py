"""Line framing, timeouts, garbled replies, retries and reconnects of the serial transport.

Every test talks over a real pty (a scripted peer or a simulator server) or a loopback socket.
"""

from __future__ import annotations

import dataclasses
import os
import time

import pytest

from drivers.errors import (
    DeviceDisconnectedError,
    DeviceTimeoutError,
    GarbledReplyError,
    ProtocolError,
)
from drivers.sim.faults import FaultInjector
from drivers.sim.oriel import ShutterControllerSim
from drivers.sim.pty_server import DeviceServer, LineFramer
from drivers.transport import SerialSettings, SerialTransport

pytestmark = pytest.mark.timeout(10)

SETTINGS = SerialSettings(write_terminator=b"\r", timeout_s=0.3, retries=2, reconnect_timeout_s=2)


def _number(line: str) -> float:
    return float(line)


def test_reply_split_across_writes_and_terminators(scripted_peer):
    peer = scripted_peer(
        [
            (b"A?\r", b"12"),  # the rest of the line comes in the next write
            (b"B?\r", b".5\r\n"),
            (b"C?\r", b"\r\n\r\n7\n"),  # empty lines are skipped; LF alone ends a line
        ]
    )
    with SerialTransport(peer.path, SETTINGS, name="peer") as transport:
        transport.write_line("A?")
        transport.write_line("B?")
        assert transport.read_line() == "12.5"
        assert transport.query("C?", _number) == 7.0
    peer.check()


def test_xon_xoff_bytes_are_not_part_of_a_reply(scripted_peer):
    peer = scripted_peer([(b"X?\r", b"4\x132\x11\r")])
    with SerialTransport(peer.path, SETTINGS) as transport:
        assert transport.query("X?", str) == "42"
    peer.check()


def test_stale_input_is_discarded_before_a_query(scripted_peer):
    peer = scripted_peer([(b"A?\r", b"1\rlate-reply-to-A\r"), (b"B?\r", b"2\r")])
    with SerialTransport(peer.path, SETTINGS) as transport:
        assert transport.query("A?", str) == "1"
        time.sleep(0.1)  # the late line arrives before B? is sent
        assert transport.query("B?", str) == "2"
    peer.check()


def test_garbled_reply_is_retried_and_then_accepted(scripted_peer):
    garbled = bytes(b ^ 0x80 for b in b"42")
    peer = scripted_peer([(b"X?\r", garbled + b"\r"), (b"X?\r", b"42\r")])
    with SerialTransport(peer.path, SETTINGS) as transport:
        assert transport.query("X?", _number) == 42.0
    peer.check()


def test_persistently_garbled_reply_raises_after_the_retries(scripted_peer):
    garbled = bytes(b ^ 0x80 for b in b"42") + b"\r"
    peer = scripted_peer([(b"X?\r", garbled)] * 3)
    with (
        SerialTransport(peer.path, SETTINGS, name="lamp") as transport,
        pytest.raises(GarbledReplyError, match=r"lamp at .*garbled reply.*3 attempts"),
    ):
        transport.query("X?", _number)
    peer.check()


def test_truncated_reply_times_out_showing_the_partial_bytes(scripted_peer):
    peer = scripted_peer([(b"X?\r", b"123")] * 3)
    start = time.monotonic()
    with (
        SerialTransport(peer.path, SETTINGS) as transport,
        pytest.raises(DeviceTimeoutError, match=r"partial reply b'123'.*3 attempts"),
    ):
        transport.query("X?", _number)
    assert time.monotonic() - start < 3 * SETTINGS.timeout_s + 1.0
    peer.check()


def test_malformed_reply_is_a_protocol_error(scripted_peer):
    peer = scripted_peer([(b"X?\r", b"abc\r")])
    settings = dataclasses.replace(SETTINGS, retries=0)
    with (
        SerialTransport(peer.path, settings) as transport,
        pytest.raises(ProtocolError, match=r"unexpected reply 'abc' to 'X\?'"),
    ):
        transport.query("X?", _number)
    peer.check()


def test_non_idempotent_query_is_not_retried(scripted_peer):
    peer = scripted_peer([(b"GO\r", None)])
    with (
        SerialTransport(peer.path, SETTINGS) as transport,
        pytest.raises(DeviceTimeoutError, match="1 attempt\\)"),
    ):
        transport.query("GO", str, idempotent=False)
    peer.check()


def test_opening_a_missing_port_names_it():
    with pytest.raises(DeviceDisconnectedError, match="/dev/does-not-exist"):
        SerialTransport("/dev/does-not-exist", SETTINGS).open()


def test_transcript_records_both_directions(scripted_peer):
    peer = scripted_peer([(b"IDN?\r", b"68945\r\n")])
    with SerialTransport(peer.path, SETTINGS) as transport:
        transport.query("IDN?", str)
        assert [(e.direction, e.data) for e in transport.transcript] == [
            ("tx", b"IDN?\r"),
            ("rx", b"68945"),
        ]
    peer.check()


@pytest.mark.parametrize("transport_kind", ["pty", "tcp"])
def test_reconnects_after_the_port_goes_away_and_comes_back(transport_kind):
    device = ShutterControllerSim()
    with DeviceServer(device, transport=transport_kind, name="shutter") as server:
        with SerialTransport(server.port, SETTINGS, name="shutter") as transport:
            assert transport.query("IDN?", str) == "68945"
            server.disconnect(downtime_s=0.3)
            time.sleep(0.1)
            assert transport.query("RUN?", str) == "0"  # reopened within reconnect_timeout_s
        if transport_kind == "pty":
            assert os.path.islink(server.port)
        assert server.disconnects == 1


def test_port_gone_for_longer_than_the_reconnect_timeout_raises():
    settings = dataclasses.replace(SETTINGS, reconnect_timeout_s=0.3)
    with (
        DeviceServer(ShutterControllerSim(), name="shutter") as server,
        SerialTransport(server.port, settings, name="shutter") as transport,
    ):
        transport.query("IDN?", str)
        server.disconnect(downtime_s=5.0)
        time.sleep(0.1)
        with pytest.raises(DeviceDisconnectedError, match=r"not back within 0\.3 s"):
            transport.query("RUN?", str)


def test_server_applies_reply_faults_from_its_injector():
    faults = FaultInjector()
    with (
        DeviceServer(ShutterControllerSim(), faults, name="shutter") as server,
        SerialTransport(server.port, SETTINGS) as transport,
    ):
        server.inject("garbled:1")
        assert transport.query("IDN?", str) == "68945"  # second attempt is clean
        server.inject("no-reply:1")
        assert transport.query("IDN?", str) == "68945"
        assert faults.fired == ["garbled", "no-reply"]


def test_line_framer_handles_split_commands_and_flow_bytes():
    framer = LineFramer()
    assert framer.feed(b"1P") == []
    assert framer.feed(b"A4\x115.0\r") == ["1PA45.0"]  # CR ends the line; XON dropped
    assert framer.feed(b"\n\r\n1TS\r\n") == ["1TS"]  # the pending LF and empty lines: nothing
