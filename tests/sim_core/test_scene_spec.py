"""The scene format's documentation and its JSON Schema follow the pydantic models."""

from __future__ import annotations

import re
import typing
from pathlib import Path

from pydantic import BaseModel

from sim_core.scene_spec import SceneSpec

ROOT = Path(__file__).resolve().parents[2]
SCENE_DOC = ROOT / "docs" / "scene-format.md"


def _models(annotation) -> list[type[BaseModel]]:
    """The pydantic models inside a field's annotation (through unions, lists, Annotated)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in _models(arg)]


def model_fields_recursive(model: type[BaseModel], path: str = "") -> dict[str, str]:
    """Every field name of ``model`` and of the models nested in it -> one dotted path to it."""
    out: dict[str, str] = {}
    for name, info in model.model_fields.items():
        out.setdefault(name, f"{path}{name}")
        for sub in _models(info.annotation):
            for k, v in model_fields_recursive(sub, f"{path}{name}.").items():
                out.setdefault(k, v)
    return out


def code_words(markdown: str) -> set[str]:
    """Every identifier-like word inside a `code span` of ``markdown`` (not in code blocks)."""
    text = re.sub(r"^```.*?^```", "", markdown, flags=re.M | re.S)
    return {w for span in re.findall(r"`([^`\n]+)`", text) for w in re.findall(r"\w+", span)}


def test_the_field_walk_reaches_nested_models():
    fields = model_fields_recursive(SceneSpec)
    assert fields["world_from_camera"] == "camera.pose.world_from_camera"
    assert fields["sbi_enabled"] == "camera.sensor.sbi_enabled"
    assert fields["subdivisions"] == "objects.mesh.subdivisions"
    assert fields["length_px"] == "optics.motion.length_px"


def test_every_scene_field_is_documented():
    documented = code_words(SCENE_DOC.read_text(encoding="utf-8"))
    missing = {p for name, p in model_fields_recursive(SceneSpec).items()
               if name not in documented}
    assert not missing, (
        f"fields of SceneSpec (sim_core/scene_spec.py) not in {SCENE_DOC.name}: "
        f"{sorted(missing)}; document each (meaning, unit, range) as `field`")
