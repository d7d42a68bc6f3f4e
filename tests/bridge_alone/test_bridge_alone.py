"""The camera bridge alone against the roypy double: what a lab PC runs, with numpy only.

``toftwin_camera_bridge.py`` is copied to the PC beside the camera and run with the Python that
PMD's royale was built for (3.8 and up), with numpy and the standard library. These tests check
that file on its own: :class:`RoyaleSource` over the conformance double of roypy
(``tests/roypy_double``) for royale 5 (raw-data listener, level 1) and royale 3/4 (extended
listener, level-2 access code), use cases of 5 and 9 raw frames, grey first and grey last; the
:class:`BridgeServer` driven by a plain socket client written here with the bridge's own wire
functions; a camera unplugged mid-stream; data that raises inside royale's callback; the bridge
started without roypy; and the bridge started the way a lab starts it, with the double as
``roypy`` on ``PYTHONPATH``.

They import only the standard library, numpy, pytest, ``toftwin_camera_bridge`` and the double,
and keep to Python 3.8's syntax: ``.ci/bridge-alone`` runs them in a venv holding numpy and
pytest alone, on the oldest Python it finds; the main suite collects them too.

In this process the double is imported as the package module ``tests.roypy_double.roypy``
(passed to the bridge as its ``roypy``), never as a top-level ``roypy``: in the main suite that
would make the rest of the session believe royale is installed (the package's docstring). The
bridge's own ``import roypy`` is exercised in a subprocess, the double's directory on
``PYTHONPATH`` as royale's python directory would be (the last test).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import platform
import queue
import re
import socket
import subprocess
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import toftwin_camera_bridge as bridge
from tests.roypy_double import roypy as double
from toftwin_camera_bridge import (
    PROTOCOL_VERSION,
    BridgeError,
    BridgeServer,
    RawDataCopy,
    RawDataLayoutError,
    RoyaleSource,
    copy_roypy_raw_data,
    encode_message,
    frame_message,
    raw_data_from_message,
    read_message,
    split_raw_buffer,
)

ROOT = Path(__file__).resolve().parents[2]
BRIDGE_FILE = Path(bridge.__file__).resolve()
DOUBLE_DIR = Path(double.__file__).resolve().parent
DOUBLE = double.DOUBLE
CAMERA_ID = double.DEFAULT_CAMERA_ID
H, W = double.SENSOR_HEIGHT, double.SENSOR_WIDTH
MODE5, MODE9 = "MODE_5_45FPS_500", "MODE_9_5FPS_2000"
EXPOSURE_US = {MODE5: 250, MODE9: 1200}
#: what royale's fields say per (use case, grey last): raw frames per exposure group, the
#: group's modulation frequency, the group's name (values per group, the double's default)
LAYOUT = {
    (MODE5, False): ((1, 4), (60_240_000, 60_240_000), ("gray", "mod6024")),
    (MODE5, True): ((4, 1), (60_240_000, 60_240_000), ("mod6024", "gray")),
    (MODE9, False): ((1, 4, 4), (60_240_000, 80_320_000, 60_240_000),
                     ("gray", "mod8032", "mod6024")),
    (MODE9, True): ((4, 4, 1), (80_320_000, 60_240_000, 60_240_000),
                    ("mod8032", "mod6024", "gray")),
}
#: grey last comes with the phases out of order: the bridge must keep royale's order
PHASES_GREY_LAST = (180, 0, 270, 90)
WAIT_S = 5.0  # the longest any single wait of these tests may take


# -- the double ----------------------------------------------------------------------------------
class Recorder:
    """The double's frame provider: random 12-bit images, kept by delivery index (so a frame
    that went through the bridge can be compared with what royale produced)."""

    def __init__(self, seed: int = 28) -> None:
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self.images: dict[int, np.ndarray] = {}
        self.slots: dict[int, list] = {}

    def __call__(self, spec: Any, index: int, slots: Any) -> list:
        images = self._rng.integers(0, 4096, (len(slots), H, W), dtype=np.uint16)
        with self._lock:
            self.images[index] = images.copy()
            self.slots[index] = list(slots)
        return list(images)


def _temperature(index: int) -> float:
    """The illumination temperature of delivery ``index`` (it encodes the index)."""
    return 20.0 + 0.25 * index


def _index_of(data: RawDataCopy) -> int:
    """The delivery index a copy came from, read back from its temperature."""
    assert data.illumination_temperature_c is not None
    index = (data.illumination_temperature_c - 20.0) / 0.25
    assert index == int(index) >= 0, data.illumination_temperature_c
    return int(index)


def _setup_double(generation: int, monkeypatch: pytest.MonkeyPatch) -> Recorder:
    DOUBLE.reset(generation=generation)
    DOUBLE.frame_interval_s = 0.01
    recorder = Recorder()
    DOUBLE.frame_provider = recorder
    DOUBLE.illumination_temperature = _temperature
    DOUBLE.plug(CAMERA_ID)
    monkeypatch.delenv(bridge.ACCESS_CODE_VARIABLE, raising=False)
    return recorder


@pytest.fixture(params=[3, 4, 5], ids=lambda g: f"royale{g}")
def royale(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch):
    """The double as royale 3, 4 or 5, one camera plugged, fast frames; the recorder."""
    yield _setup_double(request.param, monkeypatch)
    DOUBLE.reset()  # stops a stream a failing test left running


@pytest.fixture(params=[3, 5], ids=lambda g: f"royale{g}")
def royale35(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch):
    """The two raw-data generations: 3 (extended data, level 2) and 5 (raw-data listener)."""
    yield _setup_double(request.param, monkeypatch)
    DOUBLE.reset()


def _grey_order(use_case: str, grey_last: bool) -> None:
    DOUBLE.grey_last = grey_last
    if grey_last:
        DOUBLE.phase_order = PHASES_GREY_LAST


def _check_copy(data: RawDataCopy, recorder: Recorder, use_case: str, grey_last: bool) -> int:
    """``data`` is what the double delivered for its index (returned), in royale's order."""
    counts, frequencies, names = LAYOUT[(use_case, grey_last)]
    n = sum(counts)
    index = _index_of(data)
    assert (data.width, data.height) == (W, H)
    assert data.raw_frames.shape == (n, H, W) and data.raw_frames.dtype == np.uint16
    assert np.array_equal(data.raw_frames, recorder.images[index])
    grey_at = n - 1 if grey_last else 0
    assert recorder.slots[index][grey_at].grey  # the double put the grey frame there
    assert data.raw_frame_count == counts
    assert data.modulation_frequencies_hz == frequencies
    assert data.exposure_group_names == names
    assert data.exposure_times_us == (EXPOSURE_US[use_case],) * len(counts)
    phases = (PHASES_GREY_LAST if grey_last else (0, 90, 180, 270)) * (len(counts) - 1)
    assert data.phase_angles_deg == ((*phases, 0) if grey_last else (0, *phases))
    assert data.illumination_enabled == tuple(0 if i == grey_at else 1 for i in range(n))
    assert data.illumination_temperature_c == _temperature(index)
    assert isinstance(data.timestamp_us, int)
    assert abs(data.timestamp_us / 1e6 - time.time()) < 60
    assert data.stream_id == 0
    return index


