"""A frame file that is there but damaged (cut short, garbage): reads answer 410 naming the frame
and the file inside the data directory, the report and the pose's page show the gap."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.service.api.conftest import problem, start_campaign, wait_campaign


@pytest.fixture
def campaign(client):
    """A completed two-pose campaign: its id and result rows."""
    cid = start_campaign(client, [{"turntable_deg": 0.0}, {"turntable_deg": 20.0}])
    wait_campaign(client, cid, lambda s: s["state"] == "completed")
    return cid, client.get(f"/api/v1/campaigns/{cid}/results").json()


def _cut_short(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _assert_names(detail: str, frame_id: str, name: str, tmp_path: Path) -> None:
    assert f"frame file damaged: {name}" in detail and frame_id in detail, detail
    assert f"frames/{frame_id}/{name}" in detail, detail
    assert str(tmp_path) not in detail, detail  # a place inside the data dir, no server path


def test_a_truncated_raw_npz_leaves_a_gap_in_the_report_and_410s_naming_frame_and_file(
    client, campaign, tmp_path
):
    cid, rows = campaign
    damaged = rows[0]["measured_frame_id"]
    _cut_short(tmp_path / "frames" / damaged / "raw.npz")

    report = client.get(f"/api/v1/campaigns/{cid}/report")
    assert report.status_code == 200
    assert "No images: frame file damaged: raw.npz" in report.text
    assert report.text.count('class="frame-image"') == 6  # the other pose's six panels
    assert str(tmp_path) not in report.text

    page = client.get(f"/ui/poses/{rows[0]['id']}")
    assert page.status_code == 200
    assert "No images: frame file damaged: raw.npz" in page.text
    assert client.get(f"/ui/poses/{rows[1]['id']}").text.count('class="frame-image"') == 6

    for suffix in ("panels/depth-measured.png", "panels/grey-difference/colour-bar.png"):
        res = client.get(f"/api/v1/poses/{rows[0]['id']}/{suffix}")
        body = problem(res, 410)
        assert body["type"] == "urn:toftwin:problem:damaged-file"
        assert body["detail"].startswith(f"pose {rows[0]['id']}: ")
        _assert_names(body["detail"], damaged, "raw.npz", tmp_path)
    _assert_names(problem(client.get(f"/api/v1/frames/{damaged}/raw"), 410)["detail"],
                  damaged, "raw.npz", tmp_path)
    # the pose's other frame and the other pose are whole
    assert client.get(f"/api/v1/frames/{damaged}/arrays").status_code == 200
    assert client.get(f"/api/v1/poses/{rows[1]['id']}/panels/depth-measured.png"
                      ).status_code == 200


@pytest.mark.parametrize(("which", "name", "route"), [
    ("simulated_frame_id", "frame.npz", "arrays"),
    ("simulated_frame_id", "frame.json", ""),
    ("measured_frame_id", "grey.png", "preview/grey.png"),
    ("measured_frame_id", "depth.png", "preview/depth.png"),
])
def test_garbage_or_a_cut_in_any_frame_file_is_a_410_naming_it(
    client, campaign, tmp_path, which, name, route
):
    cid, rows = campaign
    frame_id = rows[1][which]
    path = tmp_path / "frames" / frame_id / name
    if name.endswith(".json"):
        path.write_bytes(b'{"kind": "simulated", "rig": {"turnt')  # cut mid-way
    else:
        path.write_bytes(b"\x89PNG garbage" + bytes(range(256)) * 4)
    res = client.get(f"/api/v1/frames/{frame_id}" + (f"/{route}" if route else ""))
    _assert_names(problem(res, 410)["detail"], frame_id, name, tmp_path)
    if name in ("frame.npz", "frame.json"):  # files the panels read
        report = client.get(f"/api/v1/campaigns/{cid}/report")
        assert report.status_code == 200
        assert f"No images: frame file damaged: {name}" in report.text
        assert report.text.count('class="frame-image"') == 6
