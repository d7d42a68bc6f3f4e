"""The ``--out`` file of a command that writes one file (``toftwin export``): what is refused
before anything is written."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from sim_core.errors import InvalidInputError


def check_out_file(out: Path, sources: Sequence[Path], force: bool,
                   suffixes: tuple[str, ...], made_from: str = "the file") -> None:
    """Refuse an ``--out`` that is no file to write: without one of ``suffixes``, a folder, in
    a folder that is a file, one of the ``sources`` it is made from, or an existing file
    without ``force``."""
    if out.suffix.lower() not in suffixes:
        raise InvalidInputError("--out", f"'{out}': a {' or '.join(suffixes)} file")
    if out.is_dir():
        raise InvalidInputError("--out", f"'{out}' is a folder; give a file in it")
    parent = next((p for p in out.absolute().parents if p.exists()), None)
    if parent is not None and not parent.is_dir():
        raise InvalidInputError("--out", f"'{parent}' is a file, not a folder")
    for source in sources:
        if out.exists() and source.exists() and out.resolve() == source.resolve():
            raise InvalidInputError("--out", f"'{out}' is {made_from} it is made from")
    if out.exists() and not force:
        raise InvalidInputError("--out", f"'{out}' exists; use --force to replace it")