# -- RoyaleSource over the double ----------------------------------------------------------------
@pytest.mark.parametrize("grey_last", [False, True], ids=["grey-first", "grey-last"])
@pytest.mark.parametrize("use_case", [MODE5, MODE9])
def test_royale_source_streams_royales_raw_frames(royale, use_case, grey_last):
    _grey_order(use_case, grey_last)
    got: queue.Queue = queue.Queue()
    source = RoyaleSource(double, got.put, DOUBLE.L2_CODE)
    assert source.describe() == {"backend": "roypy", "royale": double.getVersionString()}
    assert source.list_cameras() == [CAMERA_ID]
    ident = source.open()
    assert (ident["id"], ident["name"], ident["backend"]) == (CAMERA_ID, "PICOFLEXX", "roypy")
    assert ident["use_cases"] == list(double.PICO_FLEXX_USE_CASES)
    assert ident["info"]["IMAGER"] == "M2450_A12_AIO"
    device = DOUBLE.devices[-1]
    assert device.getAccessLevel() == 2 and source.camera_id == CAMERA_ID
    source.set_use_case(use_case)
    source.set_exposure(EXPOSURE_US[use_case])
    assert device.getCurrentUseCase() == use_case
    source.start()
    assert source.streaming and device.isCapturing()
    copies = [got.get(timeout=WAIT_S) for _ in range(3)]
    source.stop()
    assert not source.streaming and not device.isCapturing()
    # every delivery reaches on_frame, in order: the k-th copy is royale's k-th frame
    assert [_check_copy(c, royale, use_case, grey_last) for c in copies] == [0, 1, 2]
    stamps = [c.timestamp_us for c in copies]
    assert stamps == sorted(stamps) and len(set(stamps)) == 3
    source.close()
    source.close()  # twice is fine
    assert source.callback_errors == [] and DOUBLE.listener_errors == []
    with pytest.raises(BridgeError, match="no camera is open") as info:
        source.start()
    assert info.value.kind == "not_found"


def test_royale_source_switches_use_case_while_streaming(royale):
    got: queue.Queue = queue.Queue()
    source = RoyaleSource(double, got.put, DOUBLE.L2_CODE)
    source.open()
    source.set_use_case(MODE5)
    source.start()
    assert got.get(timeout=WAIT_S).raw_frames.shape[0] == 5
    source.set_use_case(MODE9)  # stops, switches, starts again
    assert source.streaming and DOUBLE.devices[-1].isCapturing()
    deadline = time.monotonic() + WAIT_S
    while got.get(timeout=WAIT_S).raw_frames.shape[0] != 9:
        assert time.monotonic() < deadline
    with pytest.raises(BridgeError, match=r"'MODE_MIXED_30_5' is not offered") as info:
        source.set_use_case("MODE_MIXED_30_5")
    assert info.value.kind == "input"
    with pytest.raises(BridgeError, match="EXPOSURE_TIME_NOT_SUPPORTED") as info:
        source.set_exposure(5000)  # beyond the use case's 2000 us
    source.close()
    assert not DOUBLE.devices[-1].isCapturing()


