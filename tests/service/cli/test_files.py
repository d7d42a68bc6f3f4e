"""Files through the command line: what ``toftwin simulate`` writes follows the umask (the data
directory's secrets stay 0600), a file that does not parse is named with its line and column,
and a refused ``serve`` writes nothing."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest
from typer.testing import CliRunner

from service.cli import app
from service.cli.serve import session_token

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
runner = CliRunner()



def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


@pytest.mark.parametrize(("mask", "mode"), [(0o022, 0o644), (0o077, 0o600)], ids=["022", "077"])
def test_the_files_simulate_writes_follow_the_umask(tmp_path, umask, mask, mode):
    umask(mask)
    out = tmp_path / "frame"
    res = runner.invoke(app, ["simulate", str(EXAMPLES / "plane.yaml"), "--out", str(out),
                              "--spp", "1", "-q"])
    assert res.exit_code == 0, res.output
    files = sorted(out.iterdir())
    assert {p.name for p in files} >= {"frame.npz", "frame.json", "grey.png", "depth.png"}
    assert {p.name: _mode(p) for p in files} == {p.name: mode for p in files}


def test_the_session_token_stays_private_under_a_loose_umask(tmp_path, umask):
    umask(0o002)
    session_token(tmp_path / "data")
    assert _mode(tmp_path / "data" / "token") == 0o600
    assert _mode(tmp_path / "data") == 0o700


def test_the_database_and_the_lock_stay_private_under_a_loose_umask(tmp_path, umask):
    from service.store.data_lock import DataDirLock
    from service.store.database import init_db, make_engine

    umask(0o002)
    lock = DataDirLock.acquire(tmp_path / "data")
    try:
        engine = make_engine(f"sqlite:///{tmp_path / 'data' / 'toftwin.db'}")
        init_db(engine)
        engine.dispose()
        assert _mode(tmp_path / "data" / ".lock") == 0o600
        assert _mode(tmp_path / "data" / "toftwin.db") == 0o600
    finally:
        lock.release()


def test_a_broken_scene_file_is_named_with_its_line_and_column(tmp_path):
    scene = tmp_path / "scene.yaml"
    scene.write_text("name: broken\ncamera:\n  preset: pmd-camboard-pico-flexx\n pose: {}\n")
    res = runner.invoke(app, ["simulate", str(scene), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and res.stdout == ""
    err = " ".join(res.stderr.split())
    assert f"error: scene: scene file {scene}:4:2: invalid YAML: " in err, err
    assert "<unicode string>" not in err and not (tmp_path / "o").exists()


def test_a_broken_json_scene_file_is_named_with_its_line_and_column(tmp_path):
    scene = tmp_path / "scene.json"
    scene.write_text('{\n  "name": "broken",\n'
                     '  "camera": {"preset": "pmd-camboard-pico-flexx",}\n}\n')
    res = runner.invoke(app, ["simulate", str(scene), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert f"{scene}:3:50: invalid JSON: " in " ".join(res.stderr.split()), res.stderr


def test_a_broken_calibration_file_is_named_with_its_line_and_column(tmp_path):
    cal = tmp_path / "calibration.yaml"
    cal.write_text("camera:\n  fx_px: 210.0\n  depth: [phase_offset_rad: 0.1\n")
    res = runner.invoke(app, ["simulate", str(EXAMPLES / "plane.yaml"), "--out",
                              str(tmp_path / "o"), "--calibration", str(cal)])
    assert res.exit_code == 2 and res.stdout == ""
    err = " ".join(res.stderr.split())
    assert f"error: calibration: file {cal}:4:1: invalid YAML: " in err, err
    res = runner.invoke(app, ["correct", str(tmp_path), "--calibration", str(cal)])
    assert res.exit_code == 2 and f"{cal}:4:1: invalid YAML: " in " ".join(res.stderr.split())


def test_a_broken_material_file_in_a_scene_is_named_with_its_line(tmp_path):
    (tmp_path / "paint.yaml").write_text("kind: lambertian\nparams:\n  albedo: 0.5\n   x: 1\n")
    scene = (EXAMPLES / "plane.yaml").read_text().replace(
        "material: {kind: lambertian, params: {albedo: 0.8}}", "material: {file: paint.yaml}")
    (tmp_path / "scene.yaml").write_text(scene)
    res = runner.invoke(app, ["simulate", str(tmp_path / "scene.yaml"), "--out",
                              str(tmp_path / "o")])
    assert res.exit_code == 2
    assert f"material file {tmp_path / 'paint.yaml'}:4:" in " ".join(res.stderr.split())


def test_serve_with_a_bad_executor_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.delenv("TOFTWIN_TOKEN", raising=False)
    data = tmp_path / "data"
    res = runner.invoke(app, ["serve", "--simulated", "--data-dir", str(data), "--executor",
                              "foo"])
    assert res.exit_code == 2 and res.stdout == ""
    assert "--executor (TOFTWIN_EXECUTOR): " in res.stderr and "'foo'" in res.stderr
    assert not data.exists()  # no token file, not even the folder
