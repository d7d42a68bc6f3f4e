"""``toftwin calibrate rig``: refusals before anything moves; a full run on the simulated lab."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from calibration.rig_verdicts import calibration_keys
from calibration.verdicts import Verdict, Verdicts, count_line, read_verdicts
from service.cli import app
from service.cli.common import print_verdicts
from sim_core.twin_file import load_calibration


def run(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def test_bad_options_are_exit_2_and_nothing_is_written(tmp_path):
    reality = tmp_path / "reality.yaml"
    reality.write_text("turntable: {zero_offset_deg: 0.3}\n")
    res = run("calibrate", "rig", "--out", tmp_path / "a", "--reality", reality)
    assert res.exit_code == 2 and "needs --simulated" in " ".join(res.output.split())
    res = run("calibrate", "rig", "--out", tmp_path, "--simulated")
    assert res.exit_code == 2 and "exists" in res.output
    bad = tmp_path / "bad.yaml"
    bad.write_text("camera: {fx_px: 0}\n")
    res = run("calibrate", "rig", "--out", tmp_path / "b", "--simulated", "--reality", bad)
    assert res.exit_code == 2 and "reality.camera.fx_px" in " ".join(res.output.split())
    res = run("calibrate", "rig", "--out", tmp_path / "c", "--simulated",
              "--frames-per-view", 0)
    assert res.exit_code == 2 and "--frames-per-view" in res.output
    res = run("calibrate", "rig", "--out", tmp_path / "d", "--simulated", "--sweep-step", 60)
    assert res.exit_code == 2 and "--sweep-step" in res.output
    assert not any((tmp_path / n).exists() for n in ("a", "b", "c", "d"))


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_full_run_writes_the_calibration_and_its_report(tmp_path):
    reality = tmp_path / "reality.yaml"
    reality.write_text("turntable: {zero_offset_deg: 0.6}\ncamera: {cx_px: 113.0}\n")
    out = tmp_path / "cal"
    # The whole sequence at a coarser sweep (every 10 deg), the camera counted warm and the
    # ringing known: the round trips run the default plan, its warm-up and settling stages too.
    res = run("calibrate", "rig", "--out", out, "--simulated", "--reality", reality, "-q",
              "--sweep-step", 10, "--no-warmup", "--no-settling")
    assert res.exit_code == 0, res.output
    cal = load_calibration(out / "calibration.yaml")
    # Twice the round trip's bounds (tests/calibration/test_rig_roundtrip.py): half the views.
    assert cal.turntable.zero_offset_deg == pytest.approx(0.6, abs=0.2)
    assert cal.camera.cx_px == pytest.approx(113.0, abs=1.0)
    report = json.loads((out / "report.json").read_text())
    assert report["provenance"]["rig"] == "simulated" and report["calibration_hash"]
    html = (out / "report.html").read_text()
    assert "intrinsics.png" in html and "Reprojection RMS" in html
    # the camera in OpenCV's form beside it (issue 29), what cv2.FileStorage reads
    import cv2

    fs = cv2.FileStorage(str(out / "opencv_intrinsics.yml"), cv2.FILE_STORAGE_READ)
    k = fs.getNode("camera_matrix").mat()
    fs.release()
    assert (k[0, 0], k[1, 1], k[0, 2], k[1, 2]) == (cal.camera.fx_px, cal.camera.fy_px,
                                                    cal.camera.cx_px, cal.camera.cy_px)
    assert (out / "intrinsics.png").stat().st_size > 1000
    # every key of the file has its verdict, counted in one line
    verdicts = read_verdicts(out / "verdicts.json")
    keys = calibration_keys(cal)
    assert list(verdicts)[:len(keys)] == keys
    # then the effect keys the run did not write (issue 27), each not determined, with why
    for key in list(verdicts)[len(keys):]:
        assert key.startswith(("camera.temperature.", "camera.stray_light.",
                               "turntable.settling.")), key
        assert not verdicts[key].determined and verdicts[key].reason
    assert count_line(verdicts) in res.output and "Verdicts" in html


def test_the_verdicts_are_counted_and_each_key_not_determined_is_listed_with_why(capsys):
    print_verdicts(Verdicts({
        "camera.fx_px": Verdict("determined", 0.05),
        "camera.distortion.k3": Verdict("not determined", None, "held at 0"),
        "turntable.zero_offset_deg": Verdict("unexplained", 0.2, "reduced chi-square 20.5"),
    }))
    out = capsys.readouterr().out.splitlines()
    assert out == ["3 keys: 1 determined, 1 not determined, 1 unexplained",
                   "  camera.distortion.k3: not determined: held at 0",
                   "  turntable.zero_offset_deg: unexplained: reduced chi-square 20.5"]