def test_royale_source_access_level_per_generation(royale):
    generation = DOUBLE.generation
    source = RoyaleSource(double, lambda data: None, access_code=None)
    if generation >= 5:  # the raw-data listener needs level 1
        assert source.open()["id"] == CAMERA_ID
        assert DOUBLE.devices[-1].getAccessLevel() == 1
        source.close()
        return
    for _ in range(2):  # a failed open leaves nothing half open: the second fails alike
        with pytest.raises(BridgeError, match=r"(?s)INSUFFICIENT_PRIVILEGES.*level 2.*"
                           + bridge.ACCESS_CODE_VARIABLE) as info:
            source.open()
        assert info.value.kind == "access" and source.camera_id is None


def test_royale_source_access_code_from_the_environment(royale, monkeypatch):
    monkeypatch.setenv(bridge.ACCESS_CODE_VARIABLE, DOUBLE.L2_CODE)
    source = RoyaleSource(double, lambda data: None)
    source.open()
    assert DOUBLE.devices[-1].getAccessLevel() == 2
    source.close()


def test_royale_source_with_no_camera_or_another_one(royale):
    DOUBLE.unplug(CAMERA_ID)
    source = RoyaleSource(double, lambda data: None, DOUBLE.L2_CODE)
    assert source.list_cameras() == []
    with pytest.raises(BridgeError, match="royale sees no camera") as info:
        source.open()
    assert info.value.kind == "not_found"
    DOUBLE.plug("0005-1111-2222-3333")
    with pytest.raises(BridgeError, match=r"'nope' not among \['0005-1111-2222-3333'\]"):
        source.open("nope")
    assert source.open()["id"] == "0005-1111-2222-3333"
    source.close()


def _stream_failing_data(recorder: Recorder, where: str) -> None:
    # had anything raised into royale's thread, this policy would have ended the stream
    DOUBLE.listener_error_policy = "stop"
    DOUBLE.fail_next_data(2, where=where)
    got: queue.Queue = queue.Queue()
    source = RoyaleSource(double, got.put, DOUBLE.L2_CODE)
    source.open()
    source.set_use_case(MODE9)
    source.set_exposure(EXPOSURE_US[MODE9])
    source.start()
    copies = [got.get(timeout=WAIT_S) for _ in range(3)]
    source.close()
    assert [_check_copy(c, recorder, MODE9, False) for c in copies] == [2, 3, 4]
    assert len(source.callback_errors) == 2
    assert all("injected failure" in e for e in source.callback_errors)
    assert DOUBLE.listener_errors == []


def test_raw_data_raising_in_royales_callback_is_counted_and_the_stream_goes_on(royale):
    _stream_failing_data(royale, "getRawPhase")


@pytest.mark.parametrize("royale", [3, 4], indirect=True, ids=lambda g: f"royale{g}")
def test_extended_data_raising_in_royales_callback_is_counted_and_the_stream_goes_on(royale):
    _stream_failing_data(royale, "hasRawData")  # IExtendedData.hasRawData(), before royale 5


def test_a_frame_handler_raising_is_counted_and_the_stream_goes_on(royale):
    DOUBLE.listener_error_policy = "stop"
    got: list = []

    def on_frame(data: RawDataCopy) -> None:
        got.append(data)
        if len(got) <= 2:
            raise ValueError(f"handler bug {len(got)}")

    source = RoyaleSource(double, on_frame, DOUBLE.L2_CODE)
    source.open()
    source.start()
    deadline = time.monotonic() + WAIT_S
    while len(got) < 4 and time.monotonic() < deadline:
        time.sleep(0.01)
    source.close()
    assert len(got) >= 4
    assert source.callback_errors == ["ValueError('handler bug 1')", "ValueError('handler bug 2')"]
    assert DOUBLE.listener_errors == []


# -- royale 5's flat raw buffer ------------------------------------------------------------------
class _WithoutGetRawPhase:
    """A royale 5 ``RawData`` whose wrapper offers the flat ``rawData`` buffer only."""

    def __init__(self, raw: Any) -> None:
        self._raw = raw

    def __getattr__(self, name: str) -> Any:
        if name == "getRawPhase":
            raise AttributeError(name)
        return getattr(self._raw, name)


def _stream_mode9_until(listener: Any, results: list) -> None:
    """Stream MODE_9 from the double's camera to ``listener`` (held here: royale keeps no
    reference of its own) until ``results`` holds something or WAIT_S passed; then reset."""
    cam = double.CameraManager().createCamera(CAMERA_ID)
    cam.initialize()
    cam.registerRawDataListener(listener)
    cam.setUseCase(MODE9)
    cam.setExposureTime(EXPOSURE_US[MODE9])
    cam.startCapture()
    deadline = time.monotonic() + WAIT_S
    while not results and time.monotonic() < deadline:
        time.sleep(0.01)
    cam.stopCapture()
    DOUBLE.reset()


