"""A unit that fails after its frame was measured leaves no frame folder behind."""

from __future__ import annotations

from tests.service.api.conftest import start_campaign, wait_campaign


def test_a_failed_campaign_leaves_no_frame_without_a_row(make_client, tmp_path):
    client = make_client(job_timeout_s=1e-4)  # no simulation comes back in time
    cid = start_campaign(client, [{"turntable_deg": a} for a in (0.0, 10.0, 20.0)])
    status = wait_campaign(client, cid, lambda s: s["state"] not in ("created", "running"))
    assert status["state"] == "failed" and "TimeoutError" in status["error"], status
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    named = {r[k] for r in rows for k in ("measured_frame_id", "simulated_frame_id")}
    on_disk = {p.name for p in (tmp_path / "frames").iterdir()}
    assert on_disk == named, f"orphan frames: {on_disk - named}"
