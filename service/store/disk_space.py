"""Room on the data directory's disk: how much is free, whether an error means "full", what to
say about it, and a small reserve that makes deleting possible on a full disk.

A campaign checks the free space before every pose and pauses, with a message that says what to
do, below ``settings.min_free_bytes``; a write that fails because the disk filled up anyway
(``ENOSPC`` from a frame file, SQLite's "database or disk is full") pauses it too instead of
failing it, so that resuming after space was freed goes on where it stopped. A request whose
write finds the disk full answers 507 naming what it was writing (:func:`writing`); whatever it
had written is removed, so nothing half-written stays behind.

The floor may be 0 (``TOFTWIN_MIN_FREE_BYTES=0``): then nothing is refused in advance, and the
first write that finds the disk full is the one that answers 507 (or pauses the campaign).

Deleting is the remedy for a full disk, but SQLite needs room to delete (its write-ahead log
grows by every page a transaction changes). :class:`SpaceReserve` keeps a small file of
allocated bytes in the data directory while there is room for it; a delete releases it first,
so that the rows can go, and makes it again afterwards if the room is there.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

from service.errors import InsufficientStorageError

_SQLITE_FULL = "database or disk is full"
_log = logging.getLogger(__name__)
#: the reserve's size: room for SQLite to delete the rows of a large campaign (4 KiB pages)
RESERVE_BYTES = 16 * 1024 * 1024
_UNITS = ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB")


def format_bytes(n: int | float) -> str:
    """A size in the unit that suits its magnitude (binary prefixes).

    >>> format_bytes(0), format_bytes(1000), format_bytes(12 * 1024), format_bytes(3.5 * 2**30)
    ('0 B', '1000 B', '12.0 KiB', '3.5 GiB')
    """
    value, unit = float(n), 0
    while abs(value) >= 1024 and unit < len(_UNITS) - 1:
        value, unit = value / 1024, unit + 1
    return f"{int(value)} B" if unit == 0 else f"{value:.1f} {_UNITS[unit]}"


def free_bytes(path: str | Path) -> int:
    """Bytes free for this process on the file system holding ``path``."""
    return shutil.disk_usage(path).free


def is_disk_full(exc: BaseException) -> bool:
    """True if ``exc`` (or what caused it) says the disk is full.

    >>> is_disk_full(OSError(errno.ENOSPC, "No space left on device"))
    True
    >>> is_disk_full(OSError(errno.EACCES, "Permission denied"))
    False
    """
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, InsufficientStorageError):
            return True
        if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
            return True
        if _SQLITE_FULL in str(exc):
            return True
        exc = getattr(exc, "orig", None) or exc.__cause__ or exc.__context__
    return False


def require_free(path: str | Path, min_bytes: int) -> None:
    """507 naming the free space and the threshold if less than ``min_bytes`` are free."""
    free = free_bytes(path)
    if free < min_bytes:
        raise InsufficientStorageError(low_space_message(free, min_bytes))


_ADVICE = ("delete old campaigns (DELETE /api/v1/campaigns/{id}) or frames "
           "(DELETE /api/v1/frames/{id}), or free space otherwise")


def low_space_message(free: int, min_bytes: int | None, *, then: str = ", then resume") -> str:
    """What an operator reads when the disk is (nearly) full, and what to do about it.

    Below the floor it names both; at or above it (a write found the disk full: the floor is 0,
    or the write was larger than what was left) it says so; ``min_bytes`` None: the floor is
    not the point (a delete). No server path: the data directory is the one the operator
    configured.

    >>> print(low_space_message(12 * 1024, 10**9).split(";")[0])
    disk space: 12.0 KiB free on the data directory's disk, below the 953.7 MiB kept free
    (TOFTWIN_MIN_FREE_BYTES)
    >>> print(low_space_message(0, 0).split(";")[0])
    disk full: 0 B free on the data directory's disk (no space is kept free:
    TOFTWIN_MIN_FREE_BYTES=0, so writes go on until the disk is full)
    """
    if min_bytes is None:
        state = f"disk full: {format_bytes(free)} free on the data directory's disk"
    elif free < min_bytes:
        state = (f"disk space: {format_bytes(free)} free on the data directory's disk, below "
                 f"the {format_bytes(min_bytes)} kept free (TOFTWIN_MIN_FREE_BYTES)")
    elif min_bytes == 0:
        state = (f"disk full: {format_bytes(free)} free on the data directory's disk (no space "
                 "is kept free: TOFTWIN_MIN_FREE_BYTES=0, so writes go on until the disk is "
                 "full)")
    else:
        state = (f"disk full: a write needed more than the {format_bytes(free)} free on the "
                 f"data directory's disk ({format_bytes(min_bytes)} kept free: "
                 "TOFTWIN_MIN_FREE_BYTES)")
    return f"{state}; {_ADVICE}{then}"


@contextlib.contextmanager
def writing(what: str, path: str | Path, min_bytes: int | None = None) -> Iterator[None]:
    """Turn a disk-full error inside the block into a 507 naming ``what`` was being written.

    The caller removes what it had written (frame files; SQLite rolls its transaction back).
    ``path``: where the data is (for the free space), ``min_bytes``: the floor kept free.
    """
    try:
        yield
    except InsufficientStorageError:
        raise
    except Exception as exc:
        if not is_disk_full(exc):
            raise
        raise InsufficientStorageError(disk_full_detail(what, path, min_bytes)) from exc


def disk_full_detail(what: str, path: str | Path, min_bytes: int | None = None) -> str:
    """The 507's detail when writing ``what`` found the disk full."""
    return (f"the disk is full: writing {what} failed, nothing of it was kept; "
            + low_space_message(_free_or_zero(path), min_bytes, then=""))