def test_royale_5_flat_buffer_gives_the_same_frames_as_get_raw_phase(monkeypatch):
    recorder = _setup_double(5, monkeypatch)
    DOUBLE.expose_flat_raw_data = True
    _grey_order(MODE9, True)
    results: list = []

    class Listener(double.IRawDataListener):  # type: ignore[name-defined]
        def onNewData(self, data: Any) -> None:
            flat = np.asarray(data.rawData, dtype=np.uint16)
            results.append((copy_roypy_raw_data(data),
                            copy_roypy_raw_data(_WithoutGetRawPhase(data)), flat))

    _stream_mode9_until(Listener(), results)
    assert results and DOUBLE.listener_errors == []
    by_phase, by_buffer, flat = results[0]
    assert _check_copy(by_phase, recorder, MODE9, True) == 0
    assert _check_copy(by_buffer, recorder, MODE9, True) == 0
    assert flat.size == 9 * W * (H + 1)
    assert int(np.count_nonzero(flat == double.PSEUDO_WORD)) == 9 * W  # the pseudo rows
    assert not np.any(by_buffer.raw_frames == double.PSEUDO_WORD)  # none leaked into an image


def test_split_raw_buffer_refuses_a_buffer_of_the_wrong_size_naming_the_layout():
    flat = np.arange(2 * 3 * 3, dtype=np.uint16)  # 2 frames of 3 x 2 plus a pseudo row each
    assert split_raw_buffer(flat, 2, 3, 2).tolist() == [[[3, 4, 5], [6, 7, 8]],
                                                        [[12, 13, 14], [15, 16, 17]]]
    for words in (17, 19, 12):
        with pytest.raises(RawDataLayoutError, match=(
                rf"^raw buffer has {words} words; 2 raw frames of 3 x 2 plus one pseudo-data "
                r"row each need 18$")) as info:
            split_raw_buffer(np.zeros(words, np.uint16), 2, 3, 2)
        assert info.value.kind == "protocol" and isinstance(info.value, BridgeError)


def test_a_frame_message_round_trip_and_a_short_payload():
    rng = np.random.default_rng(5)
    data = RawDataCopy(width=4, height=3, raw_frames=rng.integers(0, 4096, (5, 3, 4), np.uint16),
                       modulation_frequencies_hz=(60_240_000, 60_240_000),
                       exposure_times_us=(500, 500), raw_frame_count=(1, 4),
                       exposure_group_names=("gray", "mod6024"),
                       phase_angles_deg=(0, 0, 90, 180, 270), illumination_enabled=(0, 1, 1, 1, 1),
                       timestamp_us=1_700_000_000_000_001, illumination_temperature_c=31.5,
                       stream_id=3)
    a, b = socket.socketpair()
    with a, b:
        message, payload = frame_message(data, seq=4, camera=CAMERA_ID)
        a.sendall(encode_message(message, payload))
        got, got_payload = read_message(b)
    back = raw_data_from_message(got, got_payload)
    assert (got["op"], got["seq"], got["camera"], got["n_raw"]) == ("frame", 4, CAMERA_ID, 5)
    assert got_payload == data.raw_frames.astype("<u2").tobytes()
    assert np.array_equal(back.raw_frames, data.raw_frames)
    assert {**back.__dict__, "raw_frames": None} == {**data.__dict__, "raw_frames": None}
    with pytest.raises(BridgeError, match="frame payload has 6 bytes; 5 raw frames of 4 x 3"):
        raw_data_from_message(message, payload[:6])


# -- BridgeServer, driven by a plain socket client -----------------------------------------------
class Client:
    """A client of the bridge's protocol written with the bridge's wire functions only."""

    def __init__(self, address: Any) -> None:
        self.sock = socket.create_connection(address, timeout=WAIT_S)
        self._ids = itertools.count(1)
        self.pushed: deque = deque()  # frames and events read while waiting for a reply

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()

    def send(self, op: str, **fields: Any) -> int:
        request_id = next(self._ids)
        self.sock.sendall(encode_message({"op": op, "id": request_id, **fields}))
        return request_id

    def request(self, op: str, **fields: Any) -> dict:
        request_id = self.send(op, **fields)
        while True:
            message, payload = read_message(self.sock)
            if message["op"] == "reply":
                assert message["id"] == request_id, message
                return message
            assert message["op"] in ("frame", "event"), message
            self.pushed.append((message, payload))

    def ok(self, op: str, **fields: Any) -> Any:
        reply = self.request(op, **fields)
        assert reply["ok"] is True and "error" not in reply, reply
        return reply["result"]

    def error(self, op: str, **fields: Any) -> dict:
        reply = self.request(op, **fields)
        assert reply["ok"] is False, reply
        assert reply["error"]["kind"] in bridge.ERROR_KINDS
        return reply["error"]

    def push(self) -> tuple[dict, bytes]:
        """The next frame or event (those read while waiting for a reply first)."""
        if self.pushed:
            return self.pushed.popleft()
        message, payload = read_message(self.sock)
        assert message["op"] in ("frame", "event"), message
        return message, payload

    def frame(self) -> tuple[dict, RawDataCopy]:
        message, payload = self.push()
        assert message["op"] == "frame", message
        return message, raw_data_from_message(message, payload)

    def silent_for(self, seconds: float) -> bool:
        """True when nothing arrives for ``seconds`` (nothing was pending either)."""
        if self.pushed:
            return False
        self.sock.settimeout(seconds)
        try:
            return not self.sock.recv(1, socket.MSG_PEEK)
        except socket.timeout:  # noqa: UP041 - on Python 3.8/3.9 it is no TimeoutError
            return True
        finally:
            self.sock.settimeout(WAIT_S)

    def closed_by_the_bridge(self) -> bool:
        """True when the bridge closed the connection (read to its end within WAIT_S)."""
        deadline = time.monotonic() + WAIT_S
        try:
            while time.monotonic() < deadline:
                if not self.sock.recv(1 << 16):
                    return True
        except ConnectionError:
            return True
        return False


