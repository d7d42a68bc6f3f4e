"""The camera bridge (``toftwin_camera_bridge``) and its client (``BridgeCamera``) end to end.

The bridge serves :class:`toftwin_camera_bridge.RoyaleSource` over the roypy conformance double
(``tests/roypy_double``: only the third-party SDK is replaced) on a real TCP socket; the client
is the service's :class:`drivers.camera.bridge_client.BridgeCamera`. Frames through the bridge
must equal the frames royale gave; the bridge going away mid-stream must fail the capture naming
the camera and the bridge, and the camera must work again once a bridge is back on the port.
"""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest

from drivers.camera import CameraError, CameraNotFoundError, CameraProtocol
from drivers.camera.bridge_client import BridgeCamera, parse_bridge_url
from drivers.camera.wire import USE_CASES
from drivers.errors import DeviceInputError
from tests.drivers.camera.test_royale_double import _expected_phases, _frame_index
from tests.roypy_double import roypy as double
from toftwin_camera_bridge import (
    BridgeError,
    BridgeServer,
    RawDataCopy,
    RoyaleSource,
    encode_message,
    frame_message,
    main,
    raw_data_from_message,
    read_message,
)

pytestmark = pytest.mark.timeout(30)

DOUBLE = double.DOUBLE
CAMERA_ID = double.DEFAULT_CAMERA_ID
MODE5 = USE_CASES["MODE_5_45FPS_500"]
MODE9 = USE_CASES["MODE_9_5FPS_2000"]


@pytest.fixture(params=[3, 5], ids=lambda g: f"royale{g}")
def generation(request: pytest.FixtureRequest):
    """The double for one raw-data generation (3: extended data, 5: raw-data listener)."""
    DOUBLE.reset(generation=request.param)
    DOUBLE.frame_interval_s = 0.01
    DOUBLE.plug(CAMERA_ID)
    yield request.param
    DOUBLE.reset()


def _server(port: int = 0) -> BridgeServer:
    return BridgeServer(lambda on_frame: RoyaleSource(double, on_frame, DOUBLE.L2_CODE),
                        "127.0.0.1", port).start()


def _url(server: BridgeServer) -> str:
    return f"tcp://127.0.0.1:{server.address[1]}"


# -- the wire format ---------------------------------------------------------------------------
def _copy(n: int = 9) -> RawDataCopy:
    rng = np.random.default_rng(3)
    return RawDataCopy(
        width=5, height=4, raw_frames=rng.integers(0, 4096, (n, 4, 5), dtype=np.uint16),
        modulation_frequencies_hz=(80_320_000,) * 4 + (60_240_000,) * 4 + (60_240_000,),
        exposure_times_us=(1000,) * n, raw_frame_count=(4, 4, 1),
        exposure_group_names=("mod80", "mod60", "gray"), phase_angles_deg=(0, 90, 180, 270) * 2
        + (0,), illumination_enabled=(1,) * 8 + (0,), timestamp_us=1_700_000_000_000_000,
        illumination_temperature_c=37.25, stream_id=7)


def test_a_frame_crosses_the_wire_unchanged():
    data = _copy()
    a, b = socket.socketpair()
    with a, b:
        message, payload = frame_message(data, seq=12, camera="cam")
        a.sendall(encode_message(message, payload))
        got_message, got_payload = read_message(b)
    back = raw_data_from_message(got_message, got_payload)
    assert (got_message["op"], got_message["seq"], got_message["camera"]) == ("frame", 12, "cam")
    assert np.array_equal(back.raw_frames, data.raw_frames)
    assert {**back.__dict__, "raw_frames": None} == {**data.__dict__, "raw_frames": None}


def test_bytes_of_another_protocol_and_short_payloads_are_refused():
    a, b = socket.socketpair()
    with a, b:
        a.sendall(b"HTTP" + bytes(8))
        with pytest.raises(BridgeError, match="not a toftwin camera bridge message") as info:
            read_message(b)
    assert info.value.kind == "protocol"
    message, payload = frame_message(_copy(), 1, "cam")
    with pytest.raises(BridgeError, match="frame payload has 10 bytes; 9 raw frames of 5 x 4"):
        raw_data_from_message(message, payload[:10])


