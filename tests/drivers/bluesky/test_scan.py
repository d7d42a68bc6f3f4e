"""The Bluesky example, ``RE(bp.scan([camera], turntable, -60, 60, 5))`` on the simulated rig
rendering the satellite ground test: every document valid by event-model's schemas, and each
frame, read from the HDF5 file by following its StreamResource and StreamDatum, equal to the
frame the camera returned.

The scan runs in this process through the example's own function (so the frames the camera
returned can be kept for the comparison) and once more as a reader runs it, from the command
line.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path
from urllib.parse import urlparse

import event_model
import h5py
import numpy as np
import pytest
from event_model import DocumentNames, schema_validators

from drivers.rig import ANGLE_TOLERANCE_DEG
from sim_core.frame_io import measured_frame

pytestmark = [pytest.mark.bluesky, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE = ROOT / "examples" / "bluesky_scan.py"
ANGLES = np.linspace(-60.0, 60.0, 5)


def _example():
    spec = importlib.util.spec_from_file_location("bluesky_scan", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _documents(path: Path) -> list[tuple[str, dict]]:
    return [(line["name"], line["doc"]) for line in map(json.loads, path.read_text().splitlines())]


def _validate(docs: list[tuple[str, dict]]) -> None:
    for name, doc in docs:
        schema_validators[DocumentNames[name]].validate(doc)


def _file_path(uri: str) -> Path:
    parsed = urlparse(uri)
    assert parsed.scheme == "file" and parsed.netloc in ("", "localhost"), uri
    return Path(parsed.path)


def test_the_scan_documents_are_valid_and_lead_to_the_frames_the_camera_returned(tmp_path):
    returned: dict[int, tuple] = {}
    seen: list[tuple[str, dict]] = []
    summary = _example().run_scan(
        tmp_path, on_frame=lambda i, raw, frame: returned.__setitem__(i, (raw, frame)),
        on_document=lambda name, doc: seen.append((name, doc)))

    docs = _documents(tmp_path / "documents.jsonl")
    # the file holds every document, in order
    assert [(n, d) for n, d in json.loads(json.dumps(seen))] == docs
    _validate(docs)
    names = [n for n, _ in docs]
    assert names[0] == "start" and names[1] == "descriptor" and names[-1] == "stop"
    assert names.count("event") == 5 and summary["documents"]["event"] == 5
    start, descriptor, stop = docs[0][1], docs[1][1], docs[-1][1]
    assert start["plan_name"] == "scan" and start["motors"] == ["turntable"]
    assert start["detectors"] == ["camera"] and start["num_points"] == 5
    assert stop["exit_status"] == "success" and stop["num_events"] == {"primary": 5}
    keys = descriptor["data_keys"]
    frame_keys = {k for k, v in keys.items() if v.get("external") == "STREAM:"}
    assert frame_keys == {f"camera-{g}" for g in (
        "depth", "range", "grey", "amplitude", "intensity", "valid", "phase", "raw")}
    assert keys["turntable"]["units"] == "deg"

    # the turntable read back the scan's setpoints
    events = [d for n, d in docs if n == "event"]
    assert [e["seq_num"] for e in events] == [1, 2, 3, 4, 5]
    np.testing.assert_allclose([e["data"]["turntable"] for e in events], ANGLES,
                               atol=ANGLE_TOLERANCE_DEG)
    np.testing.assert_allclose([e["data"]["turntable-setpoint"] for e in events], ANGLES)

    # follow StreamResource -> StreamDatum -> the HDF5 dataset, as a reader would
    resources = {d["uid"]: d for n, d in docs if n == "stream_resource"}
    assert {r["data_key"] for r in resources.values()} == frame_keys
    datums = [d for n, d in docs if n == "stream_datum"]
    assert len(datums) == 5 * len(frame_keys)
    assert len(returned) == 5
    read: dict[tuple[str, int], np.ndarray] = {}
    for datum in datums:
        resource = resources[datum["stream_resource"]]
        assert resource["mimetype"] == "application/x-hdf5"
        assert datum["descriptor"] == descriptor["uid"]
        seq, index = datum["seq_nums"], datum["indices"]
        assert seq["stop"] - seq["start"] == index["stop"] - index["start"] == 1
        path = _file_path(resource["uri"])
        assert path == tmp_path / "frames.h5"
        with h5py.File(path, "r") as f:
            dataset = f[resource["parameters"]["dataset"]]
            data = dataset[index["start"]:index["stop"]]
            key = keys[resource["data_key"]]
            assert list(data.shape) == key["shape"]  # one frame an event: (1, ...)
            assert data.dtype == np.dtype(key["dtype_numpy"])
            assert tuple(resource["parameters"]["chunk_shape"]) == dataset.chunks
        read[(resource["data_key"], seq["start"])] = data[0]

    for index, (raw, frame) in returned.items():
        seq_num = index + 1  # the i-th frame is the i-th event's
        np.testing.assert_array_equal(read[("camera-raw", seq_num)], raw.phase_images)
        image = frame.image
        np.testing.assert_array_equal(read[("camera-depth", seq_num)], image.depth_z_m)
        np.testing.assert_array_equal(read[("camera-range", seq_num)], image.range_m)
        np.testing.assert_array_equal(read[("camera-amplitude", seq_num)], image.amplitude)
        np.testing.assert_array_equal(read[("camera-valid", seq_num)], image.valid)
        np.testing.assert_array_equal(read[("camera-grey", seq_num)], frame.grey_8bit())
        np.testing.assert_array_equal(read[("camera-phase", seq_num)], image.phase_rad)
        # the depth written is the raw frame the camera returned, reconstructed with the
        # scene's camera: redone here from the raw frame alone
        again = measured_frame(raw, _scene_camera(raw), {})
        np.testing.assert_array_equal(read[("camera-depth", seq_num)], again.image.depth_z_m)
        assert frame.image.valid.sum() > 500  # the satellite is in view
        # and it was captured where the event says the turntable stood
        angle = events[index]["data"]["turntable"]
        assert frame.meta["rig"]["turntable_angle_deg"] == pytest.approx(angle, abs=1e-9)
        assert frame.meta["rig"]["solar_suns"] == pytest.approx(1.0, abs=0.02)

    # the run replays through event-model's own router
    got = []
    router = event_model.RunRouter([lambda name, doc: ([lambda n, d: got.append(n)], [])])
    for name, doc in docs:
        router(name, doc)
    assert got[0] == "start" and got[-1] == "stop" and got.count("stream_datum") == len(datums)


def _scene_camera(raw):
    from drivers.bluesky.simulated import scene_camera
    from drivers.camera import get_use_case
    from sim_core.scene_spec import load_scene_spec

    spec = load_scene_spec(ROOT / "examples" / "satellite_ground_test.yaml")
    return scene_camera(spec)(get_use_case(raw.meta["use_case"]))


def test_the_example_runs_from_the_command_line(tmp_path):
    out = tmp_path / "scan"
    res = subprocess.run([sys.executable, str(EXAMPLE), "--out", "scan"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=240)
    assert res.returncode == 0, res.stderr
    assert "5 event" in res.stdout and "frame 4 at +60.0 deg" in res.stdout, res.stdout
    docs = _documents(out / "documents.jsonl")
    _validate(docs)
    assert [n for n, _ in docs].count("event") == 5
    with h5py.File(out / "frames.h5", "r") as f:
        assert f["/entry/depth/data"].shape == (5, 171, 224)
