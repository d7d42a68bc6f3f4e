"""RoyaleCamera against the roypy conformance double (``tests/roypy_double/roypy.py``).

The double imitates roypy's Python surface for royale 3.x, 4.x and 5.x as PMD's samples and
headers describe it (its module docstring cites each file). Only the third-party SDK is replaced:
``drivers.camera.royale.roypy`` is pointed at the double; all of our code runs as it is.

The double is imported as ``tests.roypy_double.roypy`` (a package module), never as a top-level
``roypy``: that would make ``royale_available()`` true for the rest of the session.
"""

from __future__ import annotations

import ast
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from drivers.camera import CameraError, CameraNotFoundError, CameraProtocol
from drivers.camera import royale as royale_backend
from drivers.camera.royale import RoyaleCamera, copy_roypy_raw_data, split_raw_buffer
from drivers.camera.wire import RAW_OFFSET, USE_CASES
from drivers.errors import DeviceInputError
from tests.roypy_double import roypy as double

pytestmark = pytest.mark.timeout(20)

DOUBLE = double.DOUBLE
CAMERA_ID = double.DEFAULT_CAMERA_ID
MODE5 = USE_CASES["MODE_5_45FPS_500"]
MODE9 = USE_CASES["MODE_9_5FPS_2000"]
DOUBLE_DIR = Path(double.__file__).parent


@pytest.fixture(params=[3, 4, 5], ids=lambda g: f"royale{g}")
def generation(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch):
    """The double as ``roypy`` for one royale generation, fast frames, one camera plugged."""
    DOUBLE.reset(generation=request.param)
    DOUBLE.frame_interval_s = 0.01
    DOUBLE.plug(CAMERA_ID)
    monkeypatch.setattr(royale_backend, "roypy", double)
    monkeypatch.delenv("TOFTWIN_ROYALE_ACCESS_CODE", raising=False)
    yield request.param
    DOUBLE.reset()  # stops any stream left running


@pytest.fixture
def gen5(monkeypatch: pytest.MonkeyPatch):
    """The double as royale 5's roypy (for the cases that are the same in every generation)."""
    DOUBLE.reset(generation=5)
    DOUBLE.frame_interval_s = 0.01
    monkeypatch.setattr(royale_backend, "roypy", double)
    monkeypatch.delenv("TOFTWIN_ROYALE_ACCESS_CODE", raising=False)
    yield 5
    DOUBLE.reset()


def _camera(use_case=MODE5, *, timeout_s: float = 1.0, **kwargs) -> RoyaleCamera:
    """A RoyaleCamera with the double's level-2 code (raw data before royale 5 needs it)."""
    kwargs.setdefault("access_code", DOUBLE.L2_CODE)
    return RoyaleCamera(use_case=use_case, frame_timeout_s=timeout_s, **kwargs)


def _frame_index(frame) -> int:
    """The double's default pattern encodes the delivery index (mod 32) in the grey image."""
    return int(frame.intensity[0, 0]) - 3000


def _expected_phases(uc, index: int) -> np.ndarray:
    """C = raw - 2048 of the default pattern, by frequency and phase step (0, 90, 180, 270)."""
    out = np.empty((uc.n_frequencies, 4, double.SENSOR_HEIGHT, double.SENSOR_WIDTH), np.float32)
    odd = (np.arange(double.SENSOR_WIDTH) % 2)[None, :]
    for k in range(uc.n_frequencies):
        for step in range(4):
            raw = 1024 + 256 * k + 64 * step + index % 32
            out[k, step] = raw + odd - RAW_OFFSET
    return out


# -- connect and identity ------------------------------------------------------------------------
def test_connect_reads_the_identity_and_sets_the_use_case(generation):
    with _camera(MODE9) as cam:
        assert isinstance(cam, CameraProtocol)
        ident = cam.identity()
        device = DOUBLE.devices[-1]
        assert device.getCurrentUseCase() == "MODE_9_5FPS_2000"
        assert device.getAccessLevel() == 2
    assert (ident.serial, ident.model, ident.product, ident.backend) == (
        CAMERA_ID,
        "PICOFLEXX",
        "PICOFLEXX",
        "royale",
    )
    assert ident.extra["IMAGER"] == "M2450_A12_AIO"
    assert not device.isCapturing()