def test_a_bridge_url_names_the_field_and_the_form():
    assert parse_bridge_url("tcp://10.0.0.2:5600") == ("10.0.0.2", 5600)
    for bad in ("10.0.0.2:5600", "tcp://host", "tcp://host:0", "udp://host:5600"):
        with pytest.raises(DeviceInputError, match=r"^camera: got .*tcp://HOST:PORT"):
            BridgeCamera(bad)


# -- the camera through the bridge ----------------------------------------------------------------
@pytest.mark.parametrize("uc", [MODE5, MODE9], ids=lambda u: u.name)
def test_frames_through_the_bridge_are_royales(generation, uc):
    with _server() as server, BridgeCamera(_url(server), use_case=uc, frame_timeout_s=2.0) as cam:
        assert isinstance(cam, CameraProtocol)
        frames = cam.capture(3)
        ident = cam.identity()
    for frame in frames:
        assert np.array_equal(frame.phase_images, _expected_phases(uc, _frame_index(frame)))
        assert np.allclose(frame.frequencies_hz, uc.frequencies_hz)
        assert 30.0 <= frame.illumination_temperature_c <= 32.0  # the double's warm-up
    assert (ident.serial, ident.model, ident.backend) == (CAMERA_ID, "PICOFLEXX", "bridge")
    assert DOUBLE.devices[-1].getCurrentUseCase() == uc.name
    assert not DOUBLE.devices[-1].isCapturing()  # the one-shot capture stopped the stream


def test_streaming_through_the_bridge_and_a_use_case_switch(generation):
    with _server() as server, BridgeCamera(_url(server), use_case=MODE5) as cam:
        cam.start()
        first, second = cam.capture(2)
        assert _frame_index(second) > _frame_index(first) or _frame_index(second) == 0
        cam.configure(MODE9)
        assert cam.capture(1)[0].phase_images.shape[0] == 2
        cam.stop()


def test_the_bridges_errors_reach_the_service_as_the_drivers(generation):
    DOUBLE.plug(CAMERA_ID, use_cases=[MODE9.name])  # a camera offering one use case
    with _server() as server:
        with pytest.raises(DeviceInputError, match=r"^use_case: .*'MODE_5_45FPS_500' is not"):
            BridgeCamera(_url(server), use_case=MODE5).connect()
        DOUBLE.unplug(CAMERA_ID)
        with pytest.raises(CameraNotFoundError, match="royale sees no camera"):
            BridgeCamera(_url(server)).connect()


def test_the_bridge_killed_mid_stream_then_back(generation):
    server = _server()
    port = server.address[1]
    cam = BridgeCamera(_url(server), use_case=MODE5, frame_timeout_s=0.5, connect_timeout_s=1)
    cam.connect()
    cam.start()
    assert len(cam.capture(2)) == 2
    server.close()  # the bridge (or its SDK) dies
    t0 = time.monotonic()
    with pytest.raises(CameraError, match=rf"{CAMERA_ID} at camera bridge tcp://127.0.0.1:{port}"):
        for _ in range(50):  # frames already queued are still good
            cam.capture(1)
    with pytest.raises(CameraError, match="cannot be reached"):
        cam.capture(1)  # nothing listens: named, never hangs
    assert time.monotonic() - t0 < 10.0
    with _server(port):  # the bridge is back on its port
        frames = cam.capture(2)
        assert len(frames) == 2 and frames[0].meta["device"] == CAMERA_ID
    cam.close()


def test_a_new_client_replaces_a_lost_one(generation):
    with _server() as server:
        old = BridgeCamera(_url(server), use_case=MODE5, frame_timeout_s=1.0)
        old.connect()  # a service that restarted without closing its connection
        with BridgeCamera(_url(server), use_case=MODE9, frame_timeout_s=2.0) as new:
            assert new.capture(1)[0].phase_images.shape[0] == 2
            assert not old._source.is_connected()  # the bridge dropped it for the new one
        frame = old.capture(1)[0]  # and it connects again with its own use case
        assert frame.phase_images.shape[0] == 1
        old.close()


def test_the_bridge_without_roypy_says_how_to_get_it(capsys):
    assert main(["--port", "0"]) == 2
    assert "royale not installed: cannot import roypy" in capsys.readouterr().err
