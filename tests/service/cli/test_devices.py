"""``toftwin devices`` and ``toftwin sim-device`` end to end."""

import subprocess
import sys

import pytest
from typer.testing import CliRunner

from drivers.turntable import Turntable
from service.cli import app

runner = CliRunner()


def test_devices_check_against_the_simulators_is_ok():
    res = runner.invoke(app, ["devices", "check", "--simulated", "--json"])
    assert res.exit_code == 0, res.output
    assert '"camera"' in res.output and '"turntable"' in res.output


def test_devices_check_without_ports_names_what_is_skipped():
    res = runner.invoke(app, ["devices", "check"])
    assert "turntable: no port given" in res.output


def test_devices_list_shows_the_simulated_pico_flexx():
    res = runner.invoke(app, ["devices", "list", "--simulated"])
    assert res.exit_code == 0, res.output
    assert "c012" in res.output and "pico flexx" in res.output


@pytest.mark.timeout(60)
def test_sim_device_prints_its_port_first_and_a_real_driver_drives_it():
    proc = subprocess.Popen(
        [sys.executable, "-m", "toftwin_cli", "sim-device", "turntable", "--instant"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        port = proc.stdout.readline().strip()
        assert port.startswith("/")
        tt = Turntable(port, settle_s=0.0)
        tt.connect()
        try:
            tt.home()
            assert tt.move_to(42.0) == pytest.approx(42.0, abs=0.01)
        finally:
            tt.close()
    finally:
        proc.terminate()
        proc.wait(timeout=20)


def test_sim_device_rejects_an_unknown_kind():
    res = runner.invoke(app, ["sim-device", "toaster"])
    assert res.exit_code == 2 and "turntable" in res.output
