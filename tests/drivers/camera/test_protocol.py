"""Contract suite: what the rest of the code may rely on from any camera driver.

Every backend must implement :class:`drivers.camera.CameraProtocol` this way.

Runs against the simulated pico flexx through the real pyusb driver (instant and paced at the
use case's frame rate) and, where royale is installed and a camera is connected, against real
hardware through :class:`drivers.camera.RoyaleCamera` (otherwise that backend is not
collected, so a machine without it reports no skipped tests):

    TOFTWIN_ROYALE_CAMERA=<camera id or "first">  [TOFTWIN_ROYALE_ACCESS_CODE=...]

The hardware case only needs the camera to look at something; it checks form, not content.
"""

from __future__ import annotations

import os
from collections.abc import Iterator

import numpy as np
import pytest

from drivers.camera import (
    USE_CASES,
    CameraProtocol,
    RoyaleCamera,
    UsbCamera,
    UsbCameraSettings,
    royale_available,
)
from drivers.errors import DeviceInputError
from drivers.sim.usb_camera import UsbCameraSim, plane_source

pytestmark = pytest.mark.timeout(20)


def _hardware_present() -> bool:
    if not royale_available():
        return False
    if "TOFTWIN_ROYALE_CAMERA" in os.environ:
        return True
    try:  # only reached where roypy imports
        import roypy  # type: ignore[import-not-found]

        return len(list(roypy.CameraManager().getConnectedCameraList())) > 0
    except Exception:
        return False


BACKENDS = ["sim", "sim-paced"] + (
    [pytest.param("royale", marks=pytest.mark.timeout(120))] if _hardware_present() else []
)


@pytest.fixture(params=BACKENDS)
def camera(request: pytest.FixtureRequest) -> Iterator[CameraProtocol]:
    if request.param == "royale":
        cam_id = os.environ.get("TOFTWIN_ROYALE_CAMERA", "first")
        device: CameraProtocol = RoyaleCamera(
            None if cam_id == "first" else cam_id, frame_timeout_s=5.0
        )
    else:
        sim = UsbCameraSim(
            plane_source(1.0), seed=3, instant=request.param == "sim", serial="0005-CONTRACT"
        )
        device = UsbCamera(backend=sim, settings=UsbCameraSettings(read_timeout_s=1.0))
    device.connect()  # type: ignore[attr-defined]
    yield device
    device.close()


def _check_frame(frame, use_case) -> None:
    n_f = use_case.n_frequencies
    assert frame.phase_images.shape == (n_f, 4, 171, 224)
    assert frame.phase_images.dtype == np.float32
    assert frame.intensity.shape == (171, 224) and frame.intensity.dtype == np.float32
    assert frame.saturated.shape == frame.sbi_limit.shape == (171, 224)
    assert frame.saturated.dtype == frame.sbi_limit.dtype == bool
    assert np.allclose(frame.frequencies_hz, use_case.frequencies_hz, atol=1.0)
    assert frame.exposure_s > 0 and frame.timestamp_s > 1e9
    # C = raw - 2048 of 12-bit raw values
    assert frame.phase_images.min() >= -2048 and frame.phase_images.max() <= 2047
    assert np.all(frame.phase_images == np.round(frame.phase_images))


def test_implements_the_protocol_and_identifies_itself(camera):
    assert isinstance(camera, CameraProtocol)
    ident = camera.identity()
    assert ident.serial and ident.model
    assert ident.backend in ("pyusb", "royale")


@pytest.mark.parametrize("name", sorted(USE_CASES))
def test_each_use_case_gives_frames_of_its_form(camera, name):
    camera.configure(name)
    assert camera.use_case.name == name
    frames = camera.capture(3)
    assert len(frames) == 3
    for frame in frames:
        _check_frame(frame, USE_CASES[name])
    stamps = [f.timestamp_s for f in frames]
    assert stamps == sorted(stamps)


def test_streaming_capture_returns_successive_frames(camera):
    camera.start()
    camera.start()  # idempotent
    first = camera.capture(2)
    second = camera.capture(2)
    camera.stop()
    camera.stop()  # idempotent
    stamps = [f.timestamp_s for f in first + second]
    assert stamps == sorted(stamps) and stamps[0] < stamps[-1]


def test_one_shot_capture_works_after_stop(camera):
    camera.start()
    camera.stop()
    assert len(camera.capture(1)) == 1


def test_bad_requests_are_refused_naming_the_field(camera):
    with pytest.raises(DeviceInputError, match=r"^n: got 0"):
        camera.capture(0)
    with pytest.raises(DeviceInputError, match=r"^use_case: got 'MODE_0'"):
        camera.configure("MODE_0")
    assert len(camera.capture(1)) == 1  # still usable


def test_close_is_idempotent(camera):
    camera.close()
    camera.close()
