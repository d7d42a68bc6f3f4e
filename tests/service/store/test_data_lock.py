"""The data-directory lock: one holder at a time, named in the refusal, gone with its process."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from service.lab.lab import open_lab
from service.store import queries
from service.store.data_lock import LOCK_NAME, DataDirInUseError, DataDirLock, read_holder
from tests.service.api.conftest import make_settings

ROOT = Path(__file__).parents[3]


def test_a_second_acquisition_in_the_same_process_is_refused(tmp_path):
    first = DataDirLock.acquire(tmp_path / "data", port=8123)
    try:
        holder = read_holder(tmp_path / "data")
        assert holder == first.holder
        assert holder["pid"] == os.getpid() and holder["host"] == socket.gethostname()
        assert holder["port"] == 8123 and holder["started"]
        with pytest.raises(DataDirInUseError) as info:
            DataDirLock.acquire(tmp_path / "data")
        message = str(info.value)
        assert f"data directory {tmp_path / 'data'} is in use by" in message
        assert f"pid {os.getpid()} on host {socket.gethostname()} since " in message
        assert "port 8123" in message and message.endswith("stop it or use --data-dir")
        with pytest.raises(DataDirInUseError):
            DataDirLock.check(tmp_path / "data")
    finally:
        first.release()
    assert read_holder(tmp_path / "data") is None  # emptied, not deleted (see data_lock)
    assert (tmp_path / "data" / LOCK_NAME).exists()
    DataDirLock.check(tmp_path / "data")
    with DataDirLock.acquire(tmp_path / "data") as again:
        assert again.held
    assert not again.held
    again.release()  # idempotent


def test_check_changes_nothing(tmp_path):
    DataDirLock.check(tmp_path / "absent")
    assert not (tmp_path / "absent").exists()


HOLDER = textwrap.dedent("""
    import sys, time
    from service.store.data_lock import DataDirLock
    lock = DataDirLock.acquire(sys.argv[1], port=9999)
    print("locked", flush=True)
    time.sleep(120)
""")


def test_another_process_is_refused_until_the_holder_dies(tmp_path):
    data = tmp_path / "data"
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(data)], cwd=ROOT,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "locked"
        with pytest.raises(DataDirInUseError) as info:
            DataDirLock.acquire(data)
        assert info.value.holder["pid"] == proc.pid
        assert f"pid {proc.pid} on host" in str(info.value) and "port 9999" in str(info.value)
    finally:
        proc.send_signal(signal.SIGKILL)  # no clean-up runs: the OS drops the lock
        proc.wait(timeout=10)
    assert read_holder(data)["pid"] == proc.pid  # the dead holder's description is left...
    with DataDirLock.acquire(data) as lock:  # ...and is no obstacle
        assert read_holder(data) == lock.holder


def test_a_second_lab_on_the_same_directory_touches_nothing(tmp_path):
    lab = open_lab(make_settings(tmp_path))
    try:
        with lab.session() as s:
            queries.create_campaign(
                s, campaign_id="c" * 32, name="busy", scene_name="x", scene_json="{}",
                scene_base_dir="", mask={}, seed=0, spp=1, poses=[(0.0, 0.0, 1)])
            assert queries.transition(s, "c" * 32, ("created",), "running")
        orphan = lab.store.root / ("d" * 32)  # a frame in flight: on disk, its row not yet
        orphan.mkdir()
        with pytest.raises(DataDirInUseError, match=f"pid {os.getpid()} "):
            open_lab(make_settings(tmp_path))
        with lab.session() as s:
            assert queries.get_campaign(s, "c" * 32).state == "running"
        assert orphan.is_dir()
    finally:
        lab.close()
    assert read_holder(tmp_path) is None
    lab = open_lab(make_settings(tmp_path))  # released by close: the next start recovers
    try:
        assert lab.recovered == {"interrupted": ["c" * 32], "swept_frames": ["d" * 32],
                                 "failed_calibrations": []}
    finally:
        lab.close()
