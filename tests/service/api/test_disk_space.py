"""A disk that is (nearly) full pauses a campaign with what to do; it never fails it."""

from __future__ import annotations

import errno
import sqlite3

import sqlalchemy.exc
from sqlalchemy import event

from service.store.disk_space import is_disk_full
from tests.service.api.conftest import AUTH, problem, start_campaign, wait_campaign


def test_below_the_free_space_kept_a_campaign_pauses_and_a_pose_is_refused(make_client):
    client = make_client(min_free_bytes=10**18)  # more than any disk has
    before = client.get("/api/v1/devices/turntable/position").json()["angle_deg"]
    cid = start_campaign(client, [{"turntable_deg": 0.0}, {"turntable_deg": 20.0}])
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "paused" and status["poses_done"] == 0, status
    assert "free on the data directory's disk, below the 888.2 PiB kept free" in status["error"]
    assert "TOFTWIN_MIN_FREE_BYTES" in status["error"]
    res = client.post(f"/api/v1/campaigns/{cid}/resume", headers=AUTH)  # still full: pauses
    assert res.status_code == 200
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "paused" and status["runs"] == 2
    res = client.post("/api/v1/poses", headers=AUTH,
                      json={"turntable_deg": before + 20.0, "solar_suns": 1.0})
    assert "TOFTWIN_MIN_FREE_BYTES" in problem(res, 507)["detail"]
    assert client.get("/api/v1/devices/turntable/position").json()["angle_deg"] == before
    assert client.get("/api/v1/frames").json() == []


def test_what_a_full_disk_looks_like_from_a_file_write_and_from_sqlite():
    assert is_disk_full(OSError(errno.ENOSPC, "No space left on device"))
    try:
        try:
            raise sqlite3.OperationalError("database or disk is full")
        except sqlite3.OperationalError as inner:
            raise sqlalchemy.exc.OperationalError("INSERT ...", {}, inner) from inner
    except sqlalchemy.exc.OperationalError as wrapped:
        assert is_disk_full(wrapped)
    try:
        try:
            raise OSError(errno.ENOSPC, "No space left on device")
        except OSError as exc:
            raise RuntimeError("saving frame.npz failed") from exc
    except RuntimeError as chained:
        assert is_disk_full(chained)
    assert not is_disk_full(sqlite3.OperationalError("database is locked"))
    assert not is_disk_full(ValueError("something else"))


def test_a_database_that_fills_up_mid_campaign_pauses_it_and_resume_finishes_it(client):
    """SQLite's own "database or disk is full" (its page limit, as a full disk would give)."""
    engine = client.app.state.lab.engine
    limit = {"pages": None}

    @event.listens_for(engine, "connect")
    def _cap(dbapi_conn, _record):
        if limit["pages"] is not None:
            dbapi_conn.execute(f"PRAGMA max_page_count = {limit['pages']}")

    # capped after the first result, with five still to store: the campaign cannot finish
    poses = [{"turntable_deg": a} for a in range(-50, 60, 20)]
    cid = start_campaign(client, poses)
    wait_campaign(client, cid, lambda s: s["poses_done"] >= 1)
    with engine.connect() as conn:
        limit["pages"] = conn.exec_driver_sql("PRAGMA page_count").scalar()
    engine.dispose()  # every new connection gets the cap: the next result cannot be stored
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    limit["pages"] = None
    engine.dispose()
    assert status["state"] == "paused", status
    assert "disk full: a write needed more than the" in status["error"], status
    assert "resume" in status["error"]
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    assert len(rows) == status["poses_done"] < len(poses)
    res = client.post(f"/api/v1/campaigns/{cid}/resume", headers=AUTH)
    assert res.status_code == 200, res.text
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "completed", status


def test_a_simulation_and_a_capture_are_refused_below_the_free_space_kept(make_client):
    client = make_client(min_free_bytes=10**18)
    for route, body in (("/api/v1/simulate", {"scene": "satellite_ground_test"}),
                        ("/api/v1/devices/camera/capture", None)):
        detail = problem(client.post(route, headers=AUTH, json=body), 507)["detail"]
        assert "below the 888.2 PiB kept free (TOFTWIN_MIN_FREE_BYTES)" in detail, route
    assert client.get("/api/v1/frames").json() == []


def test_a_pose_whose_result_finds_the_database_full_is_a_507_and_leaves_no_frame(
    make_client, tmp_path
):
    """Floor 0: nothing is refused in advance; SQLite's "database or disk is full" (its page
    limit, as a full disk gives it) when a result is committed is the 507. The cap is the
    database's size: poses are stored until their rows fill its last page."""
    client = make_client(min_free_bytes=0)
    engine = client.app.state.lab.engine
    with engine.connect() as conn:
        conn.exec_driver_sql("VACUUM")  # no free page left to take: the cap is the file's size
        pages = conn.exec_driver_sql("PRAGMA page_count").scalar()

    @event.listens_for(engine, "connect")
    def _cap(dbapi_conn, _record):
        dbapi_conn.execute(f"PRAGMA max_page_count = {pages}")

    engine.dispose()
    for stored in range(20):
        res = client.post("/api/v1/poses", headers=AUTH,
                          json={"turntable_deg": float(stored), "solar_suns": 1.0})
        if res.status_code != 201:
            break
    detail = problem(res, 507)["detail"]
    assert "writing the pose's simulated frame and its result failed" in detail, detail
    assert "TOFTWIN_MIN_FREE_BYTES=0" in detail and str(tmp_path) not in detail
    event.remove(engine, "connect", _cap)
    engine.dispose()
    frames = client.get("/api/v1/frames").json()
    assert len(frames) == 2 * stored  # the stored poses' frames, none of the refused one
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == sorted(
        f["id"] for f in frames)
