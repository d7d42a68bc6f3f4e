"""The object fit recovers a hidden object reality, and after it a campaign is at the noise
ceiling (issue 14's first must-show) in a world with what a real rig adds (issue 27): without the
models of those effects, the campaign names an unexplained residual and where it is.

Random realities of the simulated lab (the mount up to 10 mm and 2 deg off, every mounted
object's reflectance 0.8-1.2, the camera and rig as drawn for issue 13) with issue 27's three
effects in the world (:func:`tests.calibration.realities.with_world_effects`: the warm-up drift,
stray light and the table's settling). CI runs one reality per half: 154 with the effects' models,
155 without them (``TOFTWIN_REALITY_SEEDS=151-155`` runs issue 27's five in both, any other seeds
too). A campaign with an object fit (its first five poses' frames; three without the models)
runs five poses.

With the effects' models (the rig counted as calibrated:
:func:`tests.calibration.realities.perfect_calibration`, the reality's camera and rig keys with
its ``camera.temperature``, ``camera.stray_light`` and ``turntable.settling``, never its object
keys):

- the fitted mount offset is within 1 mm and 0.2 deg of the reality's, every scale the fit calls
  determined within 3 % (and the body and both panels are determined);
- the median over the poses of the depth RMSE against the fitted twin is within 1.25x that of
  the noise ceiling (two captures of the same state), and the median grey PSNR within 1 dB of it.

Without them (the same calibration less those three keys: no drift applied, no stray light, no
wait for the ringing): every pose whose fitted twin is beyond the ceiling carries an
``unexplained`` entry that says by how much and where, the results, the CSV and the report say
so, and at least one pose is. That last claim holds only where the effects exceed one capture's
noise (issue 27, blocked on its wording): on 151-153 they do not, and 154 sits on the line (its
face-on pose's grey PSNR was beyond the 1 dB line before issue 30's renderer changes and 0.92 dB
below the ceiling's after them: the fit's path moves with the renderer's rounding); 155's
face-on pose is 17 dB below it.
"""

from __future__ import annotations

import csv
import io
import json
import statistics
from typing import Any

import pytest
import yaml