@contextlib.contextmanager
def serving(access_code: Any = DOUBLE.L2_CODE):
    server = BridgeServer(lambda on_frame: RoyaleSource(double, on_frame, access_code),
                          "127.0.0.1", 0).start()
    try:
        yield server
    finally:
        server.close()


@contextlib.contextmanager
def client_of(server: BridgeServer):
    client = Client(server.address)
    try:
        yield client
    finally:
        client.close()


@pytest.mark.parametrize("grey_last", [False, True], ids=["grey-first", "grey-last"])
@pytest.mark.parametrize("use_case", [MODE5, MODE9])
def test_a_plain_client_gets_royales_frames_through_the_bridge(royale35, use_case, grey_last):
    _grey_order(use_case, grey_last)
    with serving() as server, client_of(server) as client:
        hello = client.ok("hello", protocol=PROTOCOL_VERSION)
        assert hello == {"protocol": PROTOCOL_VERSION, "bridge": bridge.__version__,
                         "python": platform.python_version(), "backend": "roypy",
                         "royale": double.getVersionString()}
        assert client.ok("list_cameras") == [CAMERA_ID]
        ident = client.ok("open", camera=None, use_case=use_case,
                          exposure_us=EXPOSURE_US[use_case])
        assert (ident["id"], ident["name"]) == (CAMERA_ID, "PICOFLEXX")
        assert ident["use_cases"] == list(double.PICO_FLEXX_USE_CASES)
        device = DOUBLE.devices[-1]
        assert device.getCurrentUseCase() == use_case and not device.isCapturing()
        assert client.ok("start") is None
        frames = [client.frame() for _ in range(3)]
        assert client.ok("stop") is None
        assert not device.isCapturing()
        # frames the bridge had queued before the stop may still come; then nothing
        deadline = time.monotonic() + WAIT_S
        while not client.silent_for(0.4):
            assert time.monotonic() < deadline
            client.frame()
        assert client.ok("close") is None
        assert client.error("start") == {"kind": "not_found", "message": "no camera is open"}
    assert [m["seq"] for m, _ in frames] == [1, 2, 3]
    indices = []
    for message, data in frames:
        assert (message["camera"], message["n_raw"]) == (CAMERA_ID, sum(LAYOUT[(use_case,
                                                                                 grey_last)][0]))
        assert isinstance(message["dropped"], int) and message["dropped"] >= 0
        indices.append(_check_copy(data, royale35, use_case, grey_last))
    assert indices == sorted(set(indices))
    assert server.source.callback_errors == []


def test_the_bridge_answers_bad_requests_and_keeps_the_connection(royale35):
    with serving() as server, client_of(server) as client:
        error = client.error("hello", protocol=PROTOCOL_VERSION + 1)
        assert error["kind"] == "protocol" and f"speaks {PROTOCOL_VERSION}" in error["message"]
        assert client.error("bogus") == {"kind": "protocol", "message": "unknown op 'bogus'"}
        assert client.error("use_case", name=MODE9)["kind"] == "not_found"  # nothing open
        error = client.error("open", camera="nope")
        assert error["kind"] == "not_found" and "'nope' not among" in error["message"]
        client.ok("open", camera=CAMERA_ID, use_case=MODE5)
        error = client.error("use_case", name="MODE_MIXED_30_5")
        assert error["kind"] == "input" and "is not offered" in error["message"]
        error = client.error("exposure", us=5000)
        assert error["kind"] == "error" and "EXPOSURE_TIME_NOT_SUPPORTED" in error["message"]
        assert client.error("attach_world", url="tcp://x:1")["kind"] == "input"
        assert abs(client.ok("ping")["time_s"] - time.time()) < 60  # still connected
        assert DOUBLE.devices[-1].getCurrentUseCase() == MODE5  # the bad requests changed nothing
        client.ok("start")
        client.ok("use_case", name=MODE9)  # switched while streaming: the stream goes on
        deadline = time.monotonic() + WAIT_S
        while client.frame()[1].raw_frames.shape[0] != 9:
            assert time.monotonic() < deadline