def test_no_camera_plugged_is_camera_not_found(gen5):
    assert double.CameraManager().getConnectedCameraList().size() == 0
    with pytest.raises(CameraNotFoundError, match="royale sees no camera"):
        _camera().connect()
    DOUBLE.plug("0005-1111-2222-3333")
    with pytest.raises(CameraNotFoundError, match=r"'nope' not among \['0005-1111-2222-3333'\]"):
        RoyaleCamera("nope").connect()


# -- capture ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("uc", [MODE5, MODE9], ids=lambda u: u.name)
@pytest.mark.parametrize("grey_last", [False, True], ids=["grey-first", "grey-last"])
def test_capture_gives_the_provider_images_in_our_convention(generation, uc, grey_last):
    DOUBLE.grey_last = grey_last
    if grey_last:  # and phases out of order: RoyaleCamera must sort them by angle
        DOUBLE.phase_order = (180, 0, 270, 90)
    with _camera(uc) as cam:
        frames = cam.capture(2)
    first, second = (_frame_index(f) for f in frames)
    assert first < second <= first + 1 + cam.dropped  # in order; a loaded host may drop some
    for frame, index in zip(frames, (first, second), strict=True):
        assert frame.phase_images.dtype == np.float32
        assert np.array_equal(frame.phase_images, _expected_phases(uc, index))
        grey = np.broadcast_to(3000 + index + np.arange(224) % 2, (171, 224))
        assert np.array_equal(frame.intensity, grey)
        assert frame.frequencies_hz.tolist() == list(uc.frequencies_hz)
        assert frame.exposure_s == pytest.approx(uc.exposure_s)
        assert frame.meta["grey_index"] == (uc.n_raw_frames - 1 if grey_last else 0)
        assert frame.meta["grey_index_source"] == "exposure group of one raw frame"
        assert frame.meta["timestamp_source"] == "royale"
        assert abs(frame.timestamp_s - time.time()) < 60
        assert not frame.saturated.any()
    assert cam.callback_errors == []


def test_values_per_raw_frame_convert_like_values_per_group(generation):
    DOUBLE.values_per = "frame"
    with _camera(MODE9) as cam:
        (frame,) = cam.capture(1)
    assert np.array_equal(frame.phase_images, _expected_phases(MODE9, _frame_index(frame)))


def test_the_illumination_temperature_reaches_the_raw_frame(generation):
    DOUBLE.illumination_temperature = lambda i: 20.0 + 0.5 * (i % 32)
    with _camera(MODE5) as cam:
        frames = cam.capture(3)
    for frame in frames:
        expected = 20.0 + 0.5 * _frame_index(frame)
        assert frame.illumination_temperature_c == expected
        assert frame.meta["illumination_temperature_c"] == expected


def test_streaming_capture_and_a_use_case_switch(generation):
    with _camera(MODE5) as cam:
        cam.start()
        (a,) = cam.capture(1)
        cam.configure(MODE9)  # stops, switches, restarts
        (b,) = cam.capture(1)
        assert DOUBLE.devices[-1].isCapturing()
        cam.stop()
        assert not DOUBLE.devices[-1].isCapturing()
    assert a.phase_images.shape[0] == 1 and b.phase_images.shape[0] == 2


# -- access level ----------------------------------------------------------------------------------
@pytest.mark.parametrize("generation", [3, 4], indirect=True, ids=lambda g: f"royale{g}")
def test_raw_data_before_royale_5_without_an_access_code_is_a_clear_error(generation):
    cam = _camera(access_code=None)
    with pytest.raises(CameraError, match=r"(?s)INSUFFICIENT_PRIVILEGES.*access code.*level 2"):
        cam.connect()
    with pytest.raises(CameraError, match="TOFTWIN_ROYALE_ACCESS_CODE"):
        cam.connect()  # a failed connect leaves nothing half open


@pytest.mark.parametrize("generation", [5], indirect=True, ids=lambda g: f"royale{g}")
def test_royale_5_raw_data_needs_no_access_code(generation):
    with _camera(access_code=None) as cam:
        (frame,) = cam.capture(1)
    assert DOUBLE.devices[-1].getAccessLevel() == 1
    assert frame.phase_images.shape == (1, 4, 171, 224)


