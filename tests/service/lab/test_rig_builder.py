"""One rig builder for the service and the command line (issue 26): the same ``TOFTWIN_*``
environment gives both the same rig.

The real rig here is the rig's real drivers on the serial simulators (pseudo-terminals) and
the simulated USB camera, found by pyusb as the bus's only camera; its SMC100 answers at
RS-485 address 2 only, as a controller set to another address would.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import usb.backend.libusb1
from typer.testing import CliRunner

from drivers.rig import RigState
from drivers.sim.pty_server import SimHandle, start_simulator
from drivers.sim.usb_camera import UsbCameraSim, plane_source
from service.cli import app
from service.cli.common import rig_scene
from service.lab.rig_builder import open_rig
from service.settings import Settings

SERIAL = "0005-RIG-ENV"
ADDRESS = 2


@pytest.fixture
def real_rig_env(monkeypatch) -> Iterator[tuple[SimHandle, UsbCameraSim]]:
    """The environment of a real rig (ports, turntable address, camera serial) whose devices are
    the simulators; yields the turntable's simulator and the camera."""
    with start_simulator("turntable", [], instant=True) as tt, \
            start_simulator("solar-simulator", [], instant=True) as solar:
        tt.models["turntable"].address = ADDRESS
        camera = UsbCameraSim(plane_source(1.0), seed=1, serial=SERIAL)
        # the USB bus pyusb finds (its libusb backend) holds the simulated camera
        monkeypatch.setattr(usb.backend.libusb1, "get_backend", lambda *a, **k: camera)
        for name, value in {"TURNTABLE_PORT": tt.ports[0], "TURNTABLE_ADDRESS": str(ADDRESS),
                            "LAMP_PORT": solar.ports[0], "SHUTTER_PORT": solar.ports[1],
                            "CAMERA_SERIAL": SERIAL, "TOKEN": "a-token-for-the-tests"}.items():
            monkeypatch.setenv(f"TOFTWIN_{name}", value)
        monkeypatch.delenv("TOFTWIN_SIMULATED", raising=False)
        yield tt, camera


def test_the_service_opens_the_real_rig_the_environment_names(real_rig_env):
    tt, camera = real_rig_env
    rig, world = open_rig(Settings(), rig_scene("satellite_ground_test"))
    with rig:
        assert world is None and rig.sims == {}
        assert rig.turntable.address == ADDRESS
        assert rig.camera.identity().serial == SERIAL
        rig.apply(RigState(35.0, 0.0, False))
        assert tt.models["turntable"].current_position() == pytest.approx(35.0, abs=0.01)
    assert not camera.device.claimed


def test_a_command_drives_the_same_real_rig_from_the_same_environment(real_rig_env, tmp_path):
    # Before issue 26 the command line read the ports itself and dropped the turntable's
    # address: it spoke to controller 1, which is not there, and timed out.
    tt, camera = real_rig_env
    res = CliRunner().invoke(app, ["fit-object", "--out", str(tmp_path / "o"), "--angles", "20",
                                   "--frames", "1"])
    # The command captured at 20 deg on the controller at address 2 (the object fit itself
    # then finds only the simulated camera's plane, which fits no mesh: not this test's subject).
    assert "object fit: 1 frames at 20 deg" in res.output, res.output
    assert "fitting the object twin" in res.output, res.output
    assert tt.models["turntable"].current_position() == pytest.approx(20.0, abs=0.01)
    assert not camera.device.claimed


#: every command that drives the rig, with its output in ``tmp``
RIG_COMMANDS = {
    "calibrate rig": lambda tmp: ["calibrate", "rig", "--out", str(tmp / "o")],
    "calibrate material": lambda tmp: ["calibrate", "material", "--out", str(tmp / "o")],
    "fit-object": lambda tmp: ["fit-object", "--out", str(tmp / "o")],
}


@pytest.mark.parametrize("command", RIG_COMMANDS)
def test_a_command_on_a_real_rig_without_its_ports_names_them(monkeypatch, tmp_path, command):
    for name in ("SIMULATED", "TURNTABLE_PORT", "LAMP_PORT", "SHUTTER_PORT"):
        monkeypatch.delenv(f"TOFTWIN_{name}", raising=False)
    monkeypatch.setenv("TOFTWIN_LAMP_PORT", str(tmp_path / "lamp"))
    res = CliRunner().invoke(app, RIG_COMMANDS[command](tmp_path))
    assert res.exit_code == 2, res.output
    text = " ".join(res.output.split())
    assert "no TOFTWIN_TURNTABLE_PORT, TOFTWIN_SHUTTER_PORT set (or use --simulated)" in text
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", RIG_COMMANDS)
def test_a_command_refuses_the_environment_the_service_refuses(monkeypatch, tmp_path, command):
    # A turntable address out of the SMC100's range is refused by every command as by the
    # service, naming the variable and the range, before anything is opened.
    monkeypatch.setenv("TOFTWIN_TURNTABLE_ADDRESS", "32")
    res = CliRunner().invoke(app, RIG_COMMANDS[command](tmp_path))
    assert res.exit_code == 2, res.output
    text = " ".join(res.output.split())
    assert "TOFTWIN_TURNTABLE_ADDRESS" in text and "less than or equal to 31" in text
    assert not (tmp_path / "o").exists()


def test_a_command_on_the_simulated_lab_arms_the_faults_the_environment_arms(monkeypatch,
                                                                             tmp_path):
    # TOFTWIN_FAULTS arms a fault on the simulated lab's devices for the service; the command
    # line's simulated lab is the same one (before issue 26 it ignored them and went on).
    from drivers.errors import TurntableError

    monkeypatch.setenv("TOFTWIN_FAULTS", '["turntable:stall:1"]')
    res = CliRunner().invoke(app, ["fit-object", "--simulated", "--out", str(tmp_path / "o"),
                                   "--angles", "10", "--frames", "1", "--camera-spp", "1"])
    assert isinstance(res.exception, TurntableError), res.output
    assert "move to 10 deg" in str(res.exception) and "following error" in str(res.exception)
    assert not (tmp_path / "o").exists()
