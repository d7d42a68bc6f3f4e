"""What the command line prints: units in square brackets survive in every help and in error
messages, ``--version``, and every error goes to stderr (stdout carries only results)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner
from typer.utils import get_params_from_function

from service.cli.schema import SCHEMAS
from tests.service.cli.commands import commands, groups
from toftwin_cli import app

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
BRACKETS = re.compile(r"\[[^\]\[]+\]")
runner = CliRunner()


def _flat(text: str) -> str:
    return " ".join(text.split())


def _bracketed_help(func) -> list[str]:
    """Every ``[...]`` in a command's docstring and its parameters' help."""
    texts = [func.__doc__ or ""]
    texts += [getattr(m.default, "help", None) or ""
              for m in get_params_from_function(func).values()]
    return [b for t in texts for b in BRACKETS.findall(_flat(t))]


COMMANDS = list(commands())


def test_the_units_are_found_in_the_help_texts():
    found = {b for _, func in COMMANDS for b in _bracketed_help(func)}
    assert {"[deg]", "[m]", "[nm]", "[sun]"} <= found, found


@pytest.mark.parametrize(("path", "func"), COMMANDS, ids=[" ".join(p) for p, _ in COMMANDS])
def test_every_command_help_keeps_its_square_brackets(path, func):
    res = runner.invoke(app, [*path, "--help"])
    assert res.exit_code == 0, res.output
    text = _flat(res.stdout)
    for bracketed in _bracketed_help(func):
        assert bracketed in text, f"toftwin {' '.join(path)} --help lost {bracketed}"


@pytest.mark.parametrize("path", list(groups()), ids=lambda p: " ".join(p) or "toftwin")
def test_every_group_help_is_plain_text(path):
    res = runner.invoke(app, [*path, "--help"])
    assert res.exit_code == 0 and "Usage: " in res.stdout
    assert "╭" not in res.stdout  # no rich panels: their markup ate the units


def test_simulate_help_says_degrees():
    res = runner.invoke(app, ["simulate", "--help"])
    assert "Override the turntable angle [deg]." in _flat(res.stdout)


def test_an_error_message_with_a_unit_in_brackets_prints_it(tmp_path):
    preset = "  preset: pmd-camboard-pico-flexx\n"
    scene = (EXAMPLES / "plane.yaml").read_text().replace(preset, preset + "  fov[deg]: 60\n")
    folder = tmp_path / "wall [m] 2"
    folder.mkdir()
    (folder / "plane.yaml").write_text(scene)
    res = runner.invoke(app, ["simulate", str(folder / "plane.yaml"), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and res.stdout == ""
    assert "error: camera.fov[deg]: " in _flat(res.stderr), res.stderr
    res = runner.invoke(app, ["simulate", str(folder / "nope.yaml"), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and f"{folder / 'nope.yaml'}' does not exist" in res.stderr


def test_version_prints_the_package_version_and_exits_0():
    from sim_core.frame_io import package_version

    res = runner.invoke(app, ["--version"])
    assert res.exit_code == 0
    assert res.stdout == f"toftwin {package_version()}\n"
    assert re.fullmatch(r"toftwin \d+\.\d+\S*\n", res.stdout)


def _rig_out(tmp_path: Path) -> str:
    (tmp_path / "exists").mkdir(exist_ok=True)
    return str(tmp_path / "exists")


#: one invalid call of every command: exit code, then what stderr must say
ERROR_CALLS = {
    "simulate": (lambda t: ["simulate", str(t / "none.yaml"), "--out", str(t / "o")], 2,
                 "does not exist"),
    "preview": (lambda t: ["preview", str(t / "none"), "--out", str(t / "p.png")], 2, "none"),
    "compare": (lambda t: ["compare", str(t / "a"), str(t / "b"), "--out", str(t / "c.json")], 2,
                "raw.npz"),
    "correct": (lambda t: ["correct", str(t / "a"), "--calibration", str(t / "none.yaml")], 2,
                "does not exist"),
    "serve": (lambda t: ["serve", "--simulated", "--data-dir", str(t / "d"), "--executor", "foo"],
              2, "--executor"),
    "sim-device": (lambda t: ["sim-device", "toaster"], 2, "KIND: 'toaster'"),
    "sim-device --transport": (lambda t: ["sim-device", "turntable", "--transport", "pigeon"], 2,
                               "--transport: 'pigeon'"),
    "sim-device --fault": (lambda t: ["sim-device", "turntable", "--fault", "nope"], 2,
                           "unknown fault 'nope'"),
    "camera-bridge": (lambda t: ["camera-bridge", "--port", "70000"], 2, "--port"),
    "camera-bridge royale": (lambda t: ["camera-bridge", "--port", "0"], 1,
                             "royale not installed: cannot import roypy"),
    "fit-object": (lambda t: ["fit-object", "--out", _rig_out(t), "--simulated"], 2, "exists"),
    "calibrate rig": (lambda t: ["calibrate", "rig", "--out", _rig_out(t), "--simulated"], 2,
                      "exists"),
    "calibrate material": (lambda t: ["calibrate", "material", "--out", str(t / "m.yaml"),
                                      "--prior", "unobtainium"], 2, "--prior"),
    "calibrate brdf": (lambda t: ["calibrate", "brdf", str(t / "none.csv"), "--model",
                                  "lambertian", "--out", str(t / "m.yaml")], 2, "none.csv"),
    "calibrate intrinsics": (lambda t: ["calibrate", "intrinsics", str(t / "none.png"),
                                        "--board", "chessboard", "--squares", "10x7",
                                        "--square-mm", "25", "--out", str(t / "i")], 2,
                             "none.png"),
    "bench accuracy": (lambda t: ["bench", "accuracy", "--scene", "nope"], 2, "'nope'"),
    "bench mitsuba": (lambda t: ["bench", "mitsuba", "--spp", "16,x"], 2, "--spp"),
    "bench render": (lambda t: ["bench", "render", str(t / "none.yaml")], 2, "does not exist"),
    "bench turning": (lambda t: ["bench", "turning", "--speed-deg-s", "25"], 2,
                      "--speed-deg-s"),
    "schema": (lambda t: ["schema", "table"], 2, "No such command"),
    "record": (lambda t: ["record", "--out", str(t / "r.txt"), "--simulated"], 2,
               "an .h5 file"),
    "replay": (lambda t: ["replay", str(t / "none.h5"), "--out", str(t / "o")], 2,
               "does not exist"),
    "export calibration": (lambda t: ["export", "calibration", str(t / "none.yaml"), "--to",
                                      "ros", "--out", str(t / "c.yaml")], 2, "does not exist"),
    "export mitsuba": (lambda t: ["export", "mitsuba", str(t / "none.yaml"), "--out",
                                  str(t / "m")], 2, "does not exist"),
    "export frame": (lambda t: ["export", "frame", str(t / "none"), "--to", "hdf5", "--out",
                                str(t / "f.h5")], 2, "is not a frame folder"),
}


@pytest.mark.parametrize("name", sorted(ERROR_CALLS))
def test_errors_go_to_stderr_and_nothing_to_stdout(name, tmp_path, monkeypatch):
    monkeypatch.delenv("TOFTWIN_TOKEN", raising=False)
    args, code, says = ERROR_CALLS[name]
    res = runner.invoke(app, args(tmp_path))
    assert res.exit_code == code, (res.stdout, res.stderr)
    assert res.stdout == "", res.stdout
    assert says in _flat(res.stderr), res.stderr


def test_every_command_has_an_error_call():
    schemas = {f"schema {n}" for n in SCHEMAS}  # --out alone: no input to refuse
    names = {" ".join(p) for p, _ in COMMANDS} - {"devices list", "devices check",
                                                   "bench ground-test", "bench campaign"}
    covered = {n.split(" --")[0] for n in ERROR_CALLS} | schemas
    assert names <= covered, names - covered