def _free_or_zero(path: str | Path) -> int:
    try:
        return free_bytes(path)
    except OSError:
        return 0


class SpaceReserve:
    """A file of ``size`` allocated bytes, given back to the disk while something is deleted.

    :meth:`fill` makes it when there is room (never an error: at start-up on a full disk it
    simply is not made); :meth:`released` removes it for the duration of a block (a delete)
    and makes it again afterwards, room permitting.
    """

    def __init__(self, path: str | Path, size: int = RESERVE_BYTES) -> None:
        self.path = Path(path)
        self.size = size

    @property
    def held(self) -> bool:
        """Whether the reserve is on disk at its full size."""
        try:
            return self.path.stat().st_size >= self.size
        except OSError:
            return False

    def fill(self) -> bool:
        """Allocate the reserve if it is not there; False (and nothing left over) if no room."""
        if self.held:
            return True
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            try:
                _allocate(fd, self.size)
                os.fsync(fd)
            finally:
                os.close(fd)
        except OSError as exc:
            self.release()
            _log.warning("no room for the %s disk reserve (%s): a delete on a full disk may "
                         "need its own room", format_bytes(self.size), exc.strerror or exc)
            return False
        return True

    def release(self) -> None:
        """Give the reserve's bytes back to the disk."""
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()

    @contextlib.contextmanager
    def released(self) -> Iterator[None]:
        """The block runs with the reserve given back; it is made afterwards if there is room
        (also when it was not there before: the block may have freed the room)."""
        self.release()
        try:
            yield
        finally:
            self.fill()


def _allocate(fd: int, size: int) -> None:
    """Really allocate ``size`` bytes (a sparse file would reserve nothing)."""
    if hasattr(os, "posix_fallocate"):
        try:
            os.posix_fallocate(fd, 0, size)
            return
        except OSError as exc:
            if exc.errno not in (errno.EOPNOTSUPP, errno.EINVAL):
                raise
    block = b"\0" * (1 << 20)
    written = 0
    while written < size:
        written += os.write(fd, block[: min(len(block), size - written)])
