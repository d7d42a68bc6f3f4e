"""What a result reports first: the depth difference and the flying and invalid pixels, through
the API, the page's result view, the CSV and the Bluesky documents; results stored before these
figures still read."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from event_model import DocumentNames, schema_validators
from PIL import Image

from service.export.results_table import TOF_FIELDS
from tests.service.api.conftest import AUTH

pytestmark = pytest.mark.timeout(120)

PRE_MIGRATION_DB = Path(__file__).parents[1] / "store" / "data" / "pre_migration.db"


def _digests(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def test_a_pose_reports_its_depth_difference_and_pixels_first(client):
    res = client.post("/api/v1/poses", headers=AUTH,
                      json={"turntable_deg": 30.0, "solar_suns": 1.0})  # the README's pose
    assert res.status_code == 201, res.text
    pose = res.json()
    tof = pose["metrics"]["tof"]
    assert set(tof) >= set(TOF_FIELDS) | {"flying_rule"}
    assert 0 < tof["depth_diff_n_pixels"] <= pose["metrics"]["n_pixels"] <= tof["mask_pixels"]
    assert tof["depth_diff_mad_mm"] >= 0 and tof["depth_diff_p95_abs_mm"] >= 0
    for share in ("flying_share_measured", "flying_share_simulated", "invalid_share_measured",
                  "invalid_share_simulated"):
        assert 0.0 <= tof[share] <= 1.0
    # valid in both frames within the mask: what the invalid shares leave, at most
    assert pose["metrics"]["n_pixels"] <= tof["mask_pixels"] * (
        1 - max(tof["invalid_share_measured"], tof["invalid_share_simulated"])) + 1e-9
    assert client.get(f"/api/v1/poses/{pose['id']}").json() == pose
    # the schema says what the figures are
    schema = client.get("/api/v1/openapi.json").json()["components"]["schemas"]
    assert "depth_diff_median_mm" in schema["ToFFiguresPublic"]["properties"]

    lab = client.app.state.lab
    folders = [lab.store.path(pose[k]) for k in ("measured_frame_id", "simulated_frame_id")]
    before = [_digests(f) for f in folders]

    # the page's result view: the figures first (above the images and Table 5), the grey
    # panels stretched
    html = client.get(f"/ui/poses/{pose['id']}").text
    assert html.index('class="tof-depth"') < html.index('class="panels"') < html.index("Table 5")
    assert f"{tof['depth_diff_median_mm']:+.1f}" in html
    assert "grey [DN], 1st-99th pct of valid pixels" in html
    src = f"/api/v1/poses/{pose['id']}/panels/grey-measured.png"
    assert f'src="{src}"' in html
    shown = np.asarray(Image.open(io.BytesIO(client.get(src).content)))[..., 0]
    stored = np.asarray(Image.open(folders[0] / "grey.png"))
    assert stored.max() <= 10  # the stored grey: black to the eye
    assert shown.max() == 255  # the shown grey: spans the range
    assert client.get(f"{src[:-4]}/colour-bar.png").headers["content-type"] == "image/png"
    assert [_digests(f) for f in folders] == before  # nothing stored was touched


def test_results_stored_before_the_figures_still_read(make_client, tmp_path):
    """A database written by the old code (no ``tof`` in any result): every view of its results
    answers, with the figures empty."""
    data = tmp_path / "old"
    data.mkdir()
    shutil.copyfile(PRE_MIGRATION_DB, data / "toftwin.db")
    client = make_client(data)
    cid = "a" * 32
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    assert len(rows) == 3 and all(r["metrics"]["tof"] is None for r in rows)
    assert rows[0]["metrics"]["range_rmse_m"] == pytest.approx(0.01)  # the old figures kept
    table = list(csv.DictReader(io.StringIO(
        client.get(f"/api/v1/campaigns/{cid}/results?format=csv").text)))
    assert len(table) == 3 and all(row[f] == "" for row in table for f in TOF_FIELDS)
    docs = client.get(f"/api/v1/campaigns/{cid}/documents").json()
    for d in docs:
        schema_validators[DocumentNames[d["name"]]].validate(d["doc"])
    events = [d["doc"] for d in docs if d["name"] == "event"]
    assert events and all(e["data"]["depth_diff_median_mm"] is None for e in events)
    report = client.get(f"/api/v1/campaigns/{cid}/report")
    assert report.status_code == 200
    assert "stored before they were computed" in report.text
    pose = rows[0]["id"]
    assert client.get(f"/api/v1/poses/{pose}").json()["metrics"]["tof"] is None
    assert client.get(f"/ui/poses/{pose}").status_code == 200
    for plot in ("depth-difference", "pixel-shares"):
        svg = client.get(f"/api/v1/campaigns/{cid}/plots/{plot}.svg")
        assert svg.status_code == 200 and "no data yet" in svg.text
    json.dumps(rows)  # strict JSON throughout
