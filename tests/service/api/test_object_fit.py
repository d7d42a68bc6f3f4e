"""Campaigns with an object fit: the fit stage, the explained difference per pose, refusals."""

from __future__ import annotations

import pytest

from tests.service.api.conftest import AUTH

pytestmark = pytest.mark.timeout(900)

POSES = [{"turntable_deg": a, "solar_suns": 1.0} for a in (-30.0, 0.0, 30.0)]


@pytest.mark.parametrize(("value", "field"), [
    (1, "object_fit"),
    ("yes", "object_fit"),
    ({"poses": 0}, "object_fit.poses"),
    ({"frames": 1000}, "object_fit.frames"),
    ({"poses": 3, "colour": "red"}, "object_fit.colour"),
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


# The campaign's fit stage and its explained difference on the simulated lab: the slow test of
# tests/service/api/test_object_fit_realities.py (five random realities).
