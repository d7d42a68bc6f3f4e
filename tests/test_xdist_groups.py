"""The slow suite shares expensive calibrations between tests of one ``xdist_group`` (CI runs it
with ``-n 2 --dist loadgroup``): a pytest whose workers ignore the groups runs each of those
calibrations twice (pytest 9.2 with pytest-xdist 3.8 did, silently: pytest-dev/pytest-xdist
#1386; the satellite campaign then took 370 s instead of 23). This runs a tiny suite the way CI
runs the slow one and checks the grouped tests ran in one worker process."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(120)

SUITE = '''
import os
import pytest

GROUP = pytest.mark.xdist_group("shared")


def _record(name):
    with open(os.environ["PIDS_FILE"], "a") as f:
        f.write(f"{name} {os.getpid()}\\n")


@pytest.mark.parametrize("k", [pytest.param(k, marks=GROUP) for k in range(3)])
def test_param_in_group(k):
    _record(f"param{k}")


@GROUP
def test_function_in_group():
    _record("function")


@pytest.mark.parametrize("k", range(6))
def test_others(k):
    _record(f"other{k}")
'''


def test_tests_of_one_xdist_group_run_in_one_worker(tmp_path: Path):
    (tmp_path / "test_grouped.py").write_text(SUITE)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    pids = tmp_path / "pids.txt"
    res = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "2",
         "--dist", "loadgroup", str(tmp_path)],
        cwd=tmp_path, capture_output=True, text=True, timeout=100,
        env={"PIDS_FILE": str(pids), "PATH": "/usr/bin:/bin"})
    assert res.returncode == 0, res.stdout + res.stderr
    seen = dict(line.split() for line in pids.read_text().splitlines())
    assert len(seen) == 10
    assert len(set(seen.values())) == 2, seen  # two workers ran the suite
    # the group's four tests in one of them (round robin would spread them)
    assert {seen[n] for n in ("param0", "param1", "param2", "function")} == {
        seen["function"]}, seen
