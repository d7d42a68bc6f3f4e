"""What every command shares: the consoles, how errors are printed, exit code 2 for invalid
input, and the allowed range of every numeric option.

Text is never parsed as rich markup: the consoles print what they are given (a unit in square
brackets such as ``[deg]`` or an extra such as ``.[bench]`` stays as it is), the help of every
command is plain text (``rich_markup_mode=None``, see :func:`command_group`), and styled words
(``error:``) are :class:`rich.text.Text` spans, not markup.
"""

from __future__ import annotations

import contextlib
import math
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.text import Text

from calibration.verdicts import Verdicts, verdict_lines
from sim_core.errors import InvalidInputError

if TYPE_CHECKING:
    from pydantic import BaseModel

    from service.lab.scenes import SceneSource

err_console = Console(stderr=True, markup=False)
#: in a pipe (CI logs, ``| tee``) rich would squeeze the benchmark tables into 80 columns
console = Console(markup=False) if sys.stdout.isatty() else Console(width=120, markup=False)


def command_group(help: str, **kwargs: Any) -> typer.Typer:
    """A typer app (the root or a command group) whose help is plain text: typer's rich
    markup would eat ``[deg]``, ``[m]`` and ``[nm]`` out of the option help."""
    return typer.Typer(help=help, no_args_is_help=True, rich_markup_mode=None, **kwargs)


def print_error(message: str) -> None:
    """``error: MESSAGE`` on stderr, the message as it is (no markup), one logical line."""
    err_console.print(Text.assemble(("error:", "bold red"), " ", str(message)), soft_wrap=True)


def print_warning(message: str, label: str = "warning:") -> None:
    """``warning: MESSAGE`` (or another label) on stderr, the message as it is."""
    err_console.print(Text.assemble((label, "yellow"), " ", str(message)), soft_wrap=True)


def print_verdicts(verdicts: Verdicts) -> None:
    """The verdicts' count and every key not determined or unexplained with its reason
    (:func:`calibration.verdicts.verdict_lines`)."""
    for line in verdict_lines(verdicts):
        console.print(line, markup=False, highlight=False)


def fail_invalid(exc: InvalidInputError) -> None:
    """Print the message (it names the field and the allowed range) and exit with code 2."""
    print_error(str(exc))
    raise typer.Exit(code=2)


# -- the allowed range of a numeric option ----------------------------------------------------
@dataclass(frozen=True)
class Range:
    """An interval of allowed values, ``[lo, hi]`` with either end open, plus single values
    ``also`` allowed outside it (``0`` for "off"); finite numbers only.

    >>> str(Range(0, 1e4, lo_open=True, unit="mm"))
    '(0, 10000] mm'
    >>> Range(0.8, 1.2, also=(0.0,)).contains(0.0), Range(1, 8).contains(float("nan"))
    (True, False)
    """

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False
    unit: str = ""
    also: tuple[float, ...] = ()

    def contains(self, value: float) -> bool:
        if not math.isfinite(value):
            return False
        if value in self.also:
            return True
        above = self.lo < value if self.lo_open else self.lo <= value
        below = value < self.hi if self.hi_open else value <= self.hi
        return above and below

    def __str__(self) -> str:
        text = (f"{'(' if self.lo_open else '['}{_number(self.lo)}, {_number(self.hi)}"
                f"{')' if self.hi_open else ']'}")
        if self.unit:
            text += f" {self.unit}"
        return text + "".join(f" or {_number(v)}" for v in self.also)


def _number(v: float) -> str:
    return str(v) if isinstance(v, int) else f"{v:g}"


def field_range(model: type[BaseModel], name: str, unit: str = "") -> Range:
    """The range a pydantic model declares for a field (``Field(ge=..., le=...)``): options
    that set such a field take their range from its one home."""
    lo = hi = None
    lo_open = hi_open = False
    for m in model.model_fields[name].metadata:
        if getattr(m, "ge", None) is not None:
            lo = m.ge
        if getattr(m, "gt", None) is not None:
            lo, lo_open = m.gt, True
        if getattr(m, "le", None) is not None:
            hi = m.le
        if getattr(m, "lt", None) is not None:
            hi, hi_open = m.lt, True
    if lo is None or hi is None:
        raise ValueError(f"{model.__name__}.{name} declares no closed range")
    return Range(lo, hi, lo_open, hi_open, unit)


def in_range(allowed: Range) -> Callable[[Any], Any]:
    """A typer option callback that refuses a value (or any of a list's values) outside
    ``allowed``: exit code 2, "Invalid value for '--name': X is outside [lo, hi]"."""

    def check(param: typer.CallbackParam, value: Any) -> Any:
        if value is None:  # not given; typer before 0.17 wants a repeatable option's () back
            return () if param.multiple else None
        for v in value if isinstance(value, list | tuple) else [value]:
            if not allowed.contains(v):
                raise typer.BadParameter(f"{v} is outside {allowed}")
        return value

    check.allowed = allowed  # type: ignore[attr-defined]  # what the tests read
    return check


def number_option(*decls: str, help: str, allowed: Range, **kwargs: Any) -> Any:
    """A ``typer.Option`` for a number (or a list of numbers) in ``allowed``; its help says
    the range."""
    return typer.Option(*decls, help=f"{help} Allowed: {allowed}.", callback=in_range(allowed),
                        **kwargs)


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
        TextColumn("{task.description}", markup=False),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} spp"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err_console,
        disable=quiet or not err_console.is_terminal,
        transient=True,
    )


#: ``--quiet``: no progress bar (:func:`progress_bar`, :func:`step_progress`)
QuietOption = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")]


@contextlib.contextmanager
def step_progress(quiet: bool, description: str,
                  total: int) -> Iterator[Callable[[int, int, str], None]]:
    """A progress bar on stderr over the ``total`` steps of a procedure on the rig (off in a
    pipe or with ``quiet``) while the block runs; yields the ``progress(done, total, message)``
    callback the procedure reports to."""
    with Progress(TextColumn("{task.description}", markup=False), BarColumn(),
                  TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=err_console, transient=True,
                  disable=quiet or not err_console.is_terminal) as bar:
        task = bar.add_task(description, total=total)

        def progress(done: int, total: int, message: str) -> None:
            bar.update(task, completed=done, total=total, description=message)

        yield progress


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
