"""What needs a system library or an optional package is imported where it is used: the
simulated service starts without any of them, and a real camera without libusb says which
package to install.

The shared venv has everything, so the absence is made in a subprocess (``python -c``): the
optional packages are made unimportable (``sys.modules[name] = None``, as if not installed) and
``ctypes.util.find_library`` finds no libusb (what pyusb's backends look for, as on a machine
without ``libusb-1.0-0``). The audit behind the list (``python -X importtime`` and the shared
objects a running ``toftwin serve --simulated`` maps): after Open3D left, the only system
library a wheel needs at run time beyond the C and C++ runtimes is libusb-1.0, loaded by pyusb
through ctypes when a real camera is opened; opencv-contrib-python-headless links none (no
libGL, no X11) and is imported only by the intrinsics calibration.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TOKEN = "test-token-0123456789"
#: packages that are optional (extras) or that needed a system library; none is needed to serve
OPTIONAL = ("open3d", "distributed", "dask", "cv2", "mitsuba", "drjit")

#: the subprocess's prelude: the optional packages unimportable, no libusb on the machine
PRELUDE = f"""
import ctypes.util, json, sys
for name in {OPTIONAL!r}:
    sys.modules[name] = None
_find = ctypes.util.find_library
ctypes.util.find_library = lambda name: None if "usb" in name else _find(name)
"""

SERVE = PRELUDE + f"""
import toftwin_cli
from fastapi.testclient import TestClient
from service.api.app import create_app
from service.settings import Settings

settings = Settings(token={TOKEN!r}, data_dir=sys.argv[1], simulated=True, executor="thread",
                    sim_spp=1, camera_spp=1, camera_integrator="direct")
with TestClient(create_app(settings)) as client:
    res = client.get("/api/v1/health")
print(json.dumps({{"status": res.status_code, "health": res.json()}}))
"""

REAL_CAMERA = PRELUDE + """
from drivers.camera import UsbBackendError
from drivers.rig import Rig
from drivers.sim.pty_server import start_simulator

with start_simulator("turntable", [], instant=True) as tt, \\
        start_simulator("solar-simulator", [], instant=True) as solar:
    try:
        Rig.open(tt.ports[0], *solar.ports).close()
        print(json.dumps({"error": None}))
    except UsbBackendError as exc:
        print(json.dumps({"error": str(exc)}))
"""


def _run(code: str, *args: str) -> dict:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    res = subprocess.run([sys.executable, "-c", code, *args], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


@pytest.mark.timeout(180)
def test_the_simulated_service_answers_without_optional_packages_or_libusb(tmp_path):
    out = _run(SERVE, str(tmp_path / "data"))
    assert out["status"] == 200
    assert out["health"]["status"] == "ok" and out["health"]["simulated"] is True


@pytest.mark.timeout(180)
def test_a_real_camera_without_libusb_says_which_package_to_install():
    out = _run(REAL_CAMERA)
    assert out["error"] is not None
    assert "libusb is not installed" in out["error"]
    assert "apt-get install libusb-1.0-0" in out["error"]
