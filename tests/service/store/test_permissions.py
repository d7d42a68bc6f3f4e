"""The data directory and the database are the owner's alone."""

from __future__ import annotations

import stat

from service.lab.lab import open_lab
from service.store import queries
from tests.service.api.conftest import make_settings


def _mode(path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_the_data_directory_and_the_database_are_not_readable_by_others(tmp_path):
    data = tmp_path / "data"
    data.mkdir(mode=0o755)
    data.chmod(0o755)
    lab = open_lab(make_settings(data))
    try:
        with lab.session() as s:  # a write, so that the WAL exists
            queries.create_campaign(s, campaign_id="a" * 32, name="p", scene_name="x",
                                    scene_json="{}", scene_base_dir=".", mask={}, seed=0, spp=1,
                                    poses=[(0.0, 1.0, 1)])
        assert _mode(data) == 0o700
        for name in ("toftwin.db", "toftwin.db-wal", "toftwin.db-shm"):
            if (data / name).exists():
                assert _mode(data / name) & 0o077 == 0, (name, oct(_mode(data / name)))
        assert (data / "toftwin.db").exists()
    finally:
        lab.close()
