"""The service with its camera behind a camera bridge in another process (issue 28).

``toftwin camera-bridge --simulated`` runs as its own process and films the service's simulated
world (:mod:`drivers.sim.world_link`); the service reaches it as it would reach the bridge beside
a real pico flexx (``TOFTWIN_CAMERA=tcp://HOST:PORT``, ``serve --camera``). A campaign compares
every pose through it; killed mid-campaign, the bridge pauses the campaign with a message naming
the camera and the bridge, and once a bridge is back on its port the campaign resumes by itself
(or, with the watch off, the operator's resume) and finishes with every pose stored once.
"""

from __future__ import annotations

import time

import pytest

from drivers.sim.bridge_source import SIMULATED_CAMERA_ID
from tests.drivers.helpers import free_port, simulated_bridge_process
from tests.service.api.conftest import AUTH, start_campaign, wait_campaign

pytestmark = pytest.mark.timeout(300)

POSES = [{"turntable_deg": a} for a in (-45.0, -15.0, 15.0, 45.0)]


@pytest.fixture
def bridge_port():
    port = free_port()
    procs = [simulated_bridge_process(port)]
    yield port, procs
    for proc in procs:
        proc.kill()
        proc.wait(10)


def _paused_by_a_dead_bridge(client, procs, url: str) -> tuple[str, dict]:
    """A campaign through the bridge, the bridge killed after its first pose: paused, the
    error naming the camera and the bridge."""
    cid = start_campaign(client, POSES)
    wait_campaign(client, cid, lambda s: s["poses_done"] >= 1, timeout_s=240)
    procs[0].kill()  # the bridge dies mid-campaign
    procs[0].wait(10)
    status = wait_campaign(client, cid, lambda s: s["state"] != "running", timeout_s=240)
    assert status["state"] == "paused", status
    assert "device fault (CameraLostError)" in status["error"]
    assert SIMULATED_CAMERA_ID in status["error"] and url in status["error"]
    assert 1 <= status["poses_done"] < len(POSES)
    return cid, status


def _each_pose_once_through_the_bridge(client, cid: str) -> None:
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    assert [r["pose_index"] for r in rows] == list(range(len(POSES)))  # each pose once
    for row in rows:  # every pose compared: the measured frame came through the bridge
        assert "error" not in row["metrics"], row["metrics"]
        assert row["metrics"]["tof"]["depth_diff_n_pixels"] > 0


def test_a_campaign_through_the_bridge_pauses_when_it_dies_and_resumes_when_it_is_back(
        make_client, bridge_port):
    """The campaign watches for its camera (``camera_return_s``) and resumes by itself at the
    first frame the new bridge delivers."""
    port, procs = bridge_port
    url = f"tcp://127.0.0.1:{port}"
    client = make_client(camera=url, camera_return_s=240.0, camera_return_poll_s=0.5)
    health = client.get("/api/v1/health").json()
    assert health["status"] == "ok"

    cid, status = _paused_by_a_dead_bridge(client, procs, url)
    assert "resumes by itself when the camera delivers frames again" in status["error"]
    procs.append(simulated_bridge_process(port))  # the bridge is back: nobody resumes
    status = wait_campaign(client, cid, lambda s: s["state"] == "completed"
                           or (s["state"] != "running" and s["runs"] > 1), timeout_s=240)
    assert status["state"] == "completed", status
    assert status["runs"] == 2, status  # one run, paused, then one resumed by the watch
    _each_pose_once_through_the_bridge(client, cid)


def test_without_the_watch_the_operator_resumes_once_the_bridge_is_back(
        make_client, bridge_port):
    port, procs = bridge_port
    url = f"tcp://127.0.0.1:{port}"
    client = make_client(camera=url, camera_return_s=0.0)
    cid, status = _paused_by_a_dead_bridge(client, procs, url)
    assert "resumes by itself" not in status["error"]
    procs.append(simulated_bridge_process(port))  # the bridge is back
    time.sleep(2.0)
    assert client.get(f"/api/v1/campaigns/{cid}").json()["state"] == "paused"  # nobody resumed
    res = client.post(f"/api/v1/campaigns/{cid}/resume", headers=AUTH)
    assert res.status_code == 200, res.text
    status = wait_campaign(client, cid, lambda s: s["state"] != "running", timeout_s=240)
    assert status["state"] == "completed", status
    _each_pose_once_through_the_bridge(client, cid)


def test_the_bridge_compares_as_well_as_the_in_process_camera(make_client, bridge_port, tmp_path):
    """The same campaign through the bridge and through the in-process USB camera: the same
    world, so the same comparison within the noise of different frames."""
    port, _ = bridge_port
    metrics = {}
    for camera in ("usb", f"tcp://127.0.0.1:{port}"):
        client = make_client(tmp_path / camera.replace(":", "_").replace("/", ""), camera=camera)
        cid = start_campaign(client, POSES)
        status = wait_campaign(client, cid, lambda s: s["state"] != "running", timeout_s=240)
        assert status["state"] == "completed", status
        metrics[camera] = [r["metrics"] for r in
                           client.get(f"/api/v1/campaigns/{cid}/results").json()]
    usb, bridged = metrics.values()
    # the first pose's frame is the same request to the same world (seed, index 0): equal
    assert bridged[0] == usb[0]
    # later ones differ by which frames each camera's stream rendered: equal within noise
    for a, b in zip(usb[1:], bridged[1:], strict=True):
        assert b["grey"]["mean_measured"] == pytest.approx(a["grey"]["mean_measured"], rel=0.05)
        assert b["grey"]["psnr_db"] == pytest.approx(a["grey"]["psnr_db"], abs=1.5)
        assert b["tof"]["depth_diff_mad_mm"] == pytest.approx(a["tof"]["depth_diff_mad_mm"],
                                                              rel=0.25)
