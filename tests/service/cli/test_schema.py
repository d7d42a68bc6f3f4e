"""``toftwin schema scene``: the committed schema is current and the bundled examples pass it."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import yaml
from typer.testing import CliRunner

from service.cli import app
from service.cli.schema import SCENE_SCHEMA_FILE, scene_schema, schema_text

ROOT = Path(__file__).resolve().parents[3]
COMMITTED = ROOT / SCENE_SCHEMA_FILE
EXAMPLES = sorted((ROOT / "examples").glob("*.yaml"))
REGENERATE = f"toftwin schema scene --out {SCENE_SCHEMA_FILE}"
runner = CliRunner()


def test_schema_scene_prints_the_schema():
    res = runner.invoke(app, ["schema", "scene"])
    assert res.exit_code == 0, res.output
    printed = json.loads(res.stdout)
    assert printed == scene_schema()
    jsonschema.Draft202012Validator.check_schema(printed)


def test_schema_scene_writes_the_file(tmp_path):
    out = tmp_path / "sub" / "scene.schema.json"
    res = runner.invoke(app, ["schema", "scene", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert out.read_text(encoding="utf-8") == schema_text(scene_schema())


def test_the_committed_schema_is_current():
    assert COMMITTED.is_file(), f"{SCENE_SCHEMA_FILE} is missing; make it with `{REGENERATE}`"
    committed = COMMITTED.read_text(encoding="utf-8")
    assert committed == schema_text(scene_schema()), (
        f"{SCENE_SCHEMA_FILE} differs from the scene models (sim_core/scene_spec.py); "
        f"regenerate it with `{REGENERATE}` and commit it")


@pytest.fixture(scope="module")
def validator() -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(json.loads(COMMITTED.read_text(encoding="utf-8")))


def test_there_are_examples():
    assert len(EXAMPLES) >= 3


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_every_example_validates_against_the_schema(validator, path):
    scene = yaml.safe_load(path.read_text(encoding="utf-8"))
    errors = [f"{'.'.join(map(str, e.absolute_path))}: {e.message}"
              for e in validator.iter_errors(scene)]
    assert not errors, f"{path.name}: {errors}"


def test_the_schema_rejects_what_the_loader_rejects(validator):
    scene = yaml.safe_load(EXAMPLES[0].read_text(encoding="utf-8"))
    assert validator.is_valid(scene)
    assert not validator.is_valid({**scene, "colour": "red"})  # unknown field
    assert not validator.is_valid({**scene, "render": {"spp": 0}})  # below the range
    assert not validator.is_valid({k: v for k, v in scene.items() if k != "camera"})
