"""The CLI entry point: ``serve`` prints the port first, serves, and stops when interrupted."""

from __future__ import annotations

import io
import os
import select
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from drivers.errors import DeviceInputError
from drivers.sim.pty_server import serve
from drivers.solar_simulator import SolarSimulator
from drivers.turntable import Turntable
from tests.drivers.helpers import FAST_LAMP, FAST_SHUTTER, FAST_SMC100

pytestmark = pytest.mark.timeout(20)

REPO = Path(__file__).resolve().parents[2]


def _wait_lines(buffer: io.StringIO, n: int, timeout_s: float = 5.0) -> list[str]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        lines = buffer.getvalue().splitlines()
        if len(lines) >= n:
            return lines
        time.sleep(0.01)
    raise AssertionError(f"serve printed {buffer.getvalue()!r}")


def test_serve_prints_the_port_first_and_stops_on_request():
    out, stop = io.StringIO(), threading.Event()
    thread = threading.Thread(
        target=serve,
        args=("turntable", ["garbled:1"]),
        kwargs={"instant": True, "out": out, "stop_event": stop},
    )
    thread.start()
    try:
        port = _wait_lines(out, 1)[0]
        assert os.path.islink(port) and os.readlink(port).startswith("/dev/pts/")
        with Turntable(port, settle_s=0.0, poll_interval_s=0.005, settings=FAST_SMC100) as tt:
            assert tt.move_to(12.0) == pytest.approx(12.0)
    finally:
        stop.set()
        thread.join(timeout=5.0)
    assert not thread.is_alive()
    assert not os.path.exists(port)  # the symlink and its directory are cleaned up


def test_serve_solar_simulator_prints_lamp_then_shutter():
    out, stop = io.StringIO(), threading.Event()
    thread = threading.Thread(
        target=serve,
        args=("solar-simulator", []),
        kwargs={"instant": True, "out": out, "stop_event": stop, "transport": "tcp"},
    )
    thread.start()
    try:
        lamp, shutter = _wait_lines(out, 2)
        assert lamp.startswith("socket://127.0.0.1:") and shutter.startswith("socket://")
        with SolarSimulator(
            lamp, shutter, warmup_s=0.0, lamp_settings=FAST_LAMP, shutter_settings=FAST_SHUTTER
        ) as solar:
            assert (solar.model_id, solar.shutter_model_id) == ("69907", "68945")
    finally:
        stop.set()
        thread.join(timeout=5.0)


def test_serve_refuses_unknown_kinds_and_faults():
    with pytest.raises(DeviceInputError, match=r"^kind: got 'camera'"):
        serve("camera", [], out=io.StringIO(), stop_event=threading.Event())
    with pytest.raises(DeviceInputError, match=r"fault 'lamp-fault' does not apply here"):
        serve("turntable", ["lamp-fault"], out=io.StringIO(), stop_event=threading.Event())


def _start(*args: str) -> subprocess.Popen[str]:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
    }
    return subprocess.Popen(
        [sys.executable, "-m", "drivers.sim.pty_server", *args],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _first_line(proc: subprocess.Popen[str], timeout_s: float = 10.0) -> str:
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
    assert ready, "the simulator printed nothing"
    return proc.stdout.readline().strip()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_module_entry_point_serves_until_interrupted(sig):
    proc = _start("turntable", "--instant", "--fault", "no-reply:1")
    try:
        port = _first_line(proc)
        with Turntable(port, settle_s=0.0, poll_interval_s=0.005, settings=FAST_SMC100) as tt:
            assert tt.move_to(-33.0) == pytest.approx(-33.0)
        proc.send_signal(sig)
        assert proc.wait(timeout=5.0) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_module_entry_point_exits_2_on_a_bad_fault():
    proc = _start("turntable", "--fault", "smoke")
    _, err = proc.communicate(timeout=10.0)
    assert proc.returncode == 2
    assert "fault: unknown fault 'smoke'" in err
