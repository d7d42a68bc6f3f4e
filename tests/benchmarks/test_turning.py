"""``toftwin bench turning``: a campaign captured while turning on the simulated lab."""

from __future__ import annotations

import io
import json

import pytest
from rich.console import Console

from benchmarks.turning import run_turning_campaign

pytestmark = pytest.mark.timeout(180)


@pytest.mark.slow
def test_a_turning_campaign_reports_rates_and_edge_errors(tmp_path, monkeypatch):
    monkeypatch.setenv("TOFTWIN_CAMERA_INTEGRATOR", "direct")
    out = tmp_path / "turning.json"
    console = Console(file=io.StringIO(), width=200)
    r = run_turning_campaign(10.0, 2, 10.0, 1, 1, None, out, console)
    assert r["poses"] == 2 and len(r["poses_detail"]) == 2
    # the sweep never stops: it beats stop and go, which waits for the settling at every pose
    assert r["turning_poses_per_min"] > r["stop_and_go_poses_per_min"] > 0
    assert r["settle_wait_s"] > 0
    for pose in r["poses_detail"]:
        # each frame was taken after the table passed its pose, moving at 10 deg/s, and before
        # the next pose (10 deg on): the recorded angle is the frame's start, whatever the
        # latency. That is a poll and a frame request, plus whatever render the simulated
        # camera has in hand (its frames come at render pace: a few ms on a quiet machine,
        # 176 ms once with CI's two workers and an install beside it)
        assert 0.0 <= pose["frame_start_deg"] - pose["turntable_deg"] < 5.0
        assert pose["edges"]["edge_pixels"] > 0 and pose["edges"]["interior_pixels"] > 0
        same = pose["edges_same_pixels"]
        assert same["at_rest"]["edge_pixels"] == same["with_subframes"]["edge_pixels"]
    text = console.file.getvalue()
    assert "poses per minute" in text and "depth error" in text
    assert json.loads(out.read_text())["turning_deg_s"] == 10.0
