"""Device faults: 503 for a manual call, a campaign pauses itself and resumes once cleared."""

from __future__ import annotations

import pytest

from tests.service.api.conftest import AUTH, problem, start_campaign, wait_campaign

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
    body = problem(res, 503)
    assert body["type"] == "urn:toftwin:problem:device-fault"
    assert body["fault"] == "DeviceTimeoutError" and "turntable" in body["detail"].lower()

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


def lamp_faults(client):
    """The fault injector of the simulated lamp supply's serial port."""
    return client.app.state.lab.lease.rig.sims["solar"].servers["lamp"].faults


def test_a_lamp_fault_pauses_the_campaign_and_no_pose_is_stored_without_its_light(client):
    poses = [{"turntable_deg": a, "solar_suns": 1.0} for a in range(-40, 60, 20)]
    cid = start_campaign(client, poses)
    wait_campaign(client, cid, lambda s: s["poses_done"] >= 1)
    lamp_faults(client).inject("lamp-fault")  # the arc dies and will not relight
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "paused", status
    assert "LampFaultError" in status["error"] and "lamp" in status["error"]
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    assert len(rows) == status["poses_done"] < len(poses)
    for row in client.get(f"/api/v1/campaigns/{cid}/results").json():
        rig = client.get(f"/api/v1/frames/{row['measured_frame_id']}").json()["rig"]
        assert rig["solar_suns"] == pytest.approx(1.0, abs=0.02) and rig["shutter_open"]

    # a manual pose meets the same fault as a device error (503), not as the client's (422)
    res = client.post("/api/v1/poses", headers=AUTH, json={"turntable_deg": 0.0,
                                                          "solar_suns": 1.0})
    assert res.status_code in (409, 503), res.text

    lamp_faults(client).clear()  # the lamp replaced; the operator relights it (a pose won't)
    res = client.post("/api/v1/devices/solar/lamp", headers=AUTH, json={"on": True})
    assert res.status_code == 200 and res.json()["lamp_on"] is True, res.text
    res = client.post(f"/api/v1/campaigns/{cid}/resume", headers=AUTH)
    assert res.status_code == 200, res.text
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "completed", status
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    assert [r["pose_index"] for r in rows] == list(range(len(poses)))


def test_a_stalled_turntable_is_recovered_through_the_api(client):
    turntable_faults(client).inject("stall:1")  # the next move stalls: following error
    res = client.post("/api/v1/devices/turntable/move", headers=AUTH, json={"angle_deg": 60.0})
    assert "following error" in problem(res, 503)["detail"]
    res = client.post("/api/v1/devices/turntable/move", headers=AUTH, json={"angle_deg": 60.0})
    assert "enable" in problem(res, 503)["detail"]  # still disabled

    assert client.post("/api/v1/devices/turntable/enable").status_code == 401
    res = client.post("/api/v1/devices/turntable/enable", headers=AUTH)
    assert res.status_code == 200, res.text
    res = client.post("/api/v1/devices/turntable/move", headers=AUTH, json={"angle_deg": 60.0})
    assert res.status_code == 200 and res.json()["angle_deg"] == pytest.approx(60.0, abs=0.01)

    res = client.post("/api/v1/devices/turntable/reset", headers=AUTH)  # reboot: unreferenced
    assert res.status_code == 200, res.text
    res = client.post("/api/v1/devices/turntable/move", headers=AUTH, json={"angle_deg": -30.0})
    assert res.status_code == 200 and res.json()["angle_deg"] == pytest.approx(-30.0, abs=0.01)


def test_enable_and_reset_are_refused_while_a_campaign_holds_the_rig(client):
    cid = start_campaign(client, [{"turntable_deg": a} for a in range(-60, 70, 10)])
    wait_campaign(client, cid, lambda s: s["poses_done"] >= 1)
    for verb in ("enable", "reset"):
        res = client.post(f"/api/v1/devices/turntable/{verb}", headers=AUTH)
        assert cid in problem(res, 409)["detail"], verb
    client.post(f"/api/v1/campaigns/{cid}/cancel", headers=AUTH)


def test_a_lamp_fault_armed_at_start_pauses_the_campaign_with_no_unlit_result(make_client):
    """The operator's rehearsal: ``serve --simulated --fault solar-simulator:lamp-fault@40``."""
    client = make_client(faults=["solar-simulator:lamp-fault@40"])
    poses = [{"turntable_deg": a, "solar_suns": 1.0} for a in range(-60, 70, 10)]
    cid = start_campaign(client, poses)
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "paused" and "lamp" in status["error"], status
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    assert len(rows) == status["poses_done"] < len(poses)
    for row in rows:
        rig = client.get(f"/api/v1/frames/{row['measured_frame_id']}").json()["rig"]
        assert rig["solar_suns"] == pytest.approx(1.0, abs=0.02)
