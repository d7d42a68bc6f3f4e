"""Campaigns: run to completion, follow, export (JSON, CSV, HTML, Bluesky), control, 409."""

from __future__ import annotations

import csv
import io
import json

import event_model
import pytest
from event_model import DocumentNames, schema_validators

from service.export.plots import CAMPAIGN_PLOTS
from tests.service.api.conftest import AUTH, problem, start_campaign, wait_campaign

pytestmark = pytest.mark.timeout(120)

POSES = [{"turntable_deg": a, "solar_suns": s, "repeats": r}
         for a, s, r in ((-60, 1.0, 1), (-30, 0.9, 2), (0, 1.0, 1), (30, 1.2, 1), (60, 0.0, 1))]
UNITS = {(i, r) for i, p in enumerate(POSES) for r in range(p["repeats"])}


def test_a_campaign_runs_to_completion_with_every_metric_stored(client):
    cid = start_campaign(client, POSES, seed=7)
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "completed", status
    assert (status["poses_done"], status["poses_total"], status["pose_count"]) == (6, 6, 5)
    assert status["current_pose"] is None and status["error"] is None

    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    assert {(r["pose_index"], r["repeat"]) for r in rows} == UNITS and len(rows) == 6
    for r in rows:
        assert "error" not in r["metrics"], r["metrics"]
        for ch in ("grey", "depth"):
            assert set(r["metrics"][ch]) >= {"mean_measured", "mean_simulated", "var_measured",
                                             "var_simulated", "mse", "ssim", "psnr_db"}
        tof = r["metrics"]["tof"]  # the depth difference and pixel shares
        assert tof["depth_diff_n_pixels"] > 0 and tof["depth_diff_mad_mm"] >= 0.0
        assert 0.0 <= tof["invalid_share_measured"] <= 1.0
        assert client.get(f"/api/v1/frames/{r['measured_frame_id']}").status_code == 200
        assert client.get(f"/api/v1/frames/{r['simulated_frame_id']}").status_code == 200
    # repeats of a pose are different captures and different simulations
    rep = [r for r in rows if r["pose_index"] == 1]
    assert rep[0]["measured_frame_id"] != rep[1]["measured_frame_id"]
    assert rep[0]["metrics"]["grey"]["mse"] != rep[1]["metrics"]["grey"]["mse"]

    table = list(csv.DictReader(io.StringIO(
        client.get(f"/api/v1/campaigns/{cid}/results?format=csv").text)))
    assert len(table) == 6 and float(table[0]["depth_ssim"]) == pytest.approx(
        rows[0]["metrics"]["depth"]["ssim"])
    assert list(table[0])[9] == "depth_diff_median_mm"  # the first metric column
    assert float(table[0]["depth_diff_p95_abs_mm"]) == pytest.approx(
        rows[0]["metrics"]["tof"]["depth_diff_p95_abs_mm"])

    html = client.get(f"/api/v1/campaigns/{cid}/report")
    assert html.headers["content-type"].startswith("text/html")
    # the plots; per pose its depth difference first, then six images, each with its colour
    # bar (all inline)
    assert html.text.count("<svg") == len(CAMPAIGN_PLOTS)
    assert html.text.count('class="tof-depth"') == 5
    assert html.text.index('class="tof-depth"') < html.text.index('class="frame-image"')
    assert html.text.count('class="frame-image"') == 5 * 6
    assert html.text.count('class="colour-bar"') == 5 * 6
    assert html.text.count("data:image/png;base64,") == 5 * 6 * 2

    # the campaign's events end with the final state
    with client.stream("GET", f"/api/v1/campaigns/{cid}/events") as stream:
        text = stream.read().decode()
    data = [json.loads(line[5:]) for line in text.splitlines() if line.startswith("data:")]
    assert data[-1]["state"] == "completed" and data[-1]["poses_done"] == 6


