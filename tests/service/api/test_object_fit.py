"""Campaigns with an object fit: the fit stage, the explained difference per pose, refusals."""

from __future__ import annotations

import csv
import io

import pytest

from tests.service.api.conftest import AUTH, start_campaign, wait_campaign

pytestmark = pytest.mark.timeout(900)

POSES = [{"turntable_deg": a, "solar_suns": 1.0} for a in (-30.0, 0.0, 30.0)]


@pytest.mark.parametrize(("value", "field"), [
    (1, "object_fit"),
    ("yes", "object_fit"),
    ({"poses": 0}, "object_fit.poses"),
    ({"frames": 1000}, "object_fit.frames"),
    ({"poses": 3, "colour": "red"}, "object_fit.colour"),
    ({"effects": "some"}, "object_fit.effects"),
    ({"noise_fraction": 0.0}, "object_fit.noise_fraction"),
    ({"noise_fraction": 2.5}, "object_fit.noise_fraction"),
    ({"noise_fraction": "half"}, "object_fit.noise_fraction"),
])
def test_bad_object_fit_settings_are_422_naming_the_field(client, value, field):
    res = client.post("/api/v1/campaigns", headers=AUTH,
                      json={"name": "x", "poses": POSES, "object_fit": value})
    assert res.status_code == 422, res.text
    assert field in res.text
    assert client.get("/api/v1/campaigns").json() == []  # nothing stored


def test_a_scene_without_a_mounted_object_has_nothing_to_fit(client):
    scene = {"camera": {"pose": {"position_m": [0, -1, 0.2], "look_at_m": [0, 0, 0.2]}},
             "objects": [{"name": "wall", "mesh": {"kind": "rectangle", "size_m": [2, 2]},
                          "material": "grey-diffuse",
                          "pose": {"position_m": [0, 1, 0], "rotation_deg": [90, 0, 0]}}]}
    res = client.post("/api/v1/campaigns", headers=AUTH,
                      json={"name": "x", "poses": POSES, "scene": scene, "object_fit": True})
    assert res.status_code == 422, res.text
    assert "object_fit" in res.text and "no object on the turntable" in res.text


@pytest.mark.slow
def test_a_campaign_fits_the_object_then_explains_every_pose(make_client, tmp_path):
    """The default simulated lab (its reality moves the mount by 4/-3/2 mm and dims every object
    by 8 %): the fit stage runs first, then each pose is compared with the nominal twin, the
    fitted twin and a second capture."""
    client = make_client(tmp_path / "data", camera_spp=16, camera_integrator="path",
                         sim_spp=16)
    cid = start_campaign(client, POSES, object_fit={"poses": 3, "frames": 8})
    status = wait_campaign(client, cid, lambda s: s["state"] != "running", timeout_s=850)
    assert status["state"] == "completed", status
    fit = status["object_fit"]
    assert fit["state"] == "fitted" and fit["object_twin_hash"]
    offset = fit["object_twin"]["mount"]["pose_offset"]["position_m"]
    assert offset != [0.0, 0.0, 0.0]
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    assert len(rows) == len(POSES)
    for r in rows:
        ex = r["metrics"]["explained"]
        assert set(ex) >= {"nominal", "fitted", "ceiling", "explained"}, ex
        assert r["fitted_frame_id"] and r["fitted_frame_id"] != r["simulated_frame_id"]
        # both twins render to the default noise fraction (more samples on glints)
        for fid in (r["fitted_frame_id"], r["simulated_frame_id"]):
            meta = client.get(f"/api/v1/frames/{fid}").json()["metadata"]
            assert meta["adaptive"]["target_noise_fraction"] == 0.35, meta.get("adaptive")
            assert meta["adaptive"]["spp_min"] >= 16
        # the fitted twin is closer to the measurement than the nominal one
        assert ex["fitted"]["grey_psnr_db"] > ex["nominal"]["grey_psnr_db"]
    table = list(csv.DictReader(io.StringIO(
        client.get(f"/api/v1/campaigns/{cid}/results?format=csv").text)))
    assert {"fitted_depth_rmse_m", "ceiling_grey_psnr_db", "explained_grey"} <= set(table[0])
    html = client.get(f"/api/v1/campaigns/{cid}/report").text
    assert "Explained difference (object twin)" in html
    # deleting the campaign removes the fitted frames too
    assert client.delete(f"/api/v1/campaigns/{cid}", headers=AUTH).status_code in (200, 204)
    assert client.get(f"/api/v1/frames/{rows[0]['fitted_frame_id']}").status_code == 404
