"""The object fit recovers a hidden object reality, and after it a campaign is at the noise
ceiling (issue 14's first must-show).

Random realities of the simulated lab (the mount up to 10 mm and 2 deg off, every mounted
object's reflectance 0.8-1.2, the camera and rig as drawn for issue 13; CI runs the hardest of
the five the issue was shown on, 154, about 9 min on two cores, within its time budget (the CLI's
fit and the default lab's campaign, tests/service/cli/test_fit_object.py and test_object_fit.py,
fit two other realities); ``TOFTWIN_REALITY_SEEDS=151-155`` runs all five, any other seeds too);
the rig counts as
calibrated (:func:`tests.calibration.realities.perfect_calibration` is activated: the reality's
camera and rig keys, never its object keys). A campaign with an object fit (its first five poses'
frames) runs five poses:

- the fitted mount offset is within 1 mm and 0.2 deg of the reality's, every scale the fit calls
  determined within 3 % (and the body and both panels are determined);
- the median over the poses of the depth RMSE against the fitted twin is within 1.25x that of
  the noise ceiling (two captures of the same state), and the median grey PSNR within 1 dB of it.

One set of realities for both: the fit is the campaign's, through the service.
"""

from __future__ import annotations

import csv
import io
import json
import statistics

import pytest
import yaml

from sim_core.scene_spec import ObjectPose, load_scene_spec
from tests.calibration.realities import (
    perfect_calibration,
    pose_errors,
    random_reality,
    reality_seeds,
)
from tests.service.api.conftest import AUTH, start_campaign, wait_campaign
from tests.sim_core.scenes import EXAMPLES

pytestmark = [pytest.mark.slow, pytest.mark.timeout(1800)]

SPEC = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
MOUNTED = [o.name for o in SPEC.objects if o.on_turntable]
POSES = [{"turntable_deg": a, "solar_suns": 1.0} for a in (-60.0, -30.0, 0.0, 30.0, 60.0)]
#: issue 14's targets
POSITION_M, ROTATION_DEG, SCALE_REL = 0.001, 0.2, 0.03
DEPTH_RMSE_RATIO, GREY_PSNR_DB = 1.25, 1.0


@pytest.mark.parametrize("seed", reality_seeds([154]))
def test_after_the_fit_the_campaign_is_at_the_noise_ceiling(make_client, tmp_path, seed):
    reality = random_reality(seed, nominal_power_w=SPEC.illumination.power_w,
                             object_twin_names=MOUNTED)
    path = tmp_path / "reality.yaml"
    path.write_text(yaml.safe_dump(reality.model_dump(mode="json")))
    # The simulated world renders its light to a quarter of its sensor's noise (a real scene
    # has no render noise to freeze into every capture); the twins, to the campaign default.
    client = make_client(tmp_path / "data", reality=path, camera_spp=64,
                         camera_integrator="path", sim_spp=64, camera_noise_fraction=0.25)
    body = perfect_calibration(reality).model_dump(mode="json")
    res = client.put("/api/v1/calibration", headers=AUTH, json=body)
    assert res.status_code == 200, res.text
    cid = start_campaign(client, POSES, object_fit={"poses": 5, "frames": 32})
    status = wait_campaign(client, cid, lambda s: s["state"] != "running", timeout_s=1700)
    assert status["state"] == "completed", status
    fit = status["object_fit"]
    assert fit["state"] == "fitted" and fit["object_twin_hash"] and fit["report"]
    # the object twin: pose and determined scales
    offset = ObjectPose(**fit["object_twin"]["mount"]["pose_offset"])
    dp, dr = pose_errors(offset, reality.mount.pose_offset)
    objects = fit["report"]["objects"]
    scale_err = {n: e["reflectance_scale"] / reality.objects[n].reflectance_scale - 1.0
                 for n, e in objects.items() if e["determined"]}
    print(f"\nreality {seed}: position {dp * 1e3:.2f} mm, rotation {dr:.3f} deg, scales "
          f"{ {n: round(v, 4) for n, v in scale_err.items()} }, fit "
          f"{fit['report']['seconds']['total']:.0f} s")
    for name in ("body", "panel_left", "panel_right"):
        assert objects[name]["determined"], objects[name]
    assert dp <= POSITION_M, fit["report"]["refined"]
    assert dr <= ROTATION_DEG, fit["report"]["refined"]
    for name, err in scale_err.items():
        assert abs(err) <= SCALE_REL, (name, objects[name])
    assert set(fit["object_twin"]["objects"]) == set(scale_err)

    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    ex = [r["metrics"]["explained"] for r in rows]

    def median(twin: str, name: str) -> float:
        return statistics.median(e[twin][name] for e in ex)

    figures = {t: {"depth_rmse_mm": 1e3 * median(t, "depth_rmse_m"),
                   "grey_psnr_db": median(t, "grey_psnr_db")}
               for t in ("nominal", "fitted", "ceiling")}
    print(f"reality {seed}: {json.dumps(figures)}")
    for r, e in zip(rows, ex, strict=True):
        print(f"  pose {r['pose_index']} {r.get('turntable_deg')}: grey nominal "
              f"{e['nominal']['grey_psnr_db']:.2f} fitted {e['fitted']['grey_psnr_db']:.2f} "
              f"ceiling {e['ceiling']['grey_psnr_db']:.2f} dB")
    assert figures["fitted"]["depth_rmse_mm"] <= (
        DEPTH_RMSE_RATIO * figures["ceiling"]["depth_rmse_mm"]), figures
    assert figures["fitted"]["grey_psnr_db"] >= (
        figures["ceiling"]["grey_psnr_db"] - GREY_PSNR_DB), figures
    # the campaign keeps what explains the difference: the fitted twin and its frames
    for r in rows:
        assert r["fitted_frame_id"] and r["fitted_frame_id"] != r["simulated_frame_id"]
        assert client.get(f"/api/v1/frames/{r['fitted_frame_id']}").status_code == 200
    table = list(csv.DictReader(io.StringIO(
        client.get(f"/api/v1/campaigns/{cid}/results?format=csv").text)))
    assert {"fitted_depth_rmse_m", "ceiling_grey_psnr_db", "explained_grey"} <= set(table[0])
    assert "Explained difference (object twin)" in client.get(
        f"/api/v1/campaigns/{cid}/report").text
    # deleting the campaign removes the fitted frames too
    assert client.delete(f"/api/v1/campaigns/{cid}", headers=AUTH).status_code in (200, 204)
    assert client.get(f"/api/v1/frames/{rows[0]['fitted_frame_id']}").status_code == 404
