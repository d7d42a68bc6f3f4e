"""A campaign exported as a Bluesky run: ``documents.jsonl`` beside ``frames.h5``, the frames
referenced as a Bluesky detector references its own (StreamResource per dataset, StreamDatum per
event), each leading to the very frame the service stored for that result.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from urllib.parse import urlparse

import h5py
import numpy as np
import pytest
from event_model import DocumentNames, schema_validators

from service.export.bluesky import CampaignFrames, campaign_documents, export_campaign_run
from tests.service.api.conftest import start_campaign, wait_campaign

pytestmark = pytest.mark.timeout(120)

POSES = [{"turntable_deg": -30, "solar_suns": 1.0, "repeats": 1},
         {"turntable_deg": 0, "solar_suns": 0.9, "repeats": 2},
         {"turntable_deg": 30, "solar_suns": 0.0, "repeats": 1}]


def _completed_campaign(client) -> str:
    cid = start_campaign(client, POSES)
    status = wait_campaign(client, cid, lambda s: s["state"] != "running")
    assert status["state"] == "completed", status
    return cid


def _lines(path: Path) -> list[tuple[str, dict]]:
    return [(d["name"], d["doc"]) for d in map(json.loads, path.read_text().splitlines())]


def _followed(docs: list[tuple[str, dict]]) -> dict[tuple[str, int], np.ndarray]:
    """``(data_key, seq_num) -> the array`` read by following every StreamDatum."""
    resources = {d["uid"]: d for n, d in docs if n == "stream_resource"}
    out = {}
    for name, datum in docs:
        if name != "stream_datum":
            continue
        resource = resources[datum["stream_resource"]]
        uri = urlparse(resource["uri"])
        assert resource["mimetype"] == "application/x-hdf5"
        assert uri.scheme == "file" and uri.netloc == "localhost", resource["uri"]
        with h5py.File(uri.path, "r") as f:
            dataset = f[resource["parameters"]["dataset"]]
            assert tuple(resource["parameters"]["chunk_shape"]) == dataset.chunks
            rows = dataset[datum["indices"]["start"]:datum["indices"]["stop"]]
        assert len(rows) == datum["seq_nums"]["stop"] - datum["seq_nums"]["start"] == 1
        out[(resource["data_key"], datum["seq_nums"]["start"])] = rows[0]
    return out


def test_a_campaign_exports_as_a_run_whose_stream_documents_lead_to_its_stored_frames(
        client, tmp_path):
    cid = _completed_campaign(client)
    lab = client.app.state.lab
    out = tmp_path / "run"
    summary = export_campaign_run(lab.sessions, lab.store, cid, out)
    assert summary["skipped_results"] == []
    assert [p.name for p in summary["files"]] == ["documents.jsonl", "frames.h5"]
    docs = _lines(out / "documents.jsonl")
    for name, doc in docs:
        schema_validators[DocumentNames[name]].validate(doc)
    names = [n for n, _ in docs]
    assert names[:2] == ["start", "descriptor"] and names[-1] == "stop"
    assert names.count("event") == 4 and summary["documents"]["event"] == 4
    descriptor = docs[1][1]
    keys = descriptor["data_keys"]
    streamed = {k for k, v in keys.items() if v.get("external") == "STREAM:"}
    assert {"camera-depth", "camera-raw", "simulator-depth", "simulator-grey"} <= streamed
    assert {r["data_key"] for n, r in docs if n == "stream_resource"} == streamed
    assert all(r["uri"] == "file://localhost" + (out / "frames.h5").resolve().as_posix()
               for n, r in docs if n == "stream_resource")
    assert names.count("stream_datum") == 4 * len(streamed)

    # every event's frames, followed into frames.h5, are the frames the service stored
    events = [d for n, d in docs if n == "event"]
    read = _followed(docs)
    for event in events:
        seq, data = event["seq_num"], event["data"]
        for key, frame_id in (("camera", data["measured_frame_id"]),
                              ("simulator", data["simulated_frame_id"])):
            frame = lab.store.read(frame_id)
            np.testing.assert_array_equal(read[(f"{key}-depth", seq)], frame.image.depth_z_m)
            np.testing.assert_array_equal(read[(f"{key}-valid", seq)], frame.image.valid)
            np.testing.assert_array_equal(read[(f"{key}-grey", seq)], frame.grey_8bit())
            assert list(read[(f"{key}-depth", seq)].shape) == keys[f"{key}-depth"]["shape"][1:]
        measured = lab.store.read(data["measured_frame_id"])
        np.testing.assert_array_equal(read[("camera-raw", seq)], measured.raw.phase_images)

    # the service's own documents are these, without the frames' stream
    plain = campaign_documents(lab.sessions, cid)
    assert [d["doc"] for d in plain if d["name"] == "event"] == events
    served = client.get(f"/api/v1/campaigns/{cid}/documents").json()
    assert [d["doc"] for d in served if d["name"] == "event"] == events
    # and the same documents every time (but for where the file is)
    again = export_campaign_run(lab.sessions, lab.store, cid, tmp_path / "again")
    assert again["documents"] == summary["documents"]
    text = (tmp_path / "again" / "documents.jsonl").read_text()
    assert text.replace(str((tmp_path / "again").resolve()), str(out.resolve())) == (
        out / "documents.jsonl").read_text()


def test_a_result_whose_frames_are_gone_keeps_its_event_but_streams_no_frame(client, tmp_path):
    cid = _completed_campaign(client)
    lab = client.app.state.lab
    results = client.get(f"/api/v1/campaigns/{cid}/results").json()
    gone = results[1]  # pose 1, repeat 0
    shutil.rmtree(lab.store.path(gone["measured_frame_id"]))
    summary = export_campaign_run(lab.sessions, lab.store, cid, tmp_path)
    assert summary["skipped_results"] == [(gone["pose_index"], gone["repeat"])]
    docs = _lines(tmp_path / "documents.jsonl")
    for name, doc in docs:
        schema_validators[DocumentNames[name]].validate(doc)
    events = [d for n, d in docs if n == "event"]
    assert len(events) == 4
    seqs = {d["seq_nums"]["start"] for n, d in docs if n == "stream_datum"}
    assert seqs == {1, 3, 4}  # the second event streams nothing
    read = _followed(docs)
    for event in events:
        if event["seq_num"] == 2:
            continue
        frame = lab.store.read(event["data"]["simulated_frame_id"])
        np.testing.assert_array_equal(read[("simulator-depth", event["seq_num"])],
                                      frame.image.depth_z_m)


def test_a_file_that_is_not_a_campaigns_frames_is_refused(tmp_path):
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as f:
        f.create_group("entry")
    with pytest.raises(ValueError, match="not a campaign's frames file"):
        CampaignFrames.from_file(path)
