"""One pose end to end, single simulations, frames, access and input checks."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from service.cli import app as toftwin_app
from tests.service.api.conftest import AUTH, problem

pytestmark = pytest.mark.timeout(120)

SMALL_SCENE = {
    "name": "plane",
    "camera": {"pose": {"position_m": [0, 0, 0], "look_at_m": [0, 0, 1], "up": [0, -1, 0]},
               "width_px": 32, "height_px": 24},
    "objects": [{"name": "wall", "mesh": {"kind": "rectangle", "size_m": [3, 3]},
                 "material": {"kind": "lambertian", "params": {"albedo": 0.5}},
                 "pose": {"position_m": [0, 0, 1.5], "rotation_deg": [180, 0, 0]}}],
}


def test_a_pose_moves_captures_simulates_and_compares(client):
    res = client.post("/api/v1/poses", headers=AUTH,
                      json={"turntable_deg": 30.0, "solar_suns": 1.0})
    assert res.status_code == 201, res.text
    pose = res.json()
    m = pose["metrics"]
    assert m["n_pixels"] > 500  # the satellite on the turntable, about 1 m away
    assert 800 < m["depth"]["mean_measured"] < 1100 and 800 < m["depth"]["mean_simulated"] < 1100
    assert 0.5 < m["depth"]["ssim"] <= 1.0 and m["grey"]["psnr_db"] > 5
    assert [r[:2] for r in pose["table"][:2]] == [["Grey", "Mean"], ["Grey", "Var"]]
    assert pose["rig"]["turntable_angle_deg"] == pytest.approx(30.0, abs=0.01)
    assert set(pose["timings_s"]) >= {"move", "capture", "simulate", "compare", "store"}
    assert client.get(f"/api/v1/poses/{pose['id']}").json() == pose

    # both frames are stored, with metadata, arrays and previews
    for fid, kind in ((pose["measured_frame_id"], "measured"),
                      (pose["simulated_frame_id"], "simulated")):
        meta = client.get(f"/api/v1/frames/{fid}").json()
        assert meta["kind"] == kind and meta["metadata"]["frame_id"] == fid
        arrays = np.load(io.BytesIO(client.get(f"/api/v1/frames/{fid}/arrays").content))
        assert arrays["range_m"].shape == (171, 224) and arrays["valid"].any()
        png = client.get(f"/api/v1/frames/{fid}/preview/depth.png")
        assert png.headers["content-type"] == "image/png"
        assert np.asarray(Image.open(io.BytesIO(png.content))).dtype == np.uint16
    sim_meta = client.get(f"/api/v1/frames/{pose['simulated_frame_id']}").json()["metadata"]
    assert sim_meta["effect_plan"]["effects"] and sim_meta["turntable_object_ids"] == [0, 1, 2, 3]


def test_a_region_mask_counts_only_its_pixels(client):
    res = client.post("/api/v1/poses", headers=AUTH, json={
        "turntable_deg": 0.0, "solar_suns": 0.0,
        "mask": {"kind": "region", "rows": [60, 110], "cols": [90, 135]}})
    assert res.status_code == 201, res.text
    assert 0 < res.json()["metrics"]["n_pixels"] <= 50 * 45


def test_simulate_returns_a_frame_and_its_effect_plan(client):
    res = client.post("/api/v1/simulate", headers=AUTH,
                      json={"scene": SMALL_SCENE, "effects": "all", "seed": 3})
    assert res.status_code == 201, res.text
    body = res.json()
    assert {e["name"] for e in body["effect_plan"]["effects"]} >= {"multipath", "noise"}
    arrays = np.load(io.BytesIO(client.get(body["links"]["arrays"]).content))
    assert arrays["range_m"].shape == (24, 32)
    assert np.nanmedian(arrays["range_m"]) == pytest.approx(1.5, abs=0.1)


def test_inline_scenes_may_not_read_files_on_the_server(client):
    scene = json.loads(json.dumps(SMALL_SCENE))
    scene["objects"][0]["mesh"] = {"kind": "file", "path": "/etc/passwd"}
    res = client.post("/api/v1/simulate", headers=AUTH, json={"scene": scene})
    assert "scene.objects[0].mesh.kind" in problem(res, 422)["detail"]


def test_calls_that_change_things_need_the_token(client):
    for path, body in (("/api/v1/poses", {"turntable_deg": 0, "solar_suns": 1}),
                       ("/api/v1/devices/turntable/move", {"angle_deg": 10}),
                       ("/api/v1/campaigns", {"name": "x", "poses": [{"turntable_deg": 0}]}),
                       ("/api/v1/devices/stop", None)):
        assert client.post(path, json=body).status_code == 401
        res = client.post(path, json=body, headers={"Authorization": "Bearer wrong-token-xyz"})
        assert res.status_code == 401 and res.headers["www-authenticate"] == "Bearer"
    assert client.get("/api/v1/devices").status_code == 200  # reading is open
    assert client.get("/api/v1/campaigns").json() == []


def test_a_bad_angle_or_level_is_422_naming_the_field_and_changes_nothing(client):
    before = client.get("/api/v1/devices/turntable/position").json()["angle_deg"]
    res = client.post("/api/v1/devices/turntable/move", headers=AUTH, json={"angle_deg": 200})
    body = problem(res, 422)
    assert body["detail"].startswith("angle_deg:") and "[-170, 170] deg" in body["detail"]
    assert [e["field"] for e in body["errors"]] == ["angle_deg"]
    res = client.post("/api/v1/poses", headers=AUTH, json={"turntable_deg": 500, "solar_suns": 1})
    assert "turntable_deg: got 500" in problem(res, 422)["detail"]
    res = client.post("/api/v1/poses", headers=AUTH, json={"turntable_deg": 0, "solar_suns": 1.5})
    detail = problem(res, 422)["detail"]
    assert "solar_suns" in detail and "0.8 to 1.2 sun" in detail
    res = client.post("/api/v1/devices/solar/level", headers=AUTH, json={"suns": 0.5})
    assert "suns: got 0.5 sun" in problem(res, 422)["detail"]
    res = client.post("/api/v1/campaigns", headers=AUTH, json={
        "name": "bad", "poses": [{"turntable_deg": 0}, {"turntable_deg": 175}]})
    body = problem(res, 422)
    assert body["detail"].startswith("poses[1].turntable_deg:")
    assert body["errors"][0]["field"] == "poses[1].turntable_deg"
    res = client.post("/api/v1/campaigns", headers=AUTH, json={
        "name": "bad", "poses": [{"turntable_deg": 0, "solar_suns": 2.0}]})
    assert "poses[0].solar_suns" in problem(res, 422)["detail"]
    # nothing stored, nothing moved
    assert client.get("/api/v1/campaigns").json() == []
    assert client.get("/api/v1/frames").json() == []
    assert client.get("/api/v1/devices/turntable/position").json()["angle_deg"] == before


def test_request_bodies_are_bounded(make_client, tmp_path):
    client = make_client(tmp_path / "small", max_body_bytes=4096)
    big = {"name": "x" * 8000, "poses": [{"turntable_deg": 0}]}
    body = problem(client.post("/api/v1/campaigns", headers=AUTH, json=big), 413)
    assert body["type"] == "urn:toftwin:problem:content-too-large"
    assert "4096 bytes" in body["detail"]
    # without a Content-Length (chunked), counted as it arrives
    chunks = iter([b'{"name": "' + b"x" * 3000, b"x" * 3000 + b'", "poses": []}'])
    res = client.post("/api/v1/campaigns", content=chunks,
                      headers={**AUTH, "Content-Type": "application/json"})
    assert "TOFTWIN_MAX_BODY_BYTES" in problem(res, 413)["detail"]
    assert client.get("/api/v1/campaigns").json() == []


def test_manual_devices_report_and_obey(client):
    assert client.post("/api/v1/devices/turntable/move", headers=AUTH,
                       json={"angle_deg": -20}).json()["angle_deg"] == pytest.approx(-20, abs=0.01)
    assert client.post("/api/v1/devices/solar/lamp", headers=AUTH, json={"on": True}).json()[
        "lamp_on"]
    level = client.post("/api/v1/devices/solar/level", headers=AUTH, json={"suns": 1.1}).json()
    assert level["suns"] == pytest.approx(1.1, abs=0.02)
    assert client.post("/api/v1/devices/solar/shutter", headers=AUTH,
                       json={"open": True}).json()["shutter_open"]
    cap = client.post("/api/v1/devices/camera/capture", headers=AUTH)
    assert cap.status_code == 201 and cap.json()["rig"]["shutter_open"]
    stop = client.post("/api/v1/devices/stop", headers=AUTH).json()
    assert stop == {"stopped": ["turntable", "shutter"], "errors": {}, "campaign_paused": None,
                    "calibration_cancelled": None}
    devices = {d["name"]: d for d in client.get("/api/v1/devices").json()["devices"]}
    assert all(d["ok"] for d in devices.values())
    assert devices["solar_simulator"]["details"]["shutter_open"] is False


def test_compare_cli_prints_table_5_and_writes_json(client, tmp_path):
    pose = client.post("/api/v1/poses", headers=AUTH,
                       json={"turntable_deg": 45.0, "solar_suns": 1.0}).json()
    frames = tmp_path / "frames"
    out = tmp_path / "cmp.json"
    res = CliRunner().invoke(toftwin_app, [
        "compare", str(frames / pose["measured_frame_id"]),
        str(frames / pose["simulated_frame_id"]), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "PSNR" in res.output and "Chi-square" in res.output
    # the depth difference and the pixel shares first, as the service stores them
    assert res.output.index("depth sim - meas: median") < res.output.index("PSNR")
    assert "flying pixels: measured" in res.output
    data = json.loads(out.read_text())
    cli_tof, tof = data["metrics"]["tof"], pose["metrics"]["tof"]
    assert cli_tof.pop("flying_rule") == tof.pop("flying_rule")
    assert cli_tof == pytest.approx(tof)
    # the CLI's default mask (turntable objects) gives the service's numbers
    assert data["metrics"]["n_pixels"] == pose["metrics"]["n_pixels"]
    assert data["metrics"]["depth"]["ssim"] == pytest.approx(pose["metrics"]["depth"]["ssim"])
    res = CliRunner().invoke(toftwin_app, [
        "compare", str(frames / pose["measured_frame_id"]),
        str(frames / pose["simulated_frame_id"]), "--mask", "depth_window", "--out", str(out)])
    assert res.exit_code == 2 and "near_m" in res.output
