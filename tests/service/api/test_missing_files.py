"""A frame whose folder was lost: reads name it (410), the report shows the gap."""

from __future__ import annotations

import shutil

from tests.service.api.conftest import AUTH, problem, start_campaign, wait_campaign


def test_reads_of_a_lost_frame_answer_410_naming_it_and_the_report_shows_the_gap(
    client, tmp_path
):
    cid = start_campaign(client, [{"turntable_deg": 0.0}, {"turntable_deg": 20.0}])
    wait_campaign(client, cid, lambda s: s["state"] == "completed")
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    lost = rows[0]["measured_frame_id"]
    shutil.rmtree(tmp_path / "frames" / lost)

    for suffix in ("arrays", "raw", "preview/grey.png", "preview/depth.png"):
        res = client.get(f"/api/v1/frames/{lost}/{suffix}")
        detail = problem(res, 410)["detail"]
        assert lost in detail and "gone" in detail, suffix
    assert client.get(f"/api/v1/frames/{lost}").status_code == 200  # the row is still there

    report = client.get(f"/api/v1/campaigns/{cid}/report")
    assert report.status_code == 200
    assert f"No images: frame {lost}" in report.text
    # the other pose keeps its six panels (an image and its colour bar each)
    assert report.text.count('class="frame-image"') == 6
    assert report.text.count("<img") == 12
    # the other pose's frames are untouched
    assert client.get(f"/api/v1/frames/{rows[1]['measured_frame_id']}/arrays").status_code == 200
    assert client.get(f"/api/v1/campaigns/{cid}/results", headers=AUTH).status_code == 200
