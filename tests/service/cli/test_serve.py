"""A simulated service started without a token gets a random one, stored privately."""

import stat

import pytest
import typer

from service.cli.serve import session_token


def test_session_token_is_random_private_and_stored(tmp_path):
    a = session_token(tmp_path)
    path = tmp_path / "token"
    assert path.read_text().strip() == a
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert len(a) >= 24
    assert session_token(tmp_path) != a  # a new one every start


def test_a_loose_existing_token_file_becomes_private(tmp_path):
    path = tmp_path / "token"
    path.write_text("old\n")
    path.chmod(0o644)
    token = session_token(tmp_path)
    assert path.read_text().strip() == token
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert stat.S_IMODE(tmp_path.stat().st_mode) == 0o700  # the data directory too


def test_a_token_path_that_is_a_symlink_is_refused_and_its_target_untouched(tmp_path):
    target = tmp_path / "elsewhere"
    target.write_text("precious\n")
    data = tmp_path / "data"
    data.mkdir()
    (data / "token").symlink_to(target)
    with pytest.raises(typer.Exit) as info:
        session_token(data)
    assert info.value.exit_code == 2
    assert target.read_text() == "precious\n"


def test_serve_refuses_a_bad_fault_with_exit_code_2_before_starting(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from service.cli import app

    monkeypatch.delenv("TOFTWIN_TOKEN", raising=False)
    res = CliRunner().invoke(app, ["serve", "--simulated", "--data-dir", str(tmp_path),
                                   "--fault", "turntable:stall", "--fault", "oven:smoke"])
    assert res.exit_code == 2, res.output
    text = " ".join(res.output.split())
    assert "[1] cannot parse 'oven:smoke'" in text and "expected DEVICE:" in text, text


def test_serve_refuses_a_bad_reality_with_exit_code_2_naming_the_field(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from service.cli import app

    monkeypatch.delenv("TOFTWIN_TOKEN", raising=False)
    bad = tmp_path / "reality.yaml"
    bad.write_text("camera:\n  fx_px: -3\n")
    res = CliRunner().invoke(app, ["serve", "--simulated", "--data-dir", str(tmp_path / "d"),
                                   "--reality", str(bad)])
    assert res.exit_code == 2, res.output
    text = " ".join(res.output.split())
    assert "reality.camera.fx_px" in text and "outside [9.799, 1e+09] px" in text, text
    good = tmp_path / "good.yaml"
    good.write_text("turntable: {zero_offset_deg: 0.7}\n")
    res = CliRunner().invoke(app, ["serve", "--data-dir", str(tmp_path / "e"), "--reality",
                                   str(good)], env={"TOFTWIN_TOKEN": "a-long-enough-token"})
    assert res.exit_code == 2 and "needs the simulated rig" in " ".join(res.output.split())
