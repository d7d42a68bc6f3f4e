"""``toftwin bench accuracy`` and ``bench render``: the glossy corner is in both sweeps, a tiny
sweep of it gives finite figures, and an unknown scene is refused by name before any render."""

from __future__ import annotations

import io
import math

import pytest
from rich.console import Console
from typer.testing import CliRunner

from benchmarks.renderer import accuracy, render
from sim_core.errors import InvalidInputError
from sim_core.scene_spec import EXAMPLES_DIR
from toftwin_cli import app

#: the smallest sweep that still has a path integrator row: seconds, not minutes
TINY = {"spp": (2,), "bounces": (1, 2), "reference_spp": 4}


def _console() -> Console:
    return Console(file=io.StringIO(), width=200)


def test_both_sweeps_include_the_glossy_corner_and_every_default_scene_exists():
    assert "corner_glossy" in accuracy.SCENES
    assert "corner_glossy.yaml" in render.DEFAULT_SCENES
    for path in render.default_scene_paths():
        assert path.is_file(), path
    for name in accuracy.SCENES:
        assert (EXAMPLES_DIR / f"{name}.yaml").is_file(), name


def test_a_tiny_accuracy_sweep_of_the_glossy_corner_gives_finite_errors():
    rows = accuracy.run_accuracy_benchmark(None, False, _console(), ("corner_glossy",), TINY)
    assert {(r.integrator, r.bounces) for r in rows} == {("direct", 1), ("path", 2)}
    for r in rows:
        assert r.scene == "corner_glossy"
        assert math.isfinite(r.range_rmse_mm) and r.range_rmse_mm > 0.0
        assert math.isfinite(r.grey_rel_rmse) and r.seconds > 0.0


def test_the_accuracy_sweep_refuses_an_unknown_scene_by_name():
    with pytest.raises(InvalidInputError, match=r"no example scene 'corner_glosy'.*allowed:"):
        accuracy.run_accuracy_benchmark(None, True, _console(), ("corner", "corner_glosy"))
    res = CliRunner().invoke(app, ["bench", "accuracy", "--quick", "--scene", "nope"])
    assert res.exit_code == 2
    assert "'nope'" in res.output


def test_a_render_sweep_row_of_the_glossy_corner_adds_up():
    rows = render.run_render_benchmark(
        [EXAMPLES_DIR / "corner_glossy.yaml"], [1], [3], threads=2, console=_console())
    (row,) = rows
    assert (row["scene"], row["integrator"], row["bounces"]) == ("corner_glossy", "path", 3)
    shares = row["embree_share"] + row["kernel_share"] + row["other_share"]
    assert row["seconds"] > 0.0 and shares == pytest.approx(1.0, abs=1e-9)
