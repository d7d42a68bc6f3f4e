"""The twin applies a calibrated warm-up drift at each measured frame's temperature (issue 27).

Real app, real SQLite, the simulated rig whose reality warms up: the measured frame reports its
illumination temperature (through the USB wire), the frame store keeps it, and the pose's
simulation applies the calibration's drift at it.
"""

from __future__ import annotations

import pytest
import yaml

from tests.service.api.conftest import AUTH

pytestmark = pytest.mark.timeout(120)

WARM_UP = {"illumination_start_c": 25.0, "illumination_end_c": 45.0, "time_constant_s": 2.0,
           "depth_drift_mm_per_c": 2.0}


def test_a_pose_is_simulated_at_its_measured_frames_temperature(tmp_path, make_client):
    reality = tmp_path / "reality.yaml"
    reality.write_text(yaml.safe_dump({"camera": {"temperature": WARM_UP}}))
    client = make_client(tmp_path / "data", reality=reality)
    res = client.put("/api/v1/calibration", headers=AUTH,
                     json={"camera": {"temperature": WARM_UP}})
    assert res.status_code == 200, res.text
    for angle in (0.0, 60.0):  # the move of 60 deg takes the lab's clock 3.25 s: the lamp warms
        res = client.post("/api/v1/poses", headers=AUTH, json={"turntable_deg": angle,
                                                               "solar_suns": 0.0})
    assert res.status_code == 201, res.text
    pose = res.json()
    measured = client.get(f"/api/v1/frames/{pose['measured_frame_id']}").json()["metadata"]
    temperature_c = measured["illumination_temperature_c"]
    assert 30.0 < temperature_c < 45.0
    simulated = client.get(f"/api/v1/frames/{pose['simulated_frame_id']}").json()["metadata"]
    assert simulated["illumination_temperature_c"] == temperature_c
    drift = next(e for e in simulated["effect_plan"]["effects"]
                 if e["name"] == "temperature_drift")
    assert drift["enabled"]
    assert drift["numbers"]["illumination_temperature_c"] == temperature_c
    assert drift["numbers"]["range_drift_mm"] == pytest.approx(
        [2.0 * (temperature_c - 25.0)])
    # measured and simulated agree on the drifted depth (tens of mm without the drift)
    d = pose["metrics"]["depth"]
    assert abs(d["mean_measured"] - d["mean_simulated"]) < 0.5 * 2.0 * (temperature_c - 25.0)