from service.lab.comparison import beyond_ceiling
from sim_core.scene_spec import ObjectPose, load_scene_spec
from tests.calibration.realities import (
    perfect_calibration,
    pose_errors,
    random_reality,
    reality_seeds,
    with_world_effects,
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
#: issue 27's effects: the calibration keys of their models
EFFECT_KEYS = (("camera", "temperature"), ("camera", "stray_light"), ("turntable", "settling"))


def world(seed: int):
    """The reality of ``seed`` with all three of issue 27's effects in the world."""
    return with_world_effects(random_reality(seed, nominal_power_w=SPEC.illumination.power_w,
                                             object_twin_names=MOUNTED), seed)


def run_campaign(make_client, tmp_path, reality, calibration: dict[str, Any],
                 frames: int, fit_poses: int = 5) -> tuple[Any, str, dict, list[dict]]:
    """The satellite campaign with an object fit on the simulated lab of ``reality``, under
    ``calibration``: the client, the campaign's id, its status and its results."""
    path = tmp_path / "reality.yaml"
    path.write_text(yaml.safe_dump(reality.model_dump(mode="json")))
    # The simulated world renders its light to a quarter of its sensor's noise (a real scene
    # has no render noise to freeze into every capture); the twins, to the campaign default.
    client = make_client(tmp_path / "data", reality=path, camera_spp=64,
                         camera_integrator="path", sim_spp=64, camera_noise_fraction=0.25)
    res = client.put("/api/v1/calibration", headers=AUTH, json=calibration)
    assert res.status_code == 200, res.text
    cid = start_campaign(client, POSES, object_fit={"poses": fit_poses, "frames": frames})
    status = wait_campaign(client, cid, lambda s: s["state"] != "running", timeout_s=1700)
    assert status["state"] == "completed", status
    return client, cid, status, client.get(f"/api/v1/campaigns/{cid}/results").json()


def figures(seed: int, label: str, rows: list[dict]) -> dict[str, dict[str, float]]:
    """The medians over the poses of each twin's depth RMSE [mm] and grey PSNR [dB], printed
    with every pose's figures and unexplained lines."""
    ex = [r["metrics"]["explained"] for r in rows]
    out = {t: {"depth_rmse_mm": 1e3 * statistics.median(e[t]["depth_rmse_m"] for e in ex),
               "grey_psnr_db": statistics.median(e[t]["grey_psnr_db"] for e in ex)}
           for t in ("nominal", "fitted", "ceiling")}
    print(f"\nreality {seed} ({label}): {json.dumps(out)}")
    for r, e in zip(rows, ex, strict=True):
        print(f"  pose {r['pose_index']} {r.get('turntable_deg')}: depth RMSE nominal "
              f"{1e3 * e['nominal']['depth_rmse_m']:.2f} fitted "
              f"{1e3 * e['fitted']['depth_rmse_m']:.2f} ceiling "
              f"{1e3 * e['ceiling']['depth_rmse_m']:.2f} mm; grey nominal "
              f"{e['nominal']['grey_psnr_db']:.2f} fitted {e['fitted']['grey_psnr_db']:.2f} "
              f"ceiling {e['ceiling']['grey_psnr_db']:.2f} dB")
        for t in ("fitted", "ceiling"):
            tof = e[t].get("tof") or {}
            print(f"    {t} depth difference: median {tof.get('depth_diff_median_mm')} mm, MAD "
                  f"{tof.get('depth_diff_mad_mm')} mm over {tof.get('depth_diff_n_pixels')} pixels")
        for u in e["unexplained"]:
            print(f"    unexplained {u['text']}")
    return out


def summary_line(client, cid: str) -> str:
    """The report's line on the unexplained residual."""
    html = client.get(f"/api/v1/campaigns/{cid}/report").text
    assert "Explained difference (object twin)" in html
    line = html.split('<p class="unexplained">')[1].split("</p>")[0]
    print(f"  report: {line}")
    return line


@pytest.mark.parametrize("seed", reality_seeds([154]))
def test_after_the_fit_the_campaign_is_at_the_noise_ceiling(make_client, tmp_path, seed):
    reality = world(seed)
    calibration = perfect_calibration(reality).model_dump(mode="json")
    for room, key in EFFECT_KEYS:  # the effects' models are in the calibration
        assert calibration[room][key] is not None, (room, key)
    client, cid, status, rows = run_campaign(make_client, tmp_path, reality, calibration, 32)
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
    medians = figures(seed, "with the effects' models", rows)
    summary_line(client, cid)
    for name in ("body", "panel_left", "panel_right"):
        assert objects[name]["determined"], objects[name]
    assert dp <= POSITION_M, fit["report"]["refined"]
    assert dr <= ROTATION_DEG, fit["report"]["refined"]
    for name, err in scale_err.items():
        assert abs(err) <= SCALE_REL, (name, objects[name])
    assert set(fit["object_twin"]["objects"]) == set(scale_err)
    assert medians["fitted"]["depth_rmse_mm"] <= (
        DEPTH_RMSE_RATIO * medians["ceiling"]["depth_rmse_mm"]), medians
    assert medians["fitted"]["grey_psnr_db"] >= (
        medians["ceiling"]["grey_psnr_db"] - GREY_PSNR_DB), medians
    # the campaign keeps what explains the difference: the fitted twin and its frames
    for r in rows:
        assert r["fitted_frame_id"] and r["fitted_frame_id"] != r["simulated_frame_id"]
        assert client.get(f"/api/v1/frames/{r['fitted_frame_id']}").status_code == 200
    table = list(csv.DictReader(io.StringIO(
        client.get(f"/api/v1/campaigns/{cid}/results?format=csv").text)))
    assert {"fitted_depth_rmse_m", "ceiling_grey_psnr_db", "explained_grey",
            "unexplained_depth", "unexplained_grey"} <= set(table[0])
    # deleting the campaign removes the fitted frames too
    assert client.delete(f"/api/v1/campaigns/{cid}", headers=AUTH).status_code in (200, 204)
    assert client.get(f"/api/v1/frames/{rows[0]['fitted_frame_id']}").status_code == 404


@pytest.mark.parametrize("seed", reality_seeds([155]))
def test_without_the_effects_models_the_report_names_the_unexplained_residual(
        make_client, tmp_path, seed):
    reality = world(seed)
    calibration = perfect_calibration(reality).model_dump(mode="json")
    for room, key in EFFECT_KEYS:
        calibration[room].pop(key)
    # a shorter fit than the one above (its first three poses, 16 frames a view): what is shown
    # is the residual on all five
    client, cid, _, rows = run_campaign(make_client, tmp_path, reality, calibration, 16,
                                        fit_poses=3)
    figures(seed, "without the effects' models", rows)
    line = summary_line(client, cid)
    table = list(csv.DictReader(io.StringIO(
        client.get(f"/api/v1/campaigns/{cid}/results?format=csv").text)))
    beyond = 0
    for r, t in zip(rows, table, strict=True):
        e = r["metrics"]["explained"]
        channels = beyond_ceiling(e["fitted"], e["ceiling"])
        # a pose beyond the ceiling names each channel, by how much and where; one within it,
        # nothing
        assert [u["channel"] for u in e["unexplained"]] == list(channels), e["unexplained"]
        for u in e["unexplained"]:
            assert u["where"] is not None and u["where"]["excess_ms"] > 0.0, u
            assert u["text"].startswith(channels[u["channel"]] + ": "), u
            assert u["where"]["text"] != "within the noise", u
            assert t[f"unexplained_{u['channel']}"] == u["text"]
        beyond += bool(channels)
    assert beyond >= 1, "the world's drift, stray light and ringing left no pose beyond the ceiling"
    assert line.startswith(f"unexplained residual on {beyond} of {len(rows)} poses: "), line
