"""``toftwin record`` and ``toftwin replay`` (issue 28): frames captured on the (simulated) rig
into an HDF5 recording, compared again offline into a campaign's results, CSV and report."""

from __future__ import annotations

import csv
import json

import h5py
import pytest
from typer.testing import CliRunner

from drivers.camera.wire import USE_CASES
from service.cli import app
from service.store.recording import Recording
from sim_core.twin_file import load_calibration, twin_hash, write_calibration
from tests.service.api.test_calibration import CALIBRATION

pytestmark = pytest.mark.timeout(600)

CAMPAIGN = {"name": "three poses", "seed": 3, "spp": 2,
            "poses": [{"turntable_deg": -30.0}, {"turntable_deg": 0.0, "repeats": 2},
                      {"turntable_deg": 30.0, "solar_suns": 0.0}]}


def _invoke(*args: str) -> str:
    res = CliRunner().invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res.output


def _metrics(out) -> list[tuple]:
    rows = json.loads((out / "results.json").read_text())
    return [(r["pose_index"], r["repeat"], r["calibration_hash"], r["metrics"]) for r in rows]


@pytest.fixture
def recording(tmp_path, monkeypatch):
    monkeypatch.setenv("TOFTWIN_EXECUTOR", "thread")
    monkeypatch.setenv("TOFTWIN_WORKERS", "2")
    (tmp_path / "campaign.json").write_text(json.dumps(CAMPAIGN))
    path = tmp_path / "rec.h5"
    said = _invoke("record", "--simulated", "--every-pose", tmp_path / "campaign.json",
                   "--camera-spp", "2", "--out", path)
    assert "4 frame(s) of 3 pose(s)" in said
    return path


def test_a_recording_replays_into_a_campaigns_results_csv_and_report(recording, tmp_path):
    rec = Recording(recording)
    assert rec.units() == [(0, 0), (1, 0), (1, 1), (2, 0)]
    assert rec.campaign.spp == 2 and rec.campaign.seed == 3 and rec.campaign.calibration is None
    with h5py.File(recording) as f:
        unit = next(g for g in f["frames"].values() if g.attrs["pose_index"] == 2)
        assert unit.attrs["solar_suns"] == 0.0 and not unit.attrs["shutter_open"]
        assert unit.attrs["use_case"] in USE_CASES

    _invoke("replay", recording, "--out", tmp_path / "a")
    with open(tmp_path / "a" / "results.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert [(r["pose_index"], r["repeat"]) for r in table] == [
        ("0", "0"), ("1", "0"), ("1", "1"), ("2", "0")]
    assert all(float(r["depth_diff_n_pixels"]) > 0 for r in table[:3])
    report = (tmp_path / "a" / "report.html").read_text()
    assert "<html" in report.lower() and "replay of rec.h5" in report

    _invoke("replay", recording, "--out", tmp_path / "b")  # a replay is reproducible
    assert _metrics(tmp_path / "b") == _metrics(tmp_path / "a")

    write_calibration(tmp_path / "cal.yaml", load_calibration_dict(CALIBRATION, tmp_path))
    _invoke("replay", recording, "--calibration", tmp_path / "cal.yaml", "--out", tmp_path / "c")
    calibrated = _metrics(tmp_path / "c")
    assert {c[2] for c in calibrated} == {twin_hash(load_calibration(tmp_path / "cal.yaml"))}
    assert [c[3] for c in calibrated] != [m[3] for m in _metrics(tmp_path / "a")]


def load_calibration_dict(data: dict, tmp_path):
    """A calibration file's model from its JSON form."""
    (tmp_path / "cal.json").write_text(json.dumps(data))
    return load_calibration(tmp_path / "cal.json")


@pytest.mark.parametrize("args, field", [
    (["record", "--reality", "r.yaml", "--out", "{t}/r.h5"], "--reality"),
    (["record", "--every-pose", "{t}/none.json", "--out", "{t}/r.h5"], "--every-pose"),
    (["record", "--every-pose", "{t}/bad.json", "--out", "{t}/r.h5"],
     "--every-pose poses.0.turntable_deg"),
    (["record", "--every-pose", "{t}/turning.json", "--out", "{t}/r.h5"], "--every-pose"),
    (["record", "--frames", "0", "--out", "{t}/r.h5"], "--frames"),
    (["replay", "{t}/bad.json", "--out", "{t}/o"], "recording"),
    (["replay", "{t}/not.h5", "--out", "{t}/o"], "not an HDF5 file"),
    (["replay", "{t}/other.h5", "--out", "{t}/o"], "not a toftwin recording"),
])
def test_bad_input_exits_2_naming_the_field_and_writes_nothing(tmp_path, args, field):
    (tmp_path / "bad.json").write_text(json.dumps({"name": "x", "poses": [
        {"turntable_deg": 999}]}))
    (tmp_path / "turning.json").write_text(json.dumps({"name": "x", "turning_deg_s": 5, "poses": [
        {"turntable_deg": 0}]}))
    (tmp_path / "not.h5").write_bytes(b"plain text")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = [1, 2]
    res = CliRunner().invoke(app, [a.format(t=tmp_path) for a in args])
    assert res.exit_code == 2, res.output
    assert field in " ".join(res.output.split()), res.output
    assert not (tmp_path / "r.h5").exists() and not (tmp_path / "o").exists()
