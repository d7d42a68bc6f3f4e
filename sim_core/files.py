"""Files the project writes and the text files it reads: one home for both.

:func:`atomic_write` is the one way a file is written whole or not at all: into a temporary
name in the target's folder, flushed and fsynced, renamed over the target (``os.replace``), then
the folder fsynced so that the rename survives a power cut. The file gets the permissions any
new file of the process would get (``0o666 & ~umask``), not ``tempfile.mkstemp``'s 0600; a
secret (``secret=True``: a token, a database) gets 0600 whatever the umask.

:func:`load_structured` reads a YAML or JSON file a person wrote (a scene, a calibration, a
material, an object file) and, when it does not parse, raises :class:`StructuredFileError`
whose message is ``PATH:LINE:COLUMN: invalid YAML: what is wrong`` - the form editors and
terminals jump to - instead of the parser's ``<unicode string>``.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import yaml

#: permissions of a secret file (owner read and write only), whatever the umask
SECRET_MODE = 0o600

_UMASK_LOCK = threading.Lock()


def current_umask() -> int:
    """The process's umask, read without changing it where the OS allows (Linux's
    ``/proc/self/status``); elsewhere set and restored at once under a lock."""
    with contextlib.suppress(OSError, ValueError), open("/proc/self/status",
                                                          encoding="ascii") as fh:
        for line in fh:
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    with _UMASK_LOCK:
        mask = os.umask(0o022)
        os.umask(mask)
    return mask


def file_mode(secret: bool = False) -> int:
    """Permissions of a new file: 0600 for a secret, else ``0o666 & ~umask``."""
    return SECRET_MODE if secret else 0o666 & ~current_umask()


def fsync_dir(folder: str | Path) -> None:
    """Make a rename or a new entry in ``folder`` durable (a no-op where folders cannot be
    opened, as on Windows, or their fsync is refused)."""
    flags = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0)
    try:
        fd = os.open(folder, flags)
    except OSError:
        return
    try:
        with contextlib.suppress(OSError):
            os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write(
    path: str | Path,
    data: bytes | str | Callable[[IO[bytes]], Any],
    *,
    secret: bool = False,
    encoding: str = "utf-8",
) -> Path:
    """Write ``data`` to ``path`` whole or not at all; returns the path.

    Parameters
    ----------
    path : str or Path
        The target; its folder must exist. An existing file is replaced.
    data : bytes, str or callable
        The content: bytes, text (encoded with ``encoding``) or a function that writes into
        the binary file object it is given (``np.savez_compressed``, ``Image.save``, ...).
    secret : bool
        Permissions 0600 (owner only) instead of the umask's.

    A failure (the writer raising, a full disk) leaves the target as it was and removes the
    temporary file.
    """
    p = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        if hasattr(os, "fchmod"):
            os.fchmod(fd, file_mode(secret))
        with os.fdopen(fd, "wb") as fh:
            if callable(data):
                data(fh)
            else:
                fh.write(data.encode(encoding) if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    fsync_dir(p.parent)
    return p


class StructuredFileError(ValueError):
    """A YAML or JSON file that does not parse, with where: ``PATH:LINE:COLUMN: message``.

    Attributes
    ----------
    path : Path
    line, column : int or None
        1-based position of the problem (None where the parser does not say).
    problem : str
    """

    def __init__(self, path: Path, line: int | None, column: int | None, problem: str) -> None:
        self.path, self.line, self.column, self.problem = path, line, column, problem
        where = str(path) if line is None else f"{path}:{line}:{column or 1}"
        super().__init__(f"{where}: {problem}")


def _yaml_error(path: Path, exc: yaml.YAMLError) -> StructuredFileError:
    mark = getattr(exc, "problem_mark", None)
    problem = getattr(exc, "problem", None)
    if mark is None or problem is None:  # e.g. a ReaderError: no mark, its own text
        text = str(exc).replace('"<unicode string>"', f"'{path}'")
        return StructuredFileError(path, None, None, f"invalid YAML: {text}")
    context, context_mark = getattr(exc, "context", None), getattr(exc, "context_mark", None)
    if context and context_mark is not None and context_mark.line != mark.line:
        problem = f"{problem} ({context} at line {context_mark.line + 1})"
    elif context:
        problem = f"{problem} ({context})"
    return StructuredFileError(path, mark.line + 1, mark.column + 1, f"invalid YAML: {problem}")


def parse_structured(text: str, path: str | Path, *, json_only: bool | None = None) -> Any:
    """Parse ``text`` read from ``path``: JSON for a ``.json`` file (or ``json_only``), else
    YAML (which reads JSON too); :class:`StructuredFileError` naming the file and line.

    >>> parse_structured("camera:\\n  preset: x\\n bad: 1\\n", "scene.yaml")
    Traceback (most recent call last):
    ...
    sim_core.files.StructuredFileError: scene.yaml:3:2: invalid YAML: ...
    >>> parse_structured('{"a": 1,}', "twin.json")
    Traceback (most recent call last):
    ...
    sim_core.files.StructuredFileError: twin.json:1:9: invalid JSON: ...
    """
    p = Path(path)
    as_json = p.suffix.lower() == ".json" if json_only is None else json_only
    if as_json:
        try:
            return json.loads(text)
        except json.JSONDecodeError as exc:
            raise StructuredFileError(p, exc.lineno, exc.colno,
                                      f"invalid JSON: {exc.msg}") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise _yaml_error(p, exc) from None


def read_text(path: str | Path) -> str:
    """The UTF-8 text of ``path``; a byte that is not UTF-8 is a :class:`StructuredFileError`
    at its line and column."""
    p = Path(path)
    raw = p.read_bytes()
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        column = exc.start - (raw.rfind(b"\n", 0, exc.start) + 1) + 1
        raise StructuredFileError(p, line, column, f"not UTF-8 text (byte "
                                  f"0x{raw[exc.start]:02x})") from None


def load_structured(path: str | Path, *, json_only: bool | None = None) -> Any:
    """Read and parse a YAML or JSON file (:func:`read_text`, :func:`parse_structured`)."""
    return parse_structured(read_text(path), path, json_only=json_only)
