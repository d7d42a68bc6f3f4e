"""A second ``toftwin serve`` on the data directory of a running one is refused, harmlessly.

Before the lock, the second server's start-up marked the first one's running campaign
``interrupted`` and swept its frames in flight. Now it exits with code 2 naming the holder, and
the first server's campaign runs on to completion with all its frames.

The first server is a real process; it is frozen (SIGSTOP) with its poses in flight while the
second one tries, so the attempt always meets a running campaign, however loaded the machine.
The second one is ``toftwin serve`` run in this process (the command line's own entry): the
lock is per open file and its holder another process, as between two servers.
"""

from __future__ import annotations

import os
import signal

import pytest

from service.store.data_lock import DataDirLock, read_holder
from tests.service.api.conftest import TOKEN
from tests.service.api.test_crash_resume import (
    ONE_WORKER_TWO_IN_FLIGHT,
    free_port,
    server,
    start_campaign,
    wait_for,
)

pytestmark = pytest.mark.timeout(180)

#: after the first pose, four to go: the campaign is still running when it is frozen (the
#: freeze follows the first pose's report within milliseconds; a pose takes ~0.5 CPU seconds)
POSES = [{"turntable_deg": a, "solar_suns": 1.0, "repeats": 1} for a in (-40, -20, 0, 20, 40)]


def test_a_second_server_on_the_same_data_dir_is_refused(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from service.cli import app

    data, log = tmp_path / "data", tmp_path / "server.log"
    with server(data, log, **ONE_WORKER_TWO_IN_FLIGHT) as (client, proc):
        cid = start_campaign(client, "first", POSES, seed=3, poses_done=1)

        # the second one: no TOFTWIN_TOKEN, so it would write DATA_DIR/token if it got that far
        monkeypatch.delenv("TOFTWIN_TOKEN", raising=False)
        os.killpg(proc.pid, signal.SIGSTOP)  # the first server and its worker, mid-campaign
        try:
            second = CliRunner().invoke(app, ["serve", "--simulated", "--port", str(free_port()),
                                              "--data-dir", str(data)])
        finally:
            os.killpg(proc.pid, signal.SIGCONT)
        assert second.exit_code == 2, second.output
        message = " ".join(second.output.split())
        assert f"error: data directory {data} is in use by toftwin serve (pid {proc.pid} " \
               in message, message
        assert "stop it or use --data-dir" in message
        assert not (data / "token").exists()

        status = client.get(f"/api/v1/campaigns/{cid}").json()
        assert status["state"] == "running" and status["poses_done"] < len(POSES), status
        status = wait_for(client, cid, lambda s: s["state"] != "running")
        assert status["state"] == "completed", status
        rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
        assert sorted(r["pose_index"] for r in rows) == list(range(len(POSES)))
        named = {r[k] for r in rows for k in ("measured_frame_id", "simulated_frame_id")}
        assert {p.name for p in (data / "frames").iterdir()} == named
        campaigns = client.get("/api/v1/campaigns").json()
        assert [c["state"] for c in campaigns] == ["completed"]

        proc.send_signal(signal.SIGTERM)  # a graceful stop (uvicorn re-raises the signal)
        assert proc.wait(timeout=30) in (0, -signal.SIGTERM)
    assert "interrupted" not in log.read_text()
    # and the stopped server let the directory go
    assert read_holder(data) is None
    DataDirLock.check(data)


def test_serve_maps_a_refusal_at_start_up_to_exit_code_2(tmp_path, monkeypatch):
    """The lock taken between serve's early check and the app's start-up: still exit code 2."""
    from typer.testing import CliRunner

    from service.cli import app
    from service.store import data_lock

    data = tmp_path / "data"
    real_check, calls = data_lock.DataDirLock.check, []

    def late_check(path):  # the early check passes, as if the other server came just after
        calls.append(path)
        if len(calls) > 1:
            real_check(path)

    monkeypatch.setattr(data_lock.DataDirLock, "check", staticmethod(late_check))
    monkeypatch.setenv("TOFTWIN_TOKEN", TOKEN)
    with data_lock.DataDirLock.acquire(data, port=1234):
        result = CliRunner().invoke(app, ["serve", "--simulated", "--executor", "thread",
                                          "--port", str(free_port()), "--data-dir", str(data)])
    assert result.exit_code == 2, result.output
    assert len(calls) == 2
    assert f"pid {os.getpid()} " in " ".join(result.output.split())
