"""Operators reclaim space: a campaign (not while it runs) or a lone frame, rows and files."""

from __future__ import annotations

from tests.service.api.conftest import AUTH, problem, start_campaign, wait_campaign


def test_a_finished_campaign_is_deleted_with_its_results_and_frames(client, tmp_path):
    cid = start_campaign(client, [{"turntable_deg": 0.0}, {"turntable_deg": 15.0}])
    wait_campaign(client, cid, lambda s: s["state"] == "completed")
    other = start_campaign(client, [{"turntable_deg": 30.0}])
    wait_campaign(client, other, lambda s: s["state"] == "completed")
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    frames = {r[k] for r in rows for k in ("measured_frame_id", "simulated_frame_id")}
    assert all((tmp_path / "frames" / f).is_dir() for f in frames)

    assert client.delete(f"/api/v1/campaigns/{cid}").status_code == 401
    assert client.delete(f"/api/v1/campaigns/{cid}", headers=AUTH).status_code == 204
    assert client.get(f"/api/v1/campaigns/{cid}").status_code == 404
    assert client.get(f"/api/v1/campaigns/{cid}/results").status_code == 404
    assert not any((tmp_path / "frames" / f).exists() for f in frames)
    assert all(client.get(f"/api/v1/frames/{f}").status_code == 404 for f in frames)
    # the other campaign is untouched
    assert client.get(f"/api/v1/campaigns/{other}").json()["poses_done"] == 1
    assert client.delete(f"/api/v1/campaigns/{cid}", headers=AUTH).status_code == 404


def test_a_running_campaign_cannot_be_deleted(client):
    cid = start_campaign(client, [{"turntable_deg": a} for a in range(-60, 70, 10)])
    wait_campaign(client, cid, lambda s: s["poses_done"] >= 1)
    res = client.delete(f"/api/v1/campaigns/{cid}", headers=AUTH)
    assert "running" in problem(res, 409)["detail"]
    client.post(f"/api/v1/campaigns/{cid}/cancel", headers=AUTH)
    wait_campaign(client, cid, lambda s: s["state"] == "cancelled")
    assert client.delete(f"/api/v1/campaigns/{cid}", headers=AUTH).status_code == 204


def test_a_lone_frame_is_deleted_but_not_one_a_result_compares(client, tmp_path):
    fid = client.post("/api/v1/devices/camera/capture", headers=AUTH).json()["frame_id"]
    assert (tmp_path / "frames" / fid).is_dir()
    assert client.delete(f"/api/v1/frames/{fid}").status_code == 401
    assert client.delete(f"/api/v1/frames/{fid}", headers=AUTH).status_code == 204
    assert not (tmp_path / "frames" / fid).exists()
    assert client.get(f"/api/v1/frames/{fid}").status_code == 404

    pose = client.post("/api/v1/poses", headers=AUTH,
                       json={"turntable_deg": 10.0, "solar_suns": 1.0}).json()
    res = client.delete(f"/api/v1/frames/{pose['measured_frame_id']}", headers=AUTH)
    assert str(pose["id"]) in problem(res, 409)["detail"]
    assert client.get(f"/api/v1/frames/{pose['measured_frame_id']}/arrays").status_code == 200
