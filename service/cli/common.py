"""What every command shares: the consoles, exit code 2 for invalid input, bounded options."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from sim_core.errors import InvalidInputError

if TYPE_CHECKING:
    from service.lab.scenes import SceneSource

err_console = Console(stderr=True)
#: in a pipe (CI logs, ``| tee``) rich would squeeze the benchmark tables into 80 columns
console = Console() if sys.stdout.isatty() else Console(width=120)


def fail_invalid(exc: InvalidInputError) -> None:
    """Print the message (it names the field and the allowed range) and exit with code 2."""
    err_console.print(f"[bold red]error:[/] {exc}")
    raise typer.Exit(code=2)


def bounded(name: str, value: int, lo: int, hi: int) -> int:
    """``value`` if it is in [lo, hi], else an input error naming the option.

    >>> bounded("--spp", 16, 1, 65536)
    16
    >>> bounded("--spp", 0, 1, 65536)
    Traceback (most recent call last):
    ...
    sim_core.errors.InvalidInputError: --spp: 0 is outside [1, 65536]
    """
    if not lo <= value <= hi:
        raise InvalidInputError(name, f"{value} is outside [{lo}, {hi}]")
    return value


def int_list(name: str, texts: list[str], lo: int, hi: int) -> list[int]:
    """Integers of an option given as comma-separated lists, repeatable, each in [lo, hi].

    >>> int_list("--spp", ["16,64", "256"], 1, 65536)
    [16, 64, 256]
    >>> int_list("--spp", ["16,x"], 1, 65536)
    Traceback (most recent call last):
    ...
    sim_core.errors.InvalidInputError: --spp: 'x' is not an integer; give e.g. 16,64,256
    """
    out = []
    for text in texts:
        for part in text.split(","):
            try:
                v = int(part.strip())
            except ValueError:
                raise InvalidInputError(
                    name, f"'{part.strip()}' is not an integer; give e.g. 16,64,256"
                ) from None
            out.append(bounded(name, v, lo, hi))
    return out


def choice(name: str, value: str, allowed: tuple[str, ...]) -> str:
    """``value`` if it is one of ``allowed``, else an input error naming the option."""
    if value not in allowed:
        raise InvalidInputError(name, f"'{value}' is not one of {list(allowed)}")
    return value


def progress_bar(quiet: bool) -> Progress:
    """A progress bar on stderr (off in a pipe or with ``quiet``)."""
    return Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} spp"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err_console,
        disable=quiet or not err_console.is_terminal,
        transient=True,
    )


def check_rig_options(out: Path, reality: Path | None, simulated: bool) -> None:
    """The options of every command that runs on the rig: a new output folder, and a reality
    only for the simulated lab."""
    if out.exists():
        raise InvalidInputError("--out", f"'{out}' exists; give a new folder")
    if reality is not None and not simulated:
        raise InvalidInputError("--reality", "describes the simulated lab: needs --simulated")


def rig_scene(scene: str) -> SceneSource:
    """``--scene``: a scene file (its folder resolves its paths) or a bundled scene's name."""
    from service.lab.scenes import SceneSource, resolve_scene
    from service.settings import EXAMPLES_DIR
    from sim_core.scene_spec import load_scene_spec

    if Path(scene).suffix.lower() in (".yaml", ".yml", ".json"):
        return SceneSource(load_scene_spec(scene), Path(scene).parent, Path(scene).stem)
    return resolve_scene(scene, EXAMPLES_DIR, max_objects=10000)
