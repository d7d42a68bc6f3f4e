"""A real server process killed (SIGKILL) mid-campaign, restarted, resumed: nothing lost.

The server runs as ``python -m toftwin_cli serve --simulated`` on a free loopback port with the
default executor (a local process pool); it is killed with its whole process group, pool
workers included, as a crash or ``docker kill`` would. The restart is the service's own
start-up (``open_lab``: the lock, the recovery, the runner) on the same data directory, in this
process: a second server process would only add the ~5 CPU seconds of its imports. A graceful
stop of a server process by SIGTERM is checked in ``test_data_dir_lock``.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.service.api.conftest import AUTH, TOKEN

pytestmark = pytest.mark.timeout(180)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def server(data_dir: Path, log: Path, **settings: str
           ) -> Iterator[tuple[httpx.Client, subprocess.Popen]]:
    """A ``toftwin serve --simulated`` process and a client for it; killed at the end.

    Tiny renders and two pool workers; ``settings`` override the ``TOFTWIN_*`` environment
    (``TOFTWIN_WORKERS="1"``). The process leads a process group of its own (its pool workers
    are in it): ``os.killpg(proc.pid, ...)`` reaches them all.
    """
    port = free_port()
    env = {**os.environ, "TOFTWIN_TOKEN": TOKEN, "TOFTWIN_SIM_SPP": "1",
           "TOFTWIN_CAMERA_SPP": "1", "TOFTWIN_CAMERA_INTEGRATOR": "direct",
           "TOFTWIN_WORKERS": "2", **settings}
    cmd = [sys.executable, "-m", "toftwin_cli", "serve", "--simulated", "--port", str(port),
           "--data-dir", str(data_dir), "--log-level", "warning"]
    with open(log, "ab") as out:
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True, cwd=Path(__file__).parents[3])
    client = httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30.0)
    try:
        deadline = time.monotonic() + 60.0
        while True:
            assert proc.poll() is None, f"server exited: {log.read_text()[-3000:]}"
            with contextlib.suppress(httpx.TransportError):
                if client.get("/api/v1/health").status_code == 200:
                    break
            assert time.monotonic() < deadline, f"server not up: {log.read_text()[-3000:]}"
            time.sleep(0.1)
        yield client, proc
    finally:
        client.close()
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)


def wait_for(client: httpx.Client, cid: str, until, timeout_s: float = 90.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while True:
        status = client.get(f"/api/v1/campaigns/{cid}").json()
        if until(status):
            return status
        assert time.monotonic() < deadline, status
        time.sleep(0.05)


def start_campaign(client: httpx.Client, name: str, poses: list[dict], *, seed: int,
                   poses_done: int) -> str:
    """Create and start a campaign; its id once ``poses_done`` of its poses are done."""
    res = client.post("/api/v1/campaigns", headers=AUTH,
                      json={"name": name, "poses": poses, "seed": seed})
    cid = res.json()["id"]
    assert client.post(f"/api/v1/campaigns/{cid}/start", headers=AUTH).status_code == 200
    wait_for(client, cid, lambda s: s["poses_done"] >= poses_done)
    return cid


#: one pool worker (one start-up fewer than two) and still two poses in flight at the kill: the
#: rig stage of the next pose overlaps the simulation of the previous one
ONE_WORKER_TWO_IN_FLIGHT = {"TOFTWIN_WORKERS": "1", "TOFTWIN_PIPELINE_DEPTH": "2"}

#: three poses, four captures (a pose of two repeats among them); killed after two captures
POSES = [{"turntable_deg": a, "solar_suns": s, "repeats": r}
         for a, s, r in ((-60, 1.0, 1), (-30, 0.9, 2), (30, 1.2, 1))]
UNITS = {(i, r) for i, p in enumerate(POSES) for r in range(p["repeats"])}


def test_killed_server_resumes_the_campaign_with_each_pose_exactly_once(tmp_path, make_client):
    data, log = tmp_path / "data", tmp_path / "server.log"
    poses, units = POSES, UNITS

    with server(data, log, **ONE_WORKER_TWO_IN_FLIGHT) as (client, proc):
        cid = start_campaign(client, "crash", poses, seed=5, poses_done=2)
        os.killpg(proc.pid, signal.SIGKILL)  # no shutdown handler runs
        proc.wait(timeout=10)

    # the restart: the service started again on the data directory the dead one left
    client = make_client(data)
    status = client.get(f"/api/v1/campaigns/{cid}").json()
    assert status["state"] == "interrupted", status
    assert 2 <= status["poses_done"] < len(units)
    before = {(r["pose_index"], r["repeat"]): r
              for r in client.get(f"/api/v1/campaigns/{cid}/results").json()}
    assert status["current_pose"] is not None  # the first unfinished one

    assert client.post(f"/api/v1/campaigns/{cid}/resume", headers=AUTH).status_code == 200
    status = wait_for(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "completed", status
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    keys = [(r["pose_index"], r["repeat"]) for r in rows]
    assert len(keys) == len(set(keys)) == len(units) and set(keys) == units
    for key, row in before.items():  # what was committed before the crash is kept as is
        match = rows[keys.index(key)]
        assert match["measured_frame_id"] == row["measured_frame_id"]
        assert match["metrics"] == row["metrics"]
    # every frame named is on disk, and nothing else is (orphans of the crash were swept)
    named = {r[k] for r in rows for k in ("measured_frame_id", "simulated_frame_id")}
    on_disk = {p.name for p in (data / "frames").iterdir()}
    assert on_disk == named
