"""The event streams of campaigns and calibration jobs: one loop (service/api/events.py), the
same wire format (event ``status``, ``id``, ``retry``, JSON data), the end at a final state and
the stream slot given back when a stream ends."""

from __future__ import annotations

import json
from collections.abc import Iterator

from tests.service.api.conftest import AUTH, start_campaign
from tests.service.api.test_calibration import SHORT_PLAN

#: the service's event interval in these tests, and the reconnect delay it implies (4 of them)
INTERVAL_S = 0.05
RETRY_MS = "200"


def sse_events(lines: Iterator[str]) -> Iterator[dict[str, str]]:
    """The events of a stream's lines, as ``{field: value}`` (keep-alive comments skipped)."""
    event: dict[str, str] = {}
    for line in lines:
        if not line:
            if event:
                yield event
            event = {}
        elif not line.startswith(":"):
            field, _, value = line.partition(":")
            event[field] = value.removeprefix(" ")
    if event:
        yield event


def test_a_campaign_s_events_carry_the_poses_done_as_their_id(make_client):
    client = make_client(sse_interval_s=INTERVAL_S)
    cid = start_campaign(client, [{"turntable_deg": 0.0}, {"turntable_deg": 10.0}])
    with client.stream("GET", f"/api/v1/campaigns/{cid}/events") as stream:
        assert stream.headers["content-type"].startswith("text/event-stream")
        events = list(sse_events(stream.iter_lines()))
    statuses = [json.loads(e["data"]) for e in events]
    assert {e["event"] for e in events} == {"status"}
    assert {e["retry"] for e in events} == {RETRY_MS}
    assert [e["id"] for e in events] == [str(s["poses_done"]) for s in statuses]
    assert statuses[-1]["state"] == "completed" and statuses[-1]["poses_done"] == 2
    assert len({json.dumps(s, sort_keys=True) for s in statuses}) == len(statuses)


def test_a_calibration_job_s_events_are_numbered_and_end_when_it_is_cancelled(make_client):
    client = make_client(sse_interval_s=INTERVAL_S, sse_max_streams=1)
    client.app.state.lab.calibrations.world = None  # the job waits for an operator
    jid = client.post("/api/v1/calibrations", headers=AUTH, json=SHORT_PLAN).json()["id"]
    url = f"/api/v1/calibrations/{jid}/events"
    with client.stream("GET", url) as stream:
        assert stream.headers["content-type"].startswith("text/event-stream")
        events = sse_events(stream.iter_lines())
        first = next(events)
        assert json.loads(first["data"])["state"] in ("queued", "running")
        assert client.get(url).status_code == 503  # the one slot is this stream's
        res = client.post(f"/api/v1/calibrations/{jid}/cancel", headers=AUTH)
        assert res.status_code == 200, res.text
        rest = list(events)
    seen = [first, *rest]
    assert {e["event"] for e in seen} == {"status"}
    assert {e["retry"] for e in seen} == {RETRY_MS}
    assert [e["id"] for e in seen] == [str(n) for n in range(1, len(seen) + 1)]
    assert json.loads(seen[-1]["data"])["state"] == "cancelled"
    # the ended stream gave its slot back: a new one opens, sends the final state and ends
    with client.stream("GET", url) as again:
        assert again.status_code == 200
        replay = list(sse_events(again.iter_lines()))
    assert [e["id"] for e in replay] == ["1"]
    assert json.loads(replay[0]["data"])["state"] == "cancelled"
