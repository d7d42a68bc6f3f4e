"""A service killed with SIGKILL leaves no process behind: its pool workers and multiprocessing's
resource tracker follow it (checked by PID)."""

from __future__ import annotations

import os
import signal
import time

import psutil
import pytest

from tests.service.api.test_crash_resume import server

pytestmark = [pytest.mark.timeout(180), pytest.mark.slow]


def test_a_sigkilled_server_leaves_no_process_behind(tmp_path):
    with server(tmp_path / "data", tmp_path / "server.log") as (_client, proc):
        parent = psutil.Process(proc.pid)
        deadline = time.monotonic() + 60.0
        while len(children := parent.children(recursive=True)) < 3:  # 2 workers + tracker
            assert time.monotonic() < deadline, f"pool not started: {children}"
            time.sleep(0.2)
        pids = [c.pid for c in children]
        os.kill(proc.pid, signal.SIGKILL)  # the server only, as the OOM killer would
        proc.wait(timeout=10)
        _, alive = psutil.wait_procs([psutil.Process(p) for p in pids if psutil.pid_exists(p)],
                                     timeout=20)
        assert not alive, f"still running after the server died: {alive}"
