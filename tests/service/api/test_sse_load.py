"""Fifty browsers following a campaign of 30,000 results do not slow the service down.

A real server (``python -m toftwin_cli serve --simulated``) on a database holding one paused
campaign with 30,000 results; fifty clients follow its event stream while ``/health`` is timed.
A stream sends the status when it changes and otherwise asks the database one small question
per interval, so the followers cost next to nothing.
"""

from __future__ import annotations

import statistics
import threading
import time
import uuid
from pathlib import Path

import httpx
import pytest
from sqlalchemy import insert

from service.store import queries
from service.store.database import init_db, make_engine
from service.store.tables import FrameRow, PoseResultRow
from tests.service.api.conftest import AUTH
from tests.service.api.test_crash_resume import server

pytestmark = [pytest.mark.timeout(300), pytest.mark.slow]

POSES, REPEATS, CLIENTS = 300, 100, 50


def _big_campaign(data_dir: Path, poses: int = POSES, repeats: int = REPEATS) -> str:
    """A paused campaign with ``poses`` x ``repeats`` results, written straight into the
    database."""
    data_dir.mkdir(parents=True)
    engine = make_engine(f"sqlite:///{data_dir / 'toftwin.db'}")
    sessions = init_db(engine)
    cid = uuid.uuid4().hex
    with sessions() as s:
        queries.create_campaign(
            s, campaign_id=cid, name="big", scene_name="satellite_ground_test",
            scene_json="{}", scene_base_dir=".", mask={"kind": "all"}, seed=0, spp=1,
            poses=[(float(i % 340 - 170), 1.0, repeats) for i in range(poses)],
        )
        frames, results, t = [], [], time.time()
        for p in range(poses):
            for r in range(repeats):
                m, sim = uuid.uuid4().hex, uuid.uuid4().hex
                frames += [{"id": m, "kind": "measured", "campaign_id": cid, "created_at": t},
                           {"id": sim, "kind": "simulated", "campaign_id": cid, "created_at": t}]
                results.append({
                    "campaign_id": cid, "pose_index": p, "repeat": r, "turntable_deg": 0.0,
                    "solar_suns": 1.0, "measured_frame_id": m, "simulated_frame_id": sim,
                    "metrics_json": "{}", "rig_json": "{}", "timings_json": "{}",
                    "created_at": t})
        s.execute(insert(FrameRow), frames)
        s.execute(insert(PoseResultRow), results)
        s.commit()
        queries.transition(s, cid, ("created",), "paused", error="operator")
    engine.dispose()
    return cid


def test_fifty_followers_of_a_30000_result_campaign_keep_health_fast(tmp_path):
    data = tmp_path / "data"
    cid = _big_campaign(data)
    stop = threading.Event()
    events_seen = [0] * CLIENTS
    errors: list[str] = []

    with server(data, tmp_path / "server.log") as (client, _proc):
        base = str(client.base_url)

        def follow(k: int) -> None:
            try:
                with httpx.Client(base_url=base, timeout=60.0) as c, \
                        c.stream("GET", f"/api/v1/campaigns/{cid}/events") as res:
                    assert res.status_code == 200
                    for line in res.iter_lines():
                        if line.startswith("event:"):
                            events_seen[k] += 1
            except httpx.HTTPError as exc:  # the server is stopped under the open streams
                if not stop.is_set():
                    errors.append(repr(exc))

        threads = [threading.Thread(target=follow, args=(k,), daemon=True)
                   for k in range(CLIENTS)]
        for th in threads:
            th.start()
        deadline = time.monotonic() + 60.0
        while min(events_seen) < 1:  # every follower got its first status
            assert time.monotonic() < deadline, events_seen
            time.sleep(0.1)
        latencies = []
        for _ in range(20):
            t0 = time.perf_counter()
            assert client.get("/api/v1/health").status_code == 200
            latencies.append(time.perf_counter() - t0)
            time.sleep(0.25)
        stop.set()
        status = client.get(f"/api/v1/campaigns/{cid}").json()
    assert status["poses_done"] == POSES * REPEATS
    print(f"/health with {CLIENTS} followers: median {statistics.median(latencies) * 1e3:.1f} ms, "
          f"max {max(latencies) * 1e3:.1f} ms")
    assert statistics.median(latencies) < 0.1, latencies
    assert max(events_seen) == 1, "a follower was sent an unchanged status again"
    assert not errors, errors



def test_streams_beyond_the_limit_are_refused_with_503_and_a_closed_stream_frees_its_slot(
    make_client
):
    client = make_client(sse_max_streams=1)
    cid = client.post("/api/v1/campaigns", headers=AUTH,
                      json={"name": "s", "poses": [{"turntable_deg": 0.0}]}).json()["id"]
    url = f"/api/v1/campaigns/{cid}/events"
    with client.stream("GET", url) as first:
        assert first.status_code == 200
        assert next(line for line in first.iter_lines() if line.startswith("event:"))
        second = client.get(url)
        assert second.status_code == 503 and "TOFTWIN_SSE_MAX_STREAMS" in second.text
    deadline = time.monotonic() + 10.0
    while True:  # the closed stream gives its slot back once its generator has ended
        with client.stream("GET", url) as again:
            if again.status_code == 200:
                break
        assert time.monotonic() < deadline, "the first stream's slot never came back"
        time.sleep(0.1)