@pytest.mark.parametrize("garbage", [
    b"GET / HTTP/1.1\r\n\r\n",  # another protocol
    bridge.MAGIC + (5).to_bytes(4, "big") + bytes(4) + b"{nope",  # not JSON
    bridge.MAGIC + (2).to_bytes(4, "big") + bytes(4) + b"[]",  # not an object with an op
    bridge.MAGIC + (bridge.MAX_JSON_BYTES + 1).to_bytes(4, "big") + bytes(4),  # too large
], ids=["http", "not-json", "no-op", "too-large"])
def test_bytes_that_are_no_message_are_answered_then_the_connection_closes(royale35, garbage):
    with serving() as server:
        with client_of(server) as client:
            client.ok("open", use_case=MODE5)
            client.ok("start")
            client.frame()
            client.sock.sendall(garbage)
            while True:  # frames sent before the bridge read the garbage come first
                message, _ = read_message(client.sock)
                if message["op"] == "reply":
                    break
            assert (message["id"], message["ok"], message["error"]["kind"]) == (
                None, False, "protocol")
            assert client.closed_by_the_bridge()
        deadline = time.monotonic() + WAIT_S
        while DOUBLE.devices[-1].isCapturing():  # the client went: the stream stops
            assert time.monotonic() < deadline
            time.sleep(0.01)
        with client_of(server) as again:  # and the bridge serves the next one
            assert again.ok("hello", protocol=PROTOCOL_VERSION)["protocol"] == PROTOCOL_VERSION
            assert again.ok("open")["id"] == CAMERA_ID
            assert len(DOUBLE.devices) == 1  # the camera stayed open for it
            again.ok("start")
            assert again.frame()[1].raw_frames.shape[0] == 5


def test_one_client_at_a_time_a_new_one_replaces_the_old(royale35):
    with serving() as server, client_of(server) as old:
        old.ok("open", use_case=MODE9)
        old.ok("start")
        old.frame()
        with client_of(server) as new:
            assert new.ok("ping")  # the bridge took the new one
            assert old.closed_by_the_bridge()
            assert not DOUBLE.devices[-1].isCapturing()  # the old one's stream stopped
            assert new.ok("open")["id"] == CAMERA_ID and len(DOUBLE.devices) == 1
            new.ok("start")
            _, data = new.frame()
            assert data.raw_frames.shape[0] == 9  # the use case the camera kept


def test_a_camera_unplugged_mid_stream_is_an_event_and_the_bridge_serves_on(royale35):
    DOUBLE.plug(CAMERA_ID, unplug_after_frames=3)  # pulled after its third frame
    with serving() as server:
        with client_of(server) as client:
            client.ok("open", use_case=MODE9, exposure_us=EXPOSURE_US[MODE9])
            client.ok("start")
            frames, events = [], []
            while not (events and events[-1][0] == 3):  # an event after the third frame
                message, payload = client.push()
                if message["op"] == "frame":
                    frames.append((message["seq"], raw_data_from_message(message, payload)))
                else:
                    events.append((frames[-1][0] if frames else 0, message))
            assert [seq for seq, _ in frames] == [1, 2, 3]
            assert [_check_copy(d, royale35, MODE9, False) for _, d in frames] == [0, 1, 2]
            assert events[-1][1] == {"op": "event", "kind": "disconnected", "camera": CAMERA_ID,
                                     "message": "the camera is no longer connected"}
            assert client.silent_for(0.5)  # told once
            assert client.ok("list_cameras") == []
            error = client.error("stop")  # royale's stopCapture fails on a pulled camera
            assert error["kind"] == "disconnected" and "DISCONNECTED" in error["message"]
            assert client.ok("close") is None
            assert client.error("open")["kind"] == "not_found"
        DOUBLE.plug(CAMERA_ID)  # plugged in again
        with client_of(server) as again:  # a new client, the same bridge
            assert again.ok("hello", protocol=PROTOCOL_VERSION)["protocol"] == PROTOCOL_VERSION
            assert again.ok("open", use_case=MODE5)["id"] == CAMERA_ID
            again.ok("start")
            message, data = again.frame()
            assert message["seq"] == 4 and data.raw_frames.shape[0] == 5
            assert len(DOUBLE.devices) == 2  # a new royale device for the camera


def test_data_raising_in_royales_callback_under_the_bridge(royale35):
    DOUBLE.listener_error_policy = "stop"
    DOUBLE.fail_next_data(2, where="getRawPhase")
    with serving() as server, client_of(server) as client:
        client.ok("open", use_case=MODE9, exposure_us=EXPOSURE_US[MODE9])
        client.ok("start")
        frames, lost, deadline = [], [], time.monotonic() + WAIT_S
        while (len(frames) < 3 or sum(lost) < 2) and time.monotonic() < deadline:
            message, payload = client.push()
            if message["op"] == "frame":
                frames.append((message, raw_data_from_message(message, payload)))
                continue
            # the client is told of every lost frame: an error event, the last error named
            assert (message["kind"], message["camera"]) == ("error", CAMERA_ID), message
            found = re.match(r"^(\d+) frame\(s\) lost in royale's callback; the last: .*"
                             r"injected failure", message["message"])
            assert found, message
            lost.append(int(found.group(1)))
        errors = list(server.source.callback_errors)
    assert [m["seq"] for m, _ in frames[:3]] == [1, 2, 3]
    assert [_check_copy(d, royale35, MODE9, False) for _, d in frames[:3]] == [2, 3, 4]
    assert len(errors) == 2 and all("injected failure" in e for e in errors)
    assert sum(lost) == 2  # each told once
    assert DOUBLE.listener_errors == []  # nothing raised into royale's thread


