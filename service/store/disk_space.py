"""Room on the data directory's disk: how much is free, and whether an error means "full".

A campaign checks the free space before every pose and pauses, with a message that says what to
do, below ``settings.min_free_bytes``; a write that fails because the disk filled up anyway
(``ENOSPC`` from a frame file, SQLite's "database or disk is full") pauses it too instead of
failing it, so that resuming after space was freed goes on where it stopped.
"""

from __future__ import annotations

import errno
import shutil
from pathlib import Path

from service.errors import InsufficientStorageError

_SQLITE_FULL = "database or disk is full"


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
        raise InsufficientStorageError(low_space_message(path, free, min_bytes))


def low_space_message(path: str | Path, free: int, min_bytes: int) -> str:
    """What an operator reads when the disk is (nearly) full, and what to do about it."""
    return (f"disk space: {free / 1e9:.2f} GB free where the frames are stored ({path}), below "
            f"the {min_bytes / 1e9:.2f} GB kept free (TOFTWIN_MIN_FREE_BYTES); delete old "
            "campaigns (DELETE /api/v1/campaigns/{id}) or free space, then resume")
