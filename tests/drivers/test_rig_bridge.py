"""The simulated rig with its camera behind the camera bridge (``camera_transport="bridge"``).

The rig's camera is then :class:`drivers.camera.bridge_client.BridgeCamera` on a real TCP socket
to a :class:`toftwin_camera_bridge.BridgeServer` serving the simulated camera
(:class:`drivers.sim.bridge_source.SimulatedCameraSource`) with the same frame source and the
same simulated turntable and lamp: it must give the frames the USB path gives, rendered in the
rig's state, and a bridge that dies mid-capture must fail the capture naming the camera at once.
"""

from __future__ import annotations

import numpy as np
import pytest

from drivers.camera import CameraError
from drivers.camera.bridge_client import BridgeCamera
from drivers.errors import DeviceInputError
from drivers.rig import RigState
from drivers.sim.bridge_source import SIMULATED_CAMERA_ID
from drivers.sim.rig import simulated_rig
from drivers.sim.usb_camera import CameraRequest, plane_source
from tests.drivers.helpers import free_port, simulated_bridge_process

pytestmark = pytest.mark.timeout(60)


def _angle_source():
    """A plane whose grey value is 1000 + 10 x the turntable angle the frame was rendered at."""
    plane = plane_source(1.0)

    def source(request: CameraRequest):
        frame = plane(request)
        angle = 0.0 if request.rig_state is None else request.rig_state.turntable_angle_deg
        frame.intensity[...] = 1000.0 + 10.0 * angle
        return frame

    return source


@pytest.mark.parametrize("use_case", ["MODE_5_45FPS_500", "MODE_9_5FPS_2000"])
def test_the_bridged_camera_gives_the_usb_cameras_frames(use_case):
    frames = {}
    for transport in ("usb", "bridge"):
        with simulated_rig(frame_source=plane_source(1.0), seed=7, use_case=use_case,
                           camera_transport=transport) as rig:
            rig.apply(RigState(10.0, 1.0, True))
            frames[transport] = rig.capture(1)[0]
    usb, bridged = frames["usb"], frames["bridge"]
    assert np.array_equal(bridged.phase_images, usb.phase_images)
    assert np.array_equal(bridged.intensity, usb.intensity)
    assert np.array_equal(bridged.frequencies_hz, usb.frequencies_hz)
    assert bridged.exposure_s == pytest.approx(usb.exposure_s)
    assert bridged.meta["device"] == SIMULATED_CAMERA_ID


def test_each_bridged_frame_is_rendered_in_the_rigs_state():
    with simulated_rig(frame_source=_angle_source(), seed=1, camera_transport="bridge") as rig:
        assert isinstance(rig.camera, BridgeCamera)
        for angle in (-30.0, 0.0, 45.0):
            rig.apply(RigState(angle, 0.0, False))
            frame = rig.capture(1)[0]
            assert float(frame.intensity[0, 0]) == pytest.approx(1000.0 + 10.0 * angle)


def test_a_bridge_that_dies_fails_the_capture_at_once_naming_the_camera():
    with simulated_rig(frame_source=plane_source(1.0), seed=1, camera_transport="bridge") as rig:
        rig.capture(1)
        url = rig.camera.url
        rig.sims["bridge"].close()  # the bridge (or its SDK) dies
        with pytest.raises(CameraError, match=rf"{SIMULATED_CAMERA_ID} at camera bridge {url}"):
            rig.capture(1)


def test_the_usb_cameras_faults_are_refused_on_a_bridged_camera():
    with pytest.raises(DeviceInputError, match=r"^camera_faults: "):
        simulated_rig(camera_transport="bridge", camera_faults=["drop:1"])
    with pytest.raises(DeviceInputError, match=r"^camera_transport: got 'serial'"):
        simulated_rig(camera_transport="serial")


# -- a bridge in a process of its own (``toftwin camera-bridge --simulated``) -------------------
@pytest.mark.timeout(120)
def test_a_bridge_process_films_the_rigs_world_and_comes_back_after_a_kill():
    port = free_port()
    proc = simulated_bridge_process(port)
    try:
        with simulated_rig(frame_source=_angle_source(), seed=1, camera_transport="bridge",
                           camera_bridge=f"tcp://127.0.0.1:{port}") as rig:
            rig.apply(RigState(20.0, 0.0, False))
            frame = rig.capture(1)[0]
            assert float(frame.intensity[0, 0]) == pytest.approx(1200.0)  # the rig's angle
            assert rig.sims["bridge"].frames_served >= 1  # rendered by this process's world
            proc.kill()
            proc.wait(10)
            with pytest.raises(CameraError, match=rf"{SIMULATED_CAMERA_ID} at camera bridge "
                                                  rf"tcp://127.0.0.1:{port}"):
                rig.capture(1)
            proc = simulated_bridge_process(port)  # back on its port
            rig.apply(RigState(-10.0, 0.0, False))
            frame = rig.capture(1)[0]
            assert float(frame.intensity[0, 0]) == pytest.approx(900.0)
    finally:
        proc.kill()
        proc.wait(10)