def test_a_camera_pulled_and_plugged_in_again_is_opened_anew_without_a_close(royale35):
    """The service, told the camera is gone, asks for it again (``open``) until it is back:
    the bridge must not hand it royale's dead device of before."""
    DOUBLE.plug(CAMERA_ID, unplug_after_frames=2)
    with serving() as server, client_of(server) as client:
        client.ok("open", use_case=MODE9, exposure_us=EXPOSURE_US[MODE9])
        client.ok("start")
        while client.push()[0]["op"] != "event":  # its two frames, then the event
            pass
        assert client.error("open")["kind"] == "not_found"  # not back yet
        DOUBLE.plug(CAMERA_ID)
        assert client.ok("open", use_case=MODE5)["id"] == CAMERA_ID
        assert len(DOUBLE.devices) == 2 and DOUBLE.devices[-1].isConnected()
        client.ok("start")
        message, data = client.frame()
        assert data.raw_frames.shape[0] == 5 and message["seq"] == 3


def test_a_flat_buffer_holding_another_number_of_frames_than_royale_counts_is_refused(
        monkeypatch):
    """Without ``getRawPhase`` the flat buffer is split into the ``sum(rawFrameCount)`` frames
    royale counts, never into as many as happen to fit."""
    _setup_double(5, monkeypatch)
    DOUBLE.expose_flat_raw_data = True
    results: list = []

    class OneFrameLess(_WithoutGetRawPhase):
        @property
        def rawData(self) -> Any:
            return np.asarray(self._raw.rawData, dtype=np.uint16)[: 8 * W * (H + 1)]

    class Listener(double.IRawDataListener):  # type: ignore[name-defined]
        def onNewData(self, data: Any) -> None:  # the data live only inside the callback
            whole = copy_roypy_raw_data(_WithoutGetRawPhase(data))
            try:
                copy_roypy_raw_data(OneFrameLess(data))
            except RawDataLayoutError as exc:
                results.append((whole, str(exc)))
            else:
                results.append((whole, None))

    _stream_mode9_until(Listener(), results)
    assert results and DOUBLE.listener_errors == []
    whole, refused = results[0]
    assert whole.raw_frames.shape == (9, H, W)
    assert refused is not None and refused.startswith(
        f"raw buffer has {8 * W * (H + 1)} words; 9 raw frames of {W} x {H}"), refused


# -- the bridge as a program ---------------------------------------------------------------------
def _env(pythonpath: str) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["PYTHONPATH"] = pythonpath
    return env


