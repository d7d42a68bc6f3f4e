"""Session set-up shared by every test directory."""

from __future__ import annotations

import fcntl
import hashlib
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from hypothesis import settings

#: Hypothesis's per-example deadline is a timing assertion: the first example of a test may
#: compile a numba kernel (1.6 s seen on a loaded machine against the 200 ms default), so the
#: suite's outcome would depend on the load. Examples are bounded by their count instead.
settings.register_profile("toftwin", deadline=None)
settings.load_profile("toftwin")


def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile the renderer's kernels (or load them from numba's cache) before the first test.

    In a fresh clone numba compiles them on first use, a minute or more that would otherwise
    land on whichever test renders first (a tabulated material's, ``bounce``'s second
    compilation: 63 s on a 2-core Xeon, which once took a 60 s test past its timeout); here
    they are a cost of the session, once, and every test's duration is its own. Under
    pytest-xdist each worker does it (the controller runs no test), one at a time: numba writes
    a cache entry's index before its data, so a worker reading while another writes can load
    the data of an older source or another numba version (a floors venv on the same clone died
    on LLVM 22 bitcode read by LLVM 14). The first worker compiles, the next loads what it
    wrote.
    """
    config = session.config
    if config.option.collectonly:
        return
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        return
    from service.compute.jobs import warm_up

    clone = hashlib.sha256(str(config.rootpath).encode()).hexdigest()[:16]
    lock_path = Path(tempfile.gettempdir()) / f"toftwin-numba-warm-up-{clone}.lock"
    with open(lock_path, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            warm_up(tabulated=True)
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


@pytest.fixture
def umask() -> Iterator[Callable[[int], int]]:
    """Set the process's umask for one test (``umask(0o077)``); restored afterwards."""
    old = os.umask(0o022)
    os.umask(old)
    yield os.umask
    os.umask(old)
