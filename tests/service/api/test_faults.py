"""Device faults: 503 for a manual call, a campaign pauses itself and resumes once cleared."""

from __future__ import annotations

import pytest

from tests.service.api.conftest import AUTH, start_campaign, wait_campaign

pytestmark = pytest.mark.timeout(120)


def turntable_faults(client):
    """The fault injector of the simulated SMC100's serial port."""
    return client.app.state.lab.lease.rig.sims["turntable"].servers["turntable"].faults


def test_a_device_fault_pauses_the_campaign_and_resume_finishes_it(client):
    poses = [{"turntable_deg": a} for a in range(-40, 60, 20)]
    cid = start_campaign(client, poses)
    wait_campaign(client, cid, lambda s: s["poses_done"] >= 1)
    turntable_faults(client).inject("no-reply")  # the controller goes deaf mid-campaign
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "paused", status
    assert "device fault" in status["error"] and "turntable" in status["error"].lower()
    assert 1 <= status["poses_done"] < len(poses)
    done_before = status["poses_done"]

    # a manual call meets the same fault: 503 with the device's message
    res = client.get("/api/v1/devices/turntable/position")
    assert res.status_code == 503 and "DeviceTimeoutError" in res.json()["detail"]

    turntable_faults(client).clear()
    res = client.post(f"/api/v1/campaigns/{cid}/resume", headers=AUTH)
    assert res.status_code == 200 and res.json()["error"] is None
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "completed", status
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    assert [r["pose_index"] for r in rows] == list(range(len(poses)))
    assert done_before < len(rows)


def test_emergency_stop_pauses_a_running_campaign(client):
    cid = start_campaign(client, [{"turntable_deg": a} for a in range(-60, 70, 10)])
    wait_campaign(client, cid, lambda s: s["poses_done"] >= 1)
    res = client.post("/api/v1/devices/stop", headers=AUTH)
    assert res.status_code == 200, res.text
    assert res.json()["campaign_paused"] == cid and "shutter" in res.json()["stopped"]
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "paused" and status["error"] == "emergency stop"
    assert client.get("/api/v1/devices/solar").json()["shutter_open"] is False
    client.post(f"/api/v1/campaigns/{cid}/cancel", headers=AUTH)
    assert wait_campaign(client, cid, lambda s: True)["state"] == "cancelled"