def test_the_bridge_without_roypy_exits_2_saying_where_roypy_comes_from():
    # the repository's root on the path (its tests/ package holds the double, but no roypy)
    out = subprocess.run([sys.executable, str(BRIDGE_FILE), "--port", "0"], cwd=str(ROOT),
                         env=_env(str(ROOT)), capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, out.stdout + out.stderr
    assert out.stderr.startswith("toftwin-camera-bridge: royale not installed: cannot import "
                                 "roypy"), out.stderr
    for words in ("royale SDK", "pmdtec.com", "not on PyPI", "PYTHONPATH", "import roypy"):
        assert words in out.stderr, out.stderr


def test_the_bridge_started_as_a_lab_starts_it_imports_roypy_and_streams():
    """``PYTHONPATH=<royale>/python python toftwin_camera_bridge.py``, the double as roypy."""
    program = (
        "import runpy, sys\n"
        "import roypy\n"  # the double, from PYTHONPATH, as PMD's roypy would be
        "assert roypy.__file__.startswith(sys.argv[2]), roypy.__file__\n"
        "roypy.DOUBLE.frame_interval_s = 0.01\n"
        "roypy.DOUBLE.plug()\n"
        "sys.argv = [sys.argv[1], '--host', '127.0.0.1', '--port', '0']\n"
        "runpy.run_path(sys.argv[0], run_name='__main__')\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", program, str(BRIDGE_FILE), str(DOUBLE_DIR)],
                            cwd=str(ROOT), env=_env(str(DOUBLE_DIR)), stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines: queue.Queue = queue.Queue()
    log: list = []

    def read_log() -> None:
        assert proc.stderr is not None
        for line in proc.stderr:
            log.append(line)
            lines.put(line)

    threading.Thread(target=read_log, daemon=True).start()
    try:
        port, deadline = None, time.monotonic() + 30
        while port is None:
            try:
                line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                pytest.fail(f"the bridge did not say where it listens: {''.join(log)}")
            found = re.search(r"camera bridge listening on 127\.0\.0\.1:(\d+) \(roypy\)", line)
            port = int(found.group(1)) if found else None
        client = Client(("127.0.0.1", port))
        try:
            hello = client.ok("hello", protocol=PROTOCOL_VERSION)
            assert (hello["royale"], hello["python"]) == ("5.4.0.2112",
                                                          platform.python_version())
            assert client.ok("list_cameras") == [CAMERA_ID]
            client.ok("open", use_case=MODE9)
            client.ok("start")
            for _ in range(2):
                _, data = client.frame()
                grey = int(data.raw_frames[0, 0, 0])  # the double's default pattern
                index = grey - 3000
                assert 0 <= index < 32 and data.raw_frames.shape == (9, H, W)
                assert data.raw_frames[:, :, 1::2].tolist() == (
                    data.raw_frames[:, :, 0::2] + 1).tolist()
                assert data.raw_frame_count == (1, 4, 4)
            client.ok("stop")
        finally:
            client.close()
    finally:
        proc.terminate()
        proc.wait(timeout=WAIT_S)
    assert proc.returncode != 2, "".join(log)


# -- royale's processed depth (IDepthDataListener) ------------------------------------------------
def _check_depth(data: Any, generation: int) -> None:
    """``data`` is the double's wall at ``DOUBLE.depth_m`` as royale of ``generation`` gives it:
    points on the lens's rays, royale 4's noise channel (0), none before or after (NaN), the
    grey frame's values, confidence scaled to 1."""
    assert isinstance(data, bridge.DepthDataCopy)
    assert (data.width, data.height) == (W, H)
    assert data.points.shape == (H, W, 6) and data.points.dtype == np.float32
    x, y, z, noise, grey, confidence = (data.points[..., k] for k in range(6))
    assert np.allclose(z, DOUBLE.depth_m)
    lens = DOUBLE.lens
    v, u = np.mgrid[0:H, 0:W]
    assert np.allclose(x, (u - lens["cx"]) / lens["fx"] * z, atol=1e-6)
    assert np.allclose(y, (v - lens["cy"]) / lens["fy"] * z, atol=1e-6)
    assert (noise == 0).all() if generation == 4 else np.isnan(noise).all()
    assert grey.min() >= 0 and grey.max() <= 4095 and grey.std() > 0
    assert (confidence == 1.0).all()
    assert isinstance(data.timestamp_us, int)
    if generation >= 5:
        assert data.illumination_temperature_c == _temperature(_index_of(data))


@pytest.mark.parametrize("use_case", [MODE5, MODE9])
def test_royale_source_streams_royales_processed_depth(royale, use_case):
    """``mode="depth"``: ``IDepthDataListener`` (no access code needed) for royale 3 (the
    per-point getters), 4 (``npoints()`` with a noise channel) and 5 (``npoints()`` without,
    confidence 0..1)."""
    DOUBLE.depth_m = 0.75
    got: queue.Queue = queue.Queue()
    source = RoyaleSource(double, got.put, None, mode="depth")
    ident = source.open()
    assert ident["mode"] == "depth" and source.mode == "depth"
    source.set_use_case(use_case)
    source.start()
    copies = [got.get(timeout=WAIT_S) for _ in range(2)]
    source.stop()
    for data in copies:
        _check_depth(data, DOUBLE.generation)
    assert source.callback_errors == [] and DOUBLE.listener_errors == []
    # open again in raw mode: the raw listener replaces the depth one
    source.access_code = DOUBLE.L2_CODE
    assert source.open(None, "raw")["mode"] == "raw"
    source.start()
    assert isinstance(got_after(got, RawDataCopy), RawDataCopy)
    source.close()
    with pytest.raises(BridgeError, match="mode 'phase'") as info:
        source.open(None, "phase")
    assert info.value.kind == "input"


def got_after(got: queue.Queue, kind: type) -> Any:
    """The first copy of ``kind`` (those of the mode before a switch may still come)."""
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        data = got.get(timeout=WAIT_S)
        if isinstance(data, kind):
            return data
    raise AssertionError(f"no {kind.__name__} within {WAIT_S} s")


def test_a_plain_client_gets_royales_processed_depth_through_the_bridge(royale35):
    with serving() as server, client_of(server) as client:
        client.ok("hello", protocol=PROTOCOL_VERSION)
        ident = client.ok("open", camera=None, use_case=MODE5, mode="depth")
        assert ident["mode"] == "depth"
        assert client.ok("start") is None
        for _ in range(2):
            message, payload = client.push()
            assert message["op"] == "frame" and message["kind"] == "depth", message
            assert len(payload) == 4 * 6 * W * H
            _check_depth(bridge.data_from_message(message, payload), DOUBLE.generation)
        client.ok("stop")
        assert client.error("open", camera=None, mode="phase")["kind"] == "input"
    garbled = {"op": "frame", "kind": "depth", "width": W, "height": H}
    with pytest.raises(BridgeError, match="depth payload has 8 bytes") as info:
        bridge.data_from_message(garbled, b"\0" * 8)
    assert info.value.kind == "protocol"
