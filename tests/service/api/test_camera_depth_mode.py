"""royale's processed depth as the camera's data (issue 28): a lab without raw access.

The simulated camera bridge serves royale's ``DepthData`` (``--camera-mode depth``): each frame
is the camera's own z and grey, no raw phases. A campaign compares them with the twin's over
the pixels valid in both, each grey scaled by its 99.5th percentile, and every result says
``camera_data: "royale processed depth"``; the raw route has nothing to give, a recording keeps
the points and replays them exactly, and a calibration refuses the mode with the fix.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from sim_core.frame_io import read_measured
from tests.drivers.helpers import free_port, simulated_bridge_process
from tests.service.api.conftest import AUTH, start_campaign, wait_campaign
from tests.service.api.test_calibration import SHORT_PLAN

pytestmark = pytest.mark.timeout(300)

POSES = [{"turntable_deg": a} for a in (-30.0, 20.0)]


@pytest.fixture
def bridge_url():
    port = free_port()
    proc = simulated_bridge_process(port)
    yield f"tcp://127.0.0.1:{port}"
    proc.kill()
    proc.wait(10)


def _completed(client, cid: str) -> list[dict]:
    status = wait_campaign(client, cid, lambda s: s["state"] not in ("created", "running"),
                           timeout_s=240)
    assert status["state"] == "completed", status
    return client.get(f"/api/v1/campaigns/{cid}/results").json()


def test_a_campaign_on_royales_processed_depth_says_so_and_replays(make_client, bridge_url,
                                                                   tmp_path):
    client = make_client(camera=bridge_url, camera_mode="depth")
    cid = start_campaign(client, POSES, record=True)
    rows = _completed(client, cid)
    assert len(rows) == len(POSES)
    for row in rows:
        metrics = row["metrics"]
        assert metrics["camera_data"] == "royale processed depth", metrics
        tof = metrics["tof"]
        assert tof["depth_diff_n_pixels"] > 100
        # the nominal world through the nominal twin: royale's z (here our reconstruction on
        # the preset lens) against the twin's within a few mm
        assert abs(tof["depth_diff_median_mm"]) < 10.0, tof
    frame_id = rows[0]["measured_frame_id"]
    frame = read_measured(tmp_path / "frames" / frame_id)
    assert frame.raw is None and frame.meta["camera_data"] == "royale processed depth"
    assert np.isfinite(frame.image.depth_z_m[frame.image.valid]).all()
    assert client.get(f"/api/v1/frames/{frame_id}/raw").status_code == 404
    csv_text = client.get(f"/api/v1/campaigns/{cid}/results?format=csv").text
    assert "camera_data" in csv_text.splitlines()[0] and "royale processed depth" in csv_text

    res = client.post("/api/v1/campaigns", headers=AUTH, json={
        "name": "replay", "source": "recording", "recording": f"{cid}.h5"})
    assert res.status_code == 201, res.text
    replay = res.json()["id"]
    assert client.post(f"/api/v1/campaigns/{replay}/start", headers=AUTH).status_code == 200
    replayed = _completed(client, replay)
    assert [r["metrics"] for r in replayed] == [r["metrics"] for r in rows]


def test_a_calibration_refuses_processed_depth_and_names_the_fix(make_client, bridge_url):
    """A calibration measures raw frames: its job fails at its first capture, naming the
    camera mode and how to change it."""
    client = make_client(camera=bridge_url, camera_mode="depth")
    res = client.post("/api/v1/calibrations", headers=AUTH,
                      json={**SHORT_PLAN, "warmup_stage": False, "settling_stage": False})
    assert res.status_code in (201, 202), res.text
    job = res.json()["id"]
    deadline = time.monotonic() + 120
    while True:
        status = client.get(f"/api/v1/calibrations/{job}").json()
        if status["state"] in ("failed", "completed", "cancelled"):
            break
        assert time.monotonic() < deadline, status
        time.sleep(0.1)
    assert status["state"] == "failed", status
    assert "camera_mode" in status["error"] and "--camera-mode raw" in status["error"], status


def test_processed_depth_needs_a_camera_that_gives_it(make_client):
    from pydantic import ValidationError

    from service.settings import Settings

    with pytest.raises(ValidationError, match="camera_mode"):
        Settings(token="x" * 24, simulated=True, camera="usb", camera_mode="depth")
