"""The README's "where things live" table stays true: every package is in it, every path and
command in it exists."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from typer.testing import CliRunner

from toftwin_cli import app

ROOT = Path(__file__).resolve().parents[2]


def _table() -> list[list[str]]:
    text = (ROOT / "README.md").read_text()
    section = text.split("## Where things live", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| `")]
    return [[cell.strip() for cell in row.strip("|").split("|")] for row in rows]


def _packages(folder: Path) -> list[Path]:
    return sorted(p.parent for p in folder.glob("*/__init__.py"))


def test_the_table_names_every_top_level_package_and_every_service_sub_package():
    named = {cells[0].strip("`").rstrip("/") for cells in _table()}
    top = [p.relative_to(ROOT).as_posix() for p in _packages(ROOT) if p.name != "tests"]
    service = [p.relative_to(ROOT).as_posix()
               for p in sorted((ROOT / "service").rglob("__init__.py"))
               for p in [p.parent] if p.name != "service"]
    missing = [p for p in top + service if p not in named]
    assert not missing, f"README 'Where things live' does not name: {missing}"
    assert {"sim_core", "drivers", "calibration", "service"} <= set(top)


def test_every_folder_in_the_table_exists():
    for cells in _table():
        assert (ROOT / cells[0].strip("`")).is_dir(), cells[0]


def _commands() -> list[str]:
    return [c for cells in _table() for c in re.findall(r"`([^`]+)`", cells[-1])]


@pytest.mark.parametrize("command", [c for c in _commands() if c.startswith("toftwin")])
def test_every_toftwin_command_in_the_table_exists_with_its_options(command):
    words = shlex.split(command)[1:]
    options = [w for w in words if w.startswith("--")]
    command_path = [w for w in words if not w.startswith("-")][:2]
    res = CliRunner().invoke(app, [*command_path, "--help"])
    assert res.exit_code == 0, res.output
    for option in options:  # every option the table uses is one the command knows
        assert option in res.output, f"{command}: {option} is not an option"
    for word in words:  # files the command is given exist
        if word.startswith("examples/"):
            assert (ROOT / word).is_file(), word


@pytest.mark.parametrize("command", [c for c in _commands() if c.startswith("pytest ")])
def test_every_test_folder_in_the_table_exists(command):
    for target in shlex.split(command)[1:]:
        assert (ROOT / target).exists(), target
