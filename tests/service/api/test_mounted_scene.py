"""The rig has one object mounted: poses and campaigns of another scene are refused (409).

The simulated lab renders the scene it was started with (``TOFTWIN_SCENE``); a pose of another
scene would compare the satellite's frames with a plane's simulation, with no word of it. The
service says what is mounted (``/health``, the page) and refuses the rest, naming both.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tests.service.api.conftest import AUTH

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
SATELLITE_OBJECTS = ["body", "panel_left", "panel_right", "pedestal"]


def _angle(client) -> float:
    return client.get("/api/v1/devices/turntable/position").json()["angle_deg"]


def _satellite_inline() -> dict:
    return yaml.safe_load((EXAMPLES / "satellite_ground_test.yaml").read_text())


def test_health_and_the_page_say_what_is_mounted(client):
    health = client.get("/api/v1/health").json()
    assert health["mounted_scene"] == "satellite_ground_test"
    assert health["mounted_objects"] == SATELLITE_OBJECTS
    page = client.get("/").text
    assert "Mounted on the turntable: <b>satellite_ground_test</b>" in page
    # the pose and campaign forms offer the mounted scene only
    assert "<option selected>satellite_ground_test</option>" in page
    assert "<option>plane</option>" not in page


@pytest.mark.parametrize("path", ["/api/v1/poses", "/api/v1/campaigns"])
def test_another_bundled_scene_is_refused_naming_both_and_nothing_moves(client, path):
    before = _angle(client)
    body = {"scene": "plane", "turntable_deg": before + 20.0, "solar_suns": 1.0}
    if path.endswith("campaigns"):
        body = {"name": "other", "scene": "plane", "poses": [{"turntable_deg": before + 20.0}]}
    res = client.post(path, headers=AUTH, json=body)
    assert res.status_code == 409, res.text
    assert "'satellite_ground_test'" in res.text and "'plane'" in res.text
    assert _angle(client) == pytest.approx(before, abs=1e-9)
    assert client.get("/api/v1/campaigns").json() == []


def test_an_inline_variant_of_the_mounted_scene_is_accepted_and_another_is_not(client):
    variant = _satellite_inline()
    variant["name"] = "satellite_with_other_film"
    variant["objects"][0]["material"] = "silicon-solar-cell"
    res = client.post("/api/v1/campaigns", headers=AUTH,
                      json={"name": "variant", "scene": variant,
                            "poses": [{"turntable_deg": 0.0}]})
    assert res.status_code == 201, res.text

    other = _satellite_inline()
    other["objects"] = [o for o in other["objects"] if o["name"] != "panel_right"]
    res = client.post("/api/v1/campaigns", headers=AUTH,
                      json={"name": "other", "scene": other, "poses": [{"turntable_deg": 0.0}]})
    assert res.status_code == 409, res.text
    assert "panel_right" in res.text
    assert [c["name"] for c in client.get("/api/v1/campaigns").json()] == ["variant"]


def test_a_stored_campaign_of_another_scene_does_not_start_after_a_remount(make_client, tmp_path):
    first = make_client(tmp_path / "data")
    res = first.post("/api/v1/campaigns", headers=AUTH,
                     json={"name": "satellite", "poses": [{"turntable_deg": 0.0}]})
    assert res.status_code == 201, res.text
    cid = res.json()["id"]
    first.__exit__(None, None, None)

    # the operator mounts the plane's wall and restarts the service with its scene
    second = make_client(tmp_path / "data", scene="plane")
    assert second.get("/api/v1/health").json()["mounted_scene"] == "plane"
    res = second.post(f"/api/v1/campaigns/{cid}/start", headers=AUTH)
    assert res.status_code == 409, res.text
    assert "'plane'" in res.text and "satellite_ground_test" in res.text
    assert second.get(f"/api/v1/campaigns/{cid}").json()["state"] == "created"