# -- unplugged mid-stream -------------------------------------------------------------------------
def test_camera_unplugged_mid_stream_fails_capture_naming_the_camera(generation):
    cam = _camera(MODE5, timeout_s=0.3)
    cam.connect()
    cam.start()
    assert len(cam.capture(2)) == 2
    DOUBLE.unplug(CAMERA_ID)
    t0 = time.monotonic()
    with pytest.raises(CameraError, match=rf"{CAMERA_ID}: disconnected"):
        for _ in range(20):  # frames delivered before the unplug are still good
            cam.capture(1)
    assert time.monotonic() - t0 < 3.0
    cam.close()  # does not raise although stopCapture fails on a disconnected camera
    if generation >= 5:
        assert DOUBLE.events[-1][1:] == (
            double.EventSeverity_ROYALE_FATAL,
            "device disconnected",
            double.EventType_ROYALE_DEVICE_DISCONNECTED,
        )


def test_camera_unplugged_during_a_one_shot_capture(generation):
    DOUBLE.reset(generation=generation)
    DOUBLE.frame_interval_s = 0.01
    DOUBLE.plug(CAMERA_ID, unplug_after_frames=2)
    with _camera(MODE9, timeout_s=0.3) as cam:
        t0 = time.monotonic()
        with pytest.raises(CameraError, match=rf"{CAMERA_ID}.*disconnected"):
            cam.capture(5)
        assert time.monotonic() - t0 < 3.0
    assert double.CameraManager().getConnectedCameraList().size() == 0


# -- callbacks that raise --------------------------------------------------------------------------
def _failing_data(where: str, n: int) -> list:
    """``n`` frames captured after the double's next two data objects raise in ``where``; the
    two failures are counted, none escaped into royale's thread."""
    DOUBLE.fail_next_data(2, where=where)
    with _camera(MODE5) as cam:
        frames = cam.capture(n)
        errors = list(cam.callback_errors)
    assert len(errors) == 2 and all("injected failure" in e for e in errors)
    assert DOUBLE.listener_errors == []  # nothing escaped into royale's thread
    assert len(frames) == n
    return frames


def test_raw_data_that_raises_is_counted_and_later_frames_arrive(generation):
    indices = [_frame_index(f) for f in _failing_data("getRawPhase", 3)]
    assert indices[0] >= 2 and indices == sorted(indices)


@pytest.mark.parametrize("generation", [3, 4], indirect=True, ids=lambda g: f"royale{g}")
def test_extended_data_that_raises_does_not_escape_into_royale(generation):
    _failing_data("hasRawData", 2)


# -- use cases -------------------------------------------------------------------------------------
def test_a_use_case_the_camera_does_not_offer_is_refused(generation):
    DOUBLE.plug(CAMERA_ID, use_cases=("MODE_9_5FPS_2000",))
    with _camera(MODE9) as cam:
        with pytest.raises(DeviceInputError, match=r"^use_case: 'MODE_5_45FPS_500' is not offered"):
            cam.configure(MODE5)
        assert cam.use_case is MODE9
        assert cam.capture(1)[0].phase_images.shape[0] == 2
    cam = _camera(MODE5)
    for _ in range(2):  # also when connecting; and nothing stays half open
        with pytest.raises(DeviceInputError, match=r"^use_case: "):
            cam.connect()


# -- the double itself: what RoyaleCamera relies on ------------------------------------------------
def test_double_keeps_streaming_when_a_listener_raises(gen5):
    DOUBLE.plug()
    seen: list[int] = []

    def on_data(data):
        seen.append(int(data.getRawPhase(0)[0]))
        if len(seen) <= 2:
            raise ValueError("listener bug")

    _stream_raw_data(on_data, lambda: len(seen) >= 4)
    assert len(seen) >= 4 and len(DOUBLE.listener_errors) == 2
    assert "ValueError: listener bug" in DOUBLE.listener_errors[0]


