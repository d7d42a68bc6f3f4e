"""``toftwin bench campaign`` measures poses per minute and the time of every stage."""

from __future__ import annotations

import io
import json

import pytest
from rich.console import Console

from benchmarks.campaign import STAGES, run_campaign_benchmark

pytestmark = pytest.mark.timeout(120)


def test_bench_campaign_reports_rates_and_stages(tmp_path, monkeypatch):
    monkeypatch.setenv("TOFTWIN_CAMERA_INTEGRATOR", "direct")
    out = tmp_path / "bench.json"
    console = Console(file=io.StringIO(), width=200)
    # threads instead of the process pool: fast to start (the pool has tests of its own)
    results = run_campaign_benchmark(3, 1, 1, 1, [1, 2], False, out, console,
                                     local_executor="thread")
    assert [r["config"] for r in results] == ["local x1", "local x2"]
    for r in results:
        assert r["poses"] == 3 and r["poses_per_min"] > 0
        assert set(r["stages_s"]) == set(STAGES) and r["stages_s"]["simulate"] > 0
    text = console.file.getvalue()
    assert "poses/min" in text and "speed-up local x2 / local x1" in text
    assert json.loads(out.read_text())["results"][0]["pipeline_depth"] == 1
