"""Every command of the ``toftwin`` app and its numeric options, found by walking the typer app
(so that a new command or option is covered by the tests without being listed)."""

from __future__ import annotations

import types
import typing
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import typer
from typer.models import OptionInfo
from typer.utils import get_params_from_function

from toftwin_cli import app


def commands(t: typer.Typer = app, path: tuple[str, ...] = ()) -> Iterator[
        tuple[tuple[str, ...], Callable[..., Any]]]:
    """``(command path, function)`` of every command, groups included (their callback)."""
    for info in t.registered_commands:
        name = info.name or info.callback.__name__.replace("_", "-")
        yield (*path, name), info.callback
    for group in t.registered_groups:
        yield from commands(group.typer_instance, (*path, group.name))


def groups(t: typer.Typer = app, path: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    """The command path of the root and of every command group."""
    yield path
    for group in t.registered_groups:
        yield from groups(group.typer_instance, (*path, group.name))


def _number_type(annotation: Any) -> type | None:
    """int or float if the option takes numbers (``int``, ``float | None``, ``list[int]``)."""
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        inner = [a for a in args if a is not type(None)]
        return _number_type(inner[0]) if len(inner) == 1 else None
    if typing.get_origin(annotation) in (list, tuple):
        return _number_type(args[0])
    return annotation if annotation in (int, float) else None


@dataclass(frozen=True)
class NumericOption:
    command: tuple[str, ...]
    name: str
    kind: type
    info: OptionInfo

    @property
    def allowed(self):
        """The option's :class:`service.cli.common.Range` (None if it has none)."""
        return getattr(self.info.callback, "allowed", None)

    def __str__(self) -> str:
        return f"{' '.join(self.command)} {self.name}"


def numeric_options() -> list[NumericOption]:
    """Every option of every command that takes a number (or a list of numbers)."""
    out = []
    for path, func in commands():
        for name, meta in get_params_from_function(func).items():
            kind = _number_type(meta.annotation)
            if kind is None:
                continue
            info = meta.default
            decls = [d for d in (getattr(info, "param_decls", None) or ()) if d.startswith("--")]
            out.append(NumericOption(path, decls[0] if decls else "--" + name.replace("_", "-"),
                                     kind, info))
    return out
