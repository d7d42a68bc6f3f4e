"""One service per data directory: an exclusive lock on ``DATA_DIR/.lock``.

:func:`service.lab.lab.open_lab` takes it before it touches the database: a second service on
the same directory would otherwise mark the first one's running campaign ``interrupted`` and
sweep its frames in flight. The lock is an OS lock on an open file (``fcntl.flock`` on POSIX,
``msvcrt.locking`` on Windows), so it goes when its holder's process dies, however it dies:
there are no stale locks. The file itself stays; while held it says who holds it (pid, host,
start time, port, command) so that a refusal can name the holder; it is emptied on release.
A leftover description without a lock is simply overwritten by the next holder.

Both kinds of lock are per open file, so a second acquisition in the same process is refused
too. The file descriptor is not inherited by child processes started with ``spawn`` (the local
executor's workers) or ``exec``.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import json
import logging
import os
import socket
import sys
from pathlib import Path
from typing import Any

LOCK_NAME = ".lock"
_log = logging.getLogger(__name__)
#: Windows locks a byte range: one byte far past the description, so readers can read it
_WIN_LOCK_OFFSET = 1 << 20


class DataDirInUseError(RuntimeError):
    """Another process holds the data directory; ``holder`` is its description, if readable."""

    def __init__(self, data_dir: Path, holder: dict[str, Any] | None) -> None:
        self.data_dir = data_dir
        self.holder = holder
        super().__init__(
            f"data directory {data_dir} is in use by {describe(holder)}; "
            "stop it or use --data-dir"
        )


def describe(holder: dict[str, Any] | None) -> str:
    """``toftwin serve (pid 1234 on host X since 2026-..., port 8000)`` or a vaguer phrase."""
    if not holder:
        return "another process (it has not said which yet)"
    details = [f"pid {holder.get('pid', '?')} on host {holder.get('host', '?')}"]
    if holder.get("started"):
        details[0] += f" since {holder['started']}"
    if holder.get("port"):
        details.append(f"port {holder['port']}")
    return f"{holder.get('command') or 'a toftwin process'} ({', '.join(details)})"


def make_private(data_dir: Path) -> None:
    """Create ``data_dir`` (and parents) if missing; make it readable by its owner only (0700).

    The data directory holds the database, the frames and the session token: nobody else on
    the machine needs to read them. An existing directory owned by someone else is left as it
    is (chmod would fail; the service does not own it).
    """
    data_dir.mkdir(mode=0o700, parents=True, exist_ok=True)
    if hasattr(os, "getuid") and data_dir.stat().st_uid == os.getuid():
        os.chmod(data_dir, 0o700)


def read_holder(data_dir: str | Path) -> dict[str, Any] | None:
    """The description in the lock file (None if absent, empty or unreadable)."""
    try:
        text = (Path(data_dir) / LOCK_NAME).read_text(encoding="utf-8")
        holder = json.loads(text.rstrip("\0 \n")) if text.strip("\0 \n") else None
    except (OSError, ValueError):
        return None
    return holder if isinstance(holder, dict) else None


def _command() -> str:
    """``toftwin serve`` for the CLI (script or ``python -m toftwin_cli``), else the program."""
    argv = sys.argv
    if not argv or not argv[0]:
        return "python"
    path = Path(argv[0])
    if path.name == "toftwin" or path.parts[-2:] == ("toftwin_cli", "__main__.py"):
        words = [w for w in argv[1:2] if not w.startswith("-")]
        return " ".join(["toftwin", *words])
    if path.name == "__main__.py":  # python -m PACKAGE
        return f"python -m {path.parent.name}"
    return path.name


class DataDirLock:
    """The held lock of a data directory; :meth:`release` (or process exit) lets it go."""

    def __init__(self, data_dir: Path, fd: int, holder: dict[str, Any]) -> None:
        self.data_dir = data_dir
        self.holder = holder
        self._fd: int | None = fd

    @property
    def path(self) -> Path:
        return self.data_dir / LOCK_NAME

    @property
    def held(self) -> bool:
        return self._fd is not None

    @classmethod
    def acquire(cls, data_dir: str | Path, *, port: int | None = None) -> DataDirLock:
        """Lock ``data_dir`` (created if missing) or raise :class:`DataDirInUseError`."""
        data_dir = Path(data_dir)
        make_private(data_dir)
        fd = os.open(data_dir / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            locked = _try_lock(fd)
        except BaseException:
            os.close(fd)
            raise
        if not locked:
            os.close(fd)
            raise DataDirInUseError(data_dir, read_holder(data_dir))
        holder = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started": dt.datetime.now().astimezone().isoformat(timespec="seconds"),
            "port": port or None,
            "command": _command(),
        }
        try:
            _write(fd, json.dumps(holder, sort_keys=True) + "\n")
        except OSError as exc:
            # The lock is the OS lock, held; the description only names the holder. On a full
            # disk it cannot be written, and the service still starts (to serve reads and the
            # deletes that free space): a refused second service then says "another process".
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
            _log.warning("data directory %s locked, but its holder description could not be "
                         "written: %s", data_dir, exc.strerror or exc)
        except BaseException:
            _unlock(fd)
            os.close(fd)
            raise
        return cls(data_dir, fd, holder)

    @staticmethod
    def check(data_dir: str | Path) -> None:
        """Raise :class:`DataDirInUseError` if ``data_dir`` is locked; changes nothing.

        For an early, friendly refusal (``toftwin serve`` before it writes anything); only
        :meth:`acquire` protects the directory, as the holder may change right after.
        """
        data_dir = Path(data_dir)
        try:
            fd = os.open(data_dir / LOCK_NAME, os.O_RDWR)
        except FileNotFoundError:
            return
        try:
            if not _try_lock(fd):
                raise DataDirInUseError(data_dir, read_holder(data_dir))
            _unlock(fd)
        finally:
            os.close(fd)

    def release(self) -> None:
        """Empty the description and unlock (idempotent). The file is left in place."""
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            with contextlib.suppress(OSError):
                _write(fd, "")
            _unlock(fd)
        finally:
            os.close(fd)

    def __enter__(self) -> DataDirLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _write(fd: int, text: str) -> None:
    data = text.encode("utf-8")
    os.ftruncate(fd, 0)
    os.lseek(fd, 0, os.SEEK_SET)
    while data:
        data = data[os.write(fd, data):]


if sys.platform == "win32":  # pragma: no cover - exercised on Windows only
    import msvcrt

    def _try_lock(fd: int) -> bool:
        os.lseek(fd, _WIN_LOCK_OFFSET, os.SEEK_SET)
        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        except OSError:
            return False
        finally:
            os.lseek(fd, 0, os.SEEK_SET)
        return True

    def _unlock(fd: int) -> None:
        os.lseek(fd, _WIN_LOCK_OFFSET, os.SEEK_SET)
        with contextlib.suppress(OSError):
            msvcrt.locking(fd, msvcrt.LK_UNLCK, 1)
        os.lseek(fd, 0, os.SEEK_SET)

else:
    import errno
    import fcntl

    def _try_lock(fd: int) -> bool:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                return False
            raise
        return True

    def _unlock(fd: int) -> None:
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_UN)
