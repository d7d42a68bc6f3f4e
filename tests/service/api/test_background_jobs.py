"""Campaigns and calibration jobs are run by one background runner (issue 26).

Real app, real SQLite, the simulated rig. The emergency stop stops either kind through that
runner, each into its own state; a campaign running when the service stops becomes
``interrupted`` (a calibration job's ``failed`` is in test_calibration.py).
"""

from __future__ import annotations

import time

import pytest
from fastapi.testclient import TestClient

from service.api.app import create_app
from tests.service.api.conftest import AUTH, make_settings, start_campaign, wait_campaign
from tests.service.api.test_calibration import SHORT_PLAN, wait_job

pytestmark = pytest.mark.timeout(180)

MANY_POSES = [{"turntable_deg": a} for a in range(-60, 70, 10)]


def start_job(client: TestClient) -> str:
    """A calibration job that waits for the operator (the real rig's case): running, stable."""
    client.app.state.lab.calibrations.world = None
    res = client.post("/api/v1/calibrations", headers=AUTH, json=SHORT_PLAN)
    assert res.status_code == 201, res.text
    jid = res.json()["id"]
    deadline = time.monotonic() + 120
    while client.get(f"/api/v1/calibrations/{jid}").json()["operator_instruction"] is None:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    return jid


def started_campaign(client: TestClient) -> str:
    cid = start_campaign(client, MANY_POSES)
    wait_campaign(client, cid, lambda s: s["poses_done"] >= 1)
    return cid


#: kind -> (start it, its status URL, the answer's key naming it, its state and error after)
KINDS = {
    "campaign": (started_campaign, "/api/v1/campaigns", "campaign_paused", "paused"),
    "calibration job": (start_job, "/api/v1/calibrations", "calibration_cancelled",
                        "cancelled"),
}


@pytest.mark.parametrize("kind", list(KINDS))
def test_the_emergency_stop_stops_either_kind_through_the_one_runner(client, kind):
    start, url, answer_key, final = KINDS[kind]
    lab = client.app.state.lab
    job_id = start(client)
    # the campaign runner and the calibration jobs share one runner, which holds this job
    assert lab.runner.background is lab.calibrations.background is lab.background
    domain = lab.runner if kind == "campaign" else lab.calibrations
    run = lab.background.find(domain.kind, job_id)
    assert run is not None and run.kind.name == kind
    holder = "campaign_id" if kind == "campaign" else "calibration_id"
    assert client.get("/api/v1/devices").json()[holder] == job_id

    res = client.post("/api/v1/devices/stop", headers=AUTH)
    assert res.status_code == 200, res.text
    answer = res.json()
    assert answer[answer_key] == job_id and "shutter" in answer["stopped"]
    other_key = ({"campaign_paused", "calibration_cancelled"} - {answer_key}).pop()
    assert answer[other_key] is None

    assert run.thread is not None
    run.thread.join(60)
    status = client.get(f"{url}/{job_id}").json()
    assert status["state"] == final and status["error"] == "emergency stop", status
    devices = client.get("/api/v1/devices").json()
    assert devices["campaign_id"] is None and devices["calibration_id"] is None  # rig released
    assert lab.background.find(domain.kind, job_id) is None and domain.live(job_id) is None
    assert lab.background.emergency_stop() is None  # nothing runs any more
    # the rig is free for the other kind
    if kind == "campaign":
        other = start_job(client)
        client.post(f"/api/v1/calibrations/{other}/cancel", headers=AUTH)
        assert wait_job(client, other)["state"] == "cancelled"
    else:
        other = start_campaign(client, MANY_POSES[:1])
        assert wait_campaign(client, other, lambda s: s["state"] != "running")[
            "state"] == "completed"


def test_a_campaign_running_when_the_service_stops_is_interrupted(tmp_path):
    with TestClient(create_app(make_settings(tmp_path))) as client:
        cid = started_campaign(client)
    with TestClient(create_app(make_settings(tmp_path))) as client:
        status = client.get(f"/api/v1/campaigns/{cid}").json()
        assert status["state"] == "interrupted", status
        assert status["error"] == "the service was shut down"
        assert 1 <= status["poses_done"] < len(MANY_POSES)
        assert client.get("/api/v1/devices").json()["campaign_id"] is None
