"""Recording and replay (issue 28): a campaign records what it captured; a campaign replays it.

A 12-pose campaign created with ``"record": true`` writes every captured frame, with its rig
state, into ``recordings/<id>.h5``; a campaign with ``"source": "recording"`` replays that file
through the pose loop without the rig. With the calibration the recording was made with, the
replay reproduces every stored metric exactly; with another one activated, it gives the numbers
of a live campaign that ran with that calibration from the start.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from drivers.rig import RigState
from service.cli import app
from service.store.recording import (
    FORMAT,
    RecordedCampaign,
    RecordedUnit,
    Recording,
    RecordingWriter,
)
from sim_core.raw import RawFrame
from tests.service.api.conftest import AUTH, problem, start_campaign, wait_campaign
from tests.service.api.test_calibration import CALIBRATION

pytestmark = pytest.mark.timeout(600)

#: twelve poses across the table's range, one at 0 sun
POSES = [{"turntable_deg": a, "solar_suns": 0.0 if a == 0 else 1.0}
         for a in (-75.0, -60.0, -45.0, -30.0, -15.0, 0.0, 10.0, 20.0, 35.0, 50.0, 65.0, 80.0)]


def _results(client, cid: str) -> list[dict]:
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    return sorted(rows, key=lambda r: (r["pose_index"], r["repeat"]))


def _run(client, poses=None, **fields) -> tuple[str, list[dict]]:
    if poses is None:  # a replay: no poses
        res = client.post("/api/v1/campaigns", headers=AUTH, json={"name": "replay", **fields})
        assert res.status_code == 201, res.text
        cid = res.json()["id"]
        assert client.post(f"/api/v1/campaigns/{cid}/start", headers=AUTH).status_code == 200
    else:
        cid = start_campaign(client, poses, **fields)
    status = wait_campaign(client, cid, lambda s: s["state"] != "running"
                           and s["state"] != "created", timeout_s=500)
    assert status["state"] == "completed", status
    return cid, _results(client, cid)


def _comparable(rows: list[dict]) -> list[tuple]:
    return [(r["pose_index"], r["repeat"], r["turntable_deg"], r["solar_suns"],
             r["calibration_hash"], r["metrics"])
            for r in rows]


def test_a_replayed_campaign_reproduces_every_stored_metric_exactly(make_client, tmp_path,
                                                                   monkeypatch):
    client = make_client()
    cid, live = _run(client, POSES, record=True, seed=7)
    path = tmp_path / "recordings" / f"{cid}.h5"
    recording = Recording(path)
    assert recording.units() == [(i, 0) for i in range(len(POSES))]
    assert recording.campaign.seed == 7 and len(recording.campaign.poses) == len(POSES)
    with h5py.File(path) as f:  # plain HDF5: the raw frames, compressed, one chunk per frame
        assert f.attrs["format"] == FORMAT
        first = f["frames"]["000000"]
        assert first["phase_images"].compression == "gzip"
        assert first["phase_images"].chunks == first["phase_images"].shape
        assert abs(first.attrs["turntable_angle_deg"] - live[0]["turntable_deg"]) <= 0.01
        assert np.isfinite(first.attrs["timestamp_s"])

    status = client.get(f"/api/v1/campaigns/{cid}").json()
    assert status["source"] == "rig" and status["recording"] == path.name
    res = client.get(status["links"]["recording"])  # a lab shares it
    assert res.status_code == 200 and res.content == path.read_bytes()

    replay_id, replayed = _run(client, source="recording", recording=path.name)
    assert len(replayed) == len(live) == len(POSES)
    assert _comparable(replayed) == _comparable(live)  # every metric, exactly
    assert any(r["metrics"]["tof"]["depth_diff_n_pixels"] > 0 for r in live)
    status = client.get(f"/api/v1/campaigns/{replay_id}").json()
    assert status["poses_total"] == len(POSES)
    assert status["source"] == "recording" and status["recording"] == path.name
    assert "recording" not in status["links"]
    assert client.get(f"/api/v1/campaigns/{replay_id}/recording").status_code == 404

    # and offline, by `toftwin replay` with its own database and workers: the same numbers
    monkeypatch.setenv("TOFTWIN_EXECUTOR", "thread")
    res = CliRunner().invoke(app, ["replay", str(path), "--out", str(tmp_path / "offline")])
    assert res.exit_code == 0, res.output
    offline = json.loads((tmp_path / "offline" / "results.json").read_text())
    assert [(r["pose_index"], r["metrics"]) for r in offline] == [
        (r["pose_index"], r["metrics"]) for r in live]


def test_a_replay_with_a_new_calibration_gives_the_new_twins_numbers(make_client, tmp_path):
    """The recording made with the nominal twin, replayed with a calibration active, gives what a
    live campaign with that calibration gives on the same (deterministic) simulated lab."""
    poses = POSES[::3]
    recorder = make_client(tmp_path / "recorder")
    cid, nominal = _run(recorder, poses, record=True)
    calibrated = make_client(tmp_path / "calibrated")
    assert calibrated.put("/api/v1/calibration", headers=AUTH,
                          json=CALIBRATION).status_code == 200
    _, live = _run(calibrated, poses)

    assert recorder.put("/api/v1/calibration", headers=AUTH,
                        json=CALIBRATION).status_code == 200
    _, replayed = _run(recorder, source="recording", recording=f"{cid}.h5")
    assert _comparable(replayed) == _comparable(live)
    assert [r["metrics"] for r in replayed] != [r["metrics"] for r in nominal]
    assert {r["calibration_hash"] for r in replayed} == {live[0]["calibration_hash"]} != {None}


def test_replay_requests_are_checked_and_name_the_field(client, tmp_path):
    def refused(body: dict, field: str) -> str:
        res = client.post("/api/v1/campaigns", headers=AUTH, json={"name": "r", **body})
        text = problem(res, 422)["detail"] + str(problem(res, 422).get("errors", ""))
        assert field in text, text
        return text

    refused({"source": "recording"}, "recording")
    refused({"source": "recording", "recording": "../etc/passwd.h5"}, "recording")
    refused({"source": "recording", "recording": "none.h5"}, "recording")
    refused({"source": "recording", "recording": "x.h5", "poses": [{"turntable_deg": 0}]},
            "poses")
    refused({"source": "recording", "recording": "x.h5", "record": True}, "record")
    refused({"poses": [{"turntable_deg": 0}], "recording": "x.h5"}, "recording")
    refused({"poses": []}, "poses")
    (tmp_path / "recordings").mkdir()
    (tmp_path / "recordings" / "bad.h5").write_bytes(b"not hdf5")
    assert "not an HDF5 file" in refused({"source": "recording", "recording": "bad.h5"},
                                         "recording")
    assert client.get("/api/v1/campaigns").json() == []  # nothing stored


@pytest.mark.parametrize("fields", [
    {"turning_deg_s": 10.0},
    pytest.param({"object_fit": {"poses": 2, "frames": 2}}, marks=pytest.mark.slow),
], ids=["captured-while-turning", "with-an-object-fit"])
def test_turning_and_object_fit_campaigns_replay_exactly(make_client, tmp_path, fields):
    """A recording keeps each frame's turning speed, and a campaign's fitted object twin (and
    the noise ceiling's second capture): the replay compares with that fit, it does not fit."""
    client = make_client()
    poses = [{"turntable_deg": a} for a in (-40.0, -10.0, 20.0, 50.0)]
    cid, live = _run(client, poses, record=True, **fields)
    replay_id, replayed = _run(client, source="recording", recording=f"{cid}.h5")
    assert _comparable(replayed) == _comparable(live)
    original = client.get(f"/api/v1/campaigns/{cid}").json()
    replay = client.get(f"/api/v1/campaigns/{replay_id}").json()
    assert replay["object_fit"] == original["object_fit"]
    if "object_fit" in fields:
        assert all("explained" in r["metrics"] for r in replayed)
        assert replay["object_fit"]["state"] == "fitted"
    else:
        assert all("edges" in r["metrics"] for r in replayed)


def _tiny_raw(meta=None, phases=None) -> RawFrame:
    z = np.zeros((2, 3), np.float32)
    return RawFrame(np.zeros((1, 4, 2, 3), np.float32) if phases is None else phases, z,
                    np.array([60.24e6]), z.astype(bool), z.astype(bool), 500e-6, 1.0,
                    meta=meta or {})


def test_a_failed_write_leaves_the_recording_whole(tmp_path):
    """A unit whose frame cannot be written (metadata that is no JSON, data of the wrong
    kind: as a full disk fails half-way) leaves no group behind; the units before and after it
    read back."""
    camp = RecordedCampaign("x", "s", {}, None, {}, 0, 1, [(0.0, 1.0, 3)])
    writer = RecordingWriter(tmp_path / "r.h5", camp)
    state = RigState(0.0, 1.0, True)
    writer.append(RecordedUnit(0, 0, state, "MODE_5_45FPS_500", 0.0, [_tiny_raw()]))
    with pytest.raises(TypeError):
        writer.append(RecordedUnit(0, 1, state, "MODE_5_45FPS_500", 0.0,
                                   [_tiny_raw(meta={"x": object()})]))
    with pytest.raises(ValueError):
        writer.append(RecordedUnit(0, 1, state, "MODE_5_45FPS_500", 0.0,
                                   [_tiny_raw(phases=np.array(["not a number"]))]))
    writer.append(RecordedUnit(0, 2, state, "MODE_5_45FPS_500", 0.0, [_tiny_raw()]))
    rec = Recording(tmp_path / "r.h5")
    assert rec.units() == [(0, 0), (0, 2)] and rec.incomplete == []
    assert rec.unit(0, 2).raws[0].timestamp_s == 1.0


def test_a_recording_from_elsewhere_is_checked_as_a_request(client, tmp_path):
    """A recording dropped into recordings/ whose scene names files of the server's is taken as
    an inline scene, and refused; its messages name no server folder."""
    scene = {"name": "evil", "calibration": "/etc/passwd", "camera": {
        "pose": {"position_m": [0, -1, 0], "look_at_m": [0, 0, 0]}}}
    camp = RecordedCampaign("x", "evil", scene, "/etc", {"kind": "turntable"}, 0, 4,
                            [(0.0, 1.0, 1)])
    RecordingWriter(tmp_path / "recordings" / "other.h5", camp).append(
        RecordedUnit(0, 0, RigState(0.0, 1.0, True), "MODE_5_45FPS_500", 0.0, [_tiny_raw()]))
    res = client.post("/api/v1/campaigns", headers=AUTH, json={
        "name": "r", "source": "recording", "recording": "other.h5"})
    body = problem(res, 422)
    assert "calibration" in str(body) and str(tmp_path) not in res.text
    missing = client.post("/api/v1/campaigns", headers=AUTH, json={
        "name": "r", "source": "recording", "recording": "gone.h5"})
    assert "gone.h5" in missing.text and str(tmp_path) not in missing.text


def test_a_data_directory_moved_elsewhere_keeps_its_recordings(make_client, tmp_path):
    """A campaign row names its recording inside the data directory relative to it: after the
    folder is moved (a lab restores its data on another machine), the recording still downloads,
    a replay created before the move runs, and a recording campaign created before it writes
    into the folder where it is now."""
    import shutil

    poses = POSES[:2]
    before = tmp_path / "before"
    client = make_client(before)
    cid, live = _run(client, poses, record=True)
    res = client.post("/api/v1/campaigns", headers=AUTH, json={
        "name": "replay", "source": "recording", "recording": f"{cid}.h5"})
    assert res.status_code == 201, res.text
    replay_id = res.json()["id"]
    res = client.post("/api/v1/campaigns", headers=AUTH,
                      json={"name": "later", "poses": poses, "record": True})
    assert res.status_code == 201, res.text
    later_id = res.json()["id"]
    client.__exit__(None, None, None)

    after = tmp_path / "elsewhere" / "after"
    shutil.move(before, after)
    moved = make_client(after)
    status = moved.get(f"/api/v1/campaigns/{cid}").json()
    res = moved.get(status["links"]["recording"])
    assert res.status_code == 200
    assert res.content == (after / "recordings" / f"{cid}.h5").read_bytes()
    for started in (replay_id, later_id):
        assert moved.post(f"/api/v1/campaigns/{started}/start",
                          headers=AUTH).status_code == 200
        status = wait_campaign(moved, started, lambda s: s["state"] not in ("running",
                                                                            "created"),
                               timeout_s=300)
        assert status["state"] == "completed", status
    assert _comparable(_results(moved, replay_id)) == _comparable(live)
    assert Recording(after / "recordings" / f"{later_id}.h5").units() == [(0, 0), (1, 0)]
    assert not before.exists()


def test_a_row_older_than_relative_paths_finds_its_recording_in_the_moved_folder(tmp_path):
    """Rows written before recording paths were stored relative hold the folder's old absolute
    place: once the folder has moved, a recording of that name in its new ``recordings/`` is
    the one meant (and a file outside any data directory stays where it is)."""
    from service.store.recording import resolve_stored_path, stored_path

    old, new = tmp_path / "old" / "data", tmp_path / "new" / "data"
    (new / "recordings").mkdir(parents=True)
    (new / "recordings" / "a.h5").write_bytes(b"x")
    assert resolve_stored_path(new, str(old / "recordings" / "a.h5")) == (
        new / "recordings" / "a.h5")
    # not yet written (a recording campaign created before the move): the old folder is gone
    assert resolve_stored_path(new, str(old / "recordings" / "b.h5")) == (
        new / "recordings" / "b.h5")
    elsewhere = tmp_path / "share" / "c.h5"
    elsewhere.parent.mkdir()
    elsewhere.write_bytes(b"x")
    assert resolve_stored_path(new, stored_path(new, elsewhere)) == elsewhere
    assert stored_path(new, new / "recordings" / "a.h5") == "recordings/a.h5"