def test_double_surface_per_generation(generation):
    rp = double
    assert hasattr(rp, "IRawDataListener") == (generation >= 5)
    assert rp.getVersionString() == ".".join(map(str, rp.getVersion()))
    cam = rp.CameraManager(DOUBLE.L2_CODE).createCamera(CAMERA_ID)
    with pytest.raises(RuntimeError, match="DEVICE_NOT_INITIALIZED"):
        cam.getUseCases()
    cam.initialize()
    with pytest.raises(RuntimeError, match="DEVICE_ALREADY_INITIALIZED"):
        cam.initialize()
    assert cam.getCurrentUseCase() == "MODE_9_5FPS_2000"  # the first one
    assert (cam.getMaxSensorWidth(), cam.getMaxSensorHeight()) == (224, 171)
    limits = cam.getExposureLimits()
    assert (limits.first, limits.second) == (1, 2000)
    with pytest.raises(RuntimeError, match="EXPOSURE_TIME_NOT_SUPPORTED"):
        cam.setExposureTime(2001)
    with pytest.raises(RuntimeError, match="USECASE_NOT_SUPPORTED"):
        cam.setUseCase("MODE_MIXED_30_5")
    with pytest.raises(RuntimeError, match=r"LOGIC_ERROR.*no data listener"):
        cam.startCapture()
    if generation >= 4:
        assert cam.getLensParameters()["fx"] == DOUBLE.lens["fx"]
        with pytest.raises(SystemError):
            cam.asReplay()
    else:
        params = rp.LensParameters()
        cam.getLensParameters(params)
        assert params.focalLength.first == DOUBLE.lens["fx"]
        assert not hasattr(cam, "asReplay")


def test_double_recording_follows_the_record_sample(generation, tmp_path):
    stopped: list[int] = []

    class Depth(double.IDepthDataListener):
        def onNewData(self, data):
            pass

    class Stop(double.IRecordStopListener):
        def onRecordingStopped(self, frameCount):
            stopped.append(frameCount)

    cam = double.CameraManager().createCamera(CAMERA_ID)
    cam.initialize()
    depth, stop = Depth(), Stop()
    cam.registerDataListener(depth)
    cam.registerRecordListener(stop)
    cam.startCapture()
    cam.startRecording(str(tmp_path / "x.rrf"), 3, 0, 0)
    deadline = time.monotonic() + 5
    while not stopped and time.monotonic() < deadline:
        time.sleep(0.01)
    cam.stopCapture()
    assert stopped == [3] and (tmp_path / "x.rrf").exists()


def _stream_raw_data(on_data, done) -> None:
    """Stream the double's camera through a raw-data listener calling ``on_data`` until
    ``done()`` (5 s at most), then stop."""

    class Listener(double.IRawDataListener):  # type: ignore[name-defined]
        def onNewData(self, data):
            on_data(data)

    cam = double.CameraManager().createCamera(CAMERA_ID)
    cam.initialize()
    listener = Listener()
    cam.registerRawDataListener(listener)
    cam.startCapture()
    deadline = time.monotonic() + 5
    while not done() and time.monotonic() < deadline:
        time.sleep(0.01)
    cam.stopCapture()


def test_double_royale_5_flat_buffer_has_a_pseudo_row_per_raw_frame(gen5):
    DOUBLE.plug()
    DOUBLE.expose_flat_raw_data = True
    copies: list[tuple] = []

    def on_data(data):
        n = data.getNumberOfRawFrames()
        flat = split_raw_buffer(data.rawData, n, data.width, data.height)
        copies.append((copy_roypy_raw_data(data), flat, list(data.getPseudoData(0))))

    _stream_raw_data(on_data, lambda: bool(copies))
    copy, flat, pseudo = copies[0]
    assert np.array_equal(copy.raw_frames, flat) and copy.raw_frames.shape == (9, 171, 224)
    assert pseudo == [double.PSEUDO_WORD] * 224


def test_double_data_is_only_valid_inside_the_callback(gen5):
    DOUBLE.plug()
    kept: list = []

    _stream_raw_data(kept.append, lambda: bool(kept))
    with pytest.raises(RuntimeError, match="after onNewData returned"):
        kept[0].getRawPhase(0)


def test_double_needs_numpy_only_and_python_3_8_syntax():
    """What the numpy-only CI venv runs: ``import roypy`` from the directory, its self-check."""
    source = (DOUBLE_DIR / "roypy.py").read_text()
    ast.parse(source, feature_version=(3, 8))
    probe = (
        "import sys; sys.path.insert(0, sys.argv[1]); before = set(sys.modules); import roypy; "
        "new = {m.split('.')[0] for m in set(sys.modules) - before}; "
        "roypy._self_check(); "
        "print(sorted(new - set(sys.stdlib_module_names) - {'numpy', 'roypy'}))"
    )
    out = subprocess.run(
        [sys.executable, "-I", "-c", probe, str(DOUBLE_DIR)],
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
    )
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
