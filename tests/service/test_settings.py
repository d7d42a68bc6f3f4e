"""Settings fail fast, come from the environment or a file, and are all documented."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from pydantic import ValidationError

from service.settings import Settings, dask_scheduler

SERVICE_DOC = Path(__file__).resolve().parents[2] / "docs" / "service.md"

pytestmark = pytest.mark.timeout(60)


def test_settings_refuse_placeholder_tokens_and_unknown_executors(tmp_path):
    for token in ("changethis", "short"):
        with pytest.raises(ValidationError, match="token"):
            Settings(token=token, data_dir=tmp_path)
    with pytest.raises(ValidationError, match="dask://HOST:PORT"):
        Settings(token="a-real-token-123", executor="spark://x")
    # (a dask:// executor is valid where the dask extra is installed: test_dask_extra.py)
    assert dask_scheduler("dask://10.0.0.5:8786") == "tcp://10.0.0.5:8786"
    s = Settings(token="a-real-token-123", executor="local", data_dir=tmp_path)
    assert s.dask_address is None and s.host == "127.0.0.1"
    assert s.database == f"sqlite:///{tmp_path / 'toftwin.db'}"


def test_settings_come_from_the_environment_or_a_file(tmp_path, monkeypatch):
    monkeypatch.setenv("TOFTWIN_TOKEN", "from-the-environment")
    monkeypatch.setenv("TOFTWIN_WORKERS", "3")
    assert Settings.load().workers == 3
    env = tmp_path / "toftwin.env"
    env.write_text("TOFTWIN_PORT=9001\nTOFTWIN_SIMULATED=true\n")
    s = Settings.load(env, workers=2)
    assert (s.port, s.simulated, s.workers) == (9001, True, 2)


def settings_section(markdown: str) -> str:
    """The text of the ``## Settings`` section."""
    m = re.search(r"^## Settings\n(.*?)(?=^## )", markdown, flags=re.M | re.S)
    assert m, f"{SERVICE_DOC.name} has no '## Settings' section"
    return m.group(1)


def test_every_setting_is_documented():
    section = settings_section(SERVICE_DOC.read_text(encoding="utf-8"))
    words = {w for span in re.findall(r"`([^`]+)`", section) for w in re.findall(r"\w+", span)}
    missing = [name for name in Settings.model_fields
               if f"TOFTWIN_{name.upper()}" not in words and name not in words]
    assert not missing, (
        f"Settings fields (service/settings.py) missing from the settings table of "
        f"{SERVICE_DOC.name}: {missing}; add TOFTWIN_<FIELD> with its default and meaning")


def test_faults_are_checked_and_need_the_simulated_rig(tmp_path):
    from pydantic import ValidationError

    from service.settings import Settings

    ok = Settings(token="t" * 16, data_dir=tmp_path, simulated=True,
                  faults=["solar-simulator:lamp-fault:1@6", "turntable:stall"])
    assert len(ok.faults) == 2
    with pytest.raises(ValidationError, match=r"\[1\] .*unknown fault 'smoke'"):
        Settings(token="t" * 16, data_dir=tmp_path, simulated=True,
                 faults=["camera:drop", "camera:smoke"])
    with pytest.raises(ValidationError, match="needs the simulated rig"):
        Settings(token="t" * 16, data_dir=tmp_path, faults=["turntable:stall"])


def test_the_camera_setting_names_the_allowed_forms(tmp_path):
    for camera in ("usb", "royale", "tcp://labpc:5600"):
        assert Settings(token="a-real-token-123", camera=camera, data_dir=tmp_path).camera == camera
    for bad in ("udp://labpc:5600", "tcp://labpc", "pico"):
        with pytest.raises(ValidationError, match=r"camera\n.*'usb', 'royale' or a camera bridge"):
            Settings(token="a-real-token-123", camera=bad, data_dir=tmp_path)
    with pytest.raises(ValidationError, match="camera: royale opens a real pico flexx"):
        Settings(token="a-real-token-123", camera="royale", simulated=True, data_dir=tmp_path)