def test_events_follow_a_campaign_live_and_documents_are_valid_bluesky(client):
    cid = start_campaign(client, POSES[:3])
    with client.stream("GET", f"/api/v1/campaigns/{cid}/events") as stream:
        assert stream.headers["content-type"].startswith("text/event-stream")
        events = [json.loads(line[5:]) for line in stream.iter_lines()
                  if line.startswith("data:")]
    done = [e["poses_done"] for e in events]
    assert events[0]["state"] == "running" and events[-1]["state"] == "completed"
    assert done == sorted(done) and len(set(done)) >= 3  # progress seen while it ran

    docs = client.get(f"/api/v1/campaigns/{cid}/documents").json()
    assert [d["name"] for d in docs] == ["start", "descriptor"] + ["event"] * 4 + ["stop"]
    for d in docs:
        schema_validators[DocumentNames[d["name"]]].validate(d["doc"])
    start, descriptor, *events, stop = (d["doc"] for d in docs)
    assert descriptor["run_start"] == start["uid"] and stop["run_start"] == start["uid"]
    assert [e["seq_num"] for e in events] == [1, 2, 3, 4]
    assert all(e["descriptor"] == descriptor["uid"] for e in events)
    assert stop["exit_status"] == "success" and stop["num_events"] == {"primary": 4}
    assert events[0]["data"]["turntable_deg"] == -60 and events[0]["data"]["depth_ssim"] > 0
    assert descriptor["data_keys"]["depth_diff_median_mm"]["units"] == "mm"
    assert events[0]["data"]["depth_diff_n_pixels"] > 0
    # the same documents every time (uids derived from the campaign)
    assert client.get(f"/api/v1/campaigns/{cid}/documents").json() == docs
    # and they replay through event-model's own run router (which pages the events)
    seen = []
    router = event_model.RunRouter([lambda name, doc: ([lambda n, d: seen.append(n)], [])])
    for d in docs:
        router(d["name"], d["doc"])
    assert seen == ["start", "descriptor"] + ["event_page"] * 4 + ["stop"]


def test_manual_device_calls_during_a_campaign_get_409(client):
    cid = start_campaign(client, [{"turntable_deg": a, "repeats": 2} for a in range(0, 100, 10)])
    wait_campaign(client, cid, lambda s: s["poses_done"] >= 1)
    for path, body in (("/api/v1/devices/turntable/move", {"angle_deg": 5}),
                       ("/api/v1/devices/turntable/home", None),
                       ("/api/v1/devices/solar/lamp", {"on": False}),
                       ("/api/v1/devices/camera/capture", None),
                       ("/api/v1/poses", {"turntable_deg": 5, "solar_suns": 1})):
        res = client.post(path, headers=AUTH, json=body)
        assert cid in problem(res, 409)["detail"], path
    other = client.post("/api/v1/campaigns", headers=AUTH,
                        json={"name": "second", "poses": [{"turntable_deg": 0}]}).json()["id"]
    assert client.post(f"/api/v1/campaigns/{other}/start", headers=AUTH).status_code == 409
    assert client.get("/api/v1/devices").json()["campaign_id"] == cid  # reads still work
    client.post(f"/api/v1/campaigns/{cid}/cancel", headers=AUTH)
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "cancelled"
    assert client.post("/api/v1/devices/turntable/move", headers=AUTH,
                       json={"angle_deg": 5}).status_code == 200


def test_pause_and_resume_finish_every_pose_exactly_once(client):
    poses = [{"turntable_deg": a} for a in range(-50, 60, 20)]
    cid = start_campaign(client, poses)
    wait_campaign(client, cid, lambda s: s["poses_done"] >= 2)
    paused = client.post(f"/api/v1/campaigns/{cid}/pause", headers=AUTH).json()
    assert paused["state"] == "paused" and paused["poses_done"] < len(poses)
    assert paused["current_pose"]["pose_index"] == paused["poses_done"]  # the next one to do
    assert client.post(f"/api/v1/campaigns/{cid}/start", headers=AUTH).status_code == 409
    assert client.post(f"/api/v1/campaigns/{cid}/resume", headers=AUTH).status_code == 200
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "completed" and status["runs"] == 2
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    assert [r["pose_index"] for r in rows] == list(range(len(poses)))
    assert client.post(f"/api/v1/campaigns/{cid}/resume", headers=AUTH).status_code == 409


def test_unknown_campaigns_and_frames_are_404(client):
    missing = "0" * 32
    for path in (f"/api/v1/campaigns/{missing}", f"/api/v1/campaigns/{missing}/results",
                 f"/api/v1/campaigns/{missing}/report", f"/api/v1/campaigns/{missing}/documents",
                 f"/api/v1/campaigns/{missing}/events", f"/api/v1/frames/{missing}",
                 f"/api/v1/frames/{missing}/arrays", "/api/v1/poses/12345"):
        assert client.get(path).status_code == 404, path
    assert client.post(f"/api/v1/campaigns/{missing}/start", headers=AUTH).status_code == 404
