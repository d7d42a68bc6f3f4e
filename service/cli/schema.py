"""``toftwin schema``: the JSON Schemas of the files a user writes or reads, for editors and
other tools.

``toftwin schema scene`` (:class:`sim_core.scene_spec.SceneSpec`), ``calibration``
(:class:`sim_core.twin_file.CalibrationFile`), ``reality`` (:class:`~sim_core.twin_file.
RealityFile`, the simulated lab's hidden truth) and ``object`` (:class:`~sim_core.twin_file.
ObjectTwinFile`, ``toftwin fit-object``'s ``object.yaml``), ``material`` (:class:`sim_core.
materials.material_file.MaterialFile`, ``toftwin calibrate brdf``'s output) and ``frame``
(:class:`sim_core.frame_meta.FrameJson`, a frame folder's ``frame.json``): each generated from
the pydantic models that state the file. The copies in ``docs/`` (:data:`SCHEMAS`) are
regenerated with ``toftwin schema NAME --out docs/NAME.schema.json`` (a test fails when one is
stale). What a
schema cannot say (finite numbers only, unique object names, one of ``preset``/``kind``, ranges
of material parameters, a lens that fits its image) is still checked when the file is loaded.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from service.cli.common import command_group, err_console

#: the JSON Schema dialect pydantic generates
DIALECT = "https://json-schema.org/draft/2020-12/schema"
SCENE_SCHEMA_ID = "urn:toftwin:schema:scene"
SCENE_SCHEMA_FILE = "docs/scene.schema.json"

schema_app = command_group("JSON Schemas of the file formats.")


#: the other files' schemas: name -> (model's import path, title, the doc that describes it)
MODEL_SCHEMAS: dict[str, tuple[str, str, str]] = {
    "calibration": ("sim_core.twin_file:CalibrationFile", "toftwin calibration",
                    "docs/calibration.md"),
    "reality": ("sim_core.twin_file:RealityFile", "toftwin reality (the simulated lab's truth)",
                "docs/calibration.md"),
    "object": ("sim_core.twin_file:ObjectTwinFile", "toftwin object twin",
               "docs/calibration.md"),
    "material": ("sim_core.materials.material_file:MaterialFile",
                 "toftwin material (a BRDF fit's output)", "docs/brdf-fitting.md"),
    "frame": ("sim_core.frame_meta:FrameJson", "toftwin frame.json (a frame folder's metadata)",
              "docs/frame-format.md"),
}
#: every schema and its committed copy
SCHEMAS = {"scene": SCENE_SCHEMA_FILE} | {n: f"docs/{n}.schema.json" for n in MODEL_SCHEMAS}


def scene_schema() -> dict[str, Any]:
    """The JSON Schema of a scene file (YAML or JSON), with ``$schema``, ``$id`` and a title.

    >>> s = scene_schema()
    >>> s["$schema"], s["$id"], s["required"], s["additionalProperties"]
    ('https://json-schema.org/draft/2020-12/schema', 'urn:toftwin:schema:scene', ['camera'], False)
    >>> s["$defs"]["RenderSpec"]["properties"]["spp"]["minimum"]
    1
    """
    from sim_core.scene_spec import SceneSpec

    body = _without_redundant_enums(SceneSpec.model_json_schema())
    return {
        "$schema": DIALECT,
        "$id": SCENE_SCHEMA_ID,
        **body,
        "title": "toftwin scene",
        "description": "A toftwin scene file (docs/scene-format.md); "
        f"regenerate with `toftwin schema scene --out {SCENE_SCHEMA_FILE}`.",
    }


def model_schema(name: str) -> dict[str, Any]:
    """The JSON Schema of the file ``name`` of :data:`MODEL_SCHEMAS`, with ``$schema``, ``$id``
    (``urn:toftwin:schema:NAME``) and a title.

    >>> s = model_schema("calibration")
    >>> s["$id"], s["additionalProperties"], sorted(s["properties"])[:2]
    ('urn:toftwin:schema:calibration', False, ['camera', 'illumination'])
    """
    import importlib

    target, title, doc = MODEL_SCHEMAS[name]
    module, cls = target.split(":")
    model = getattr(importlib.import_module(module), cls)
    body = _without_redundant_enums(model.model_json_schema())
    return {
        "$schema": DIALECT,
        "$id": f"urn:toftwin:schema:{name}",
        **body,
        "title": title,
        "description": f"A {title} file ({doc}); regenerate with `toftwin schema {name} --out "
        f"{SCHEMAS[name]}`.",
    }


def schema_of(name: str) -> dict[str, Any]:
    """The schema ``name`` of :data:`SCHEMAS`."""
    return scene_schema() if name == "scene" else model_schema(name)


#: schema keywords whose value maps names to schemas (the names are data, not keywords)
_NAMED_SCHEMAS = ("properties", "$defs", "definitions", "patternProperties", "dependentSchemas")
#: schema keywords whose value is instance data, never a schema
_DATA = ("default", "const", "enum", "examples")


def _without_redundant_enums(schema: Any) -> Any:
    """The schema as every supported pydantic writes it (the floor, 2.9, and later releases),
    so the committed file does not depend on the version that generated it; only keywords are
    touched (never a property's name, never a default's or a constant's value):

    - ``enum: [x]`` beside ``const: x`` goes: pydantic before 2.10 writes both for a one-value
      ``Literal``, later releases only ``const``;
    - ``additionalProperties: true`` goes: later releases write it for a ``dict[str, Any]``'s
      values, 2.9 leaves it out, and it is JSON Schema's default;
    - ``propertyNames`` goes: later releases write a mapping's key constraints (an object
      name's 1-100 characters), 2.9 does not; the loader still checks them.

    >>> _without_redundant_enums({"properties": {"propertyNames": {"const": 1, "enum": [1]}},
    ...                           "propertyNames": {"maxLength": 3}, "default": {"enum": [2]}})
    {'properties': {'propertyNames': {'const': 1}}, 'default': {'enum': [2]}}
    """
    if isinstance(schema, list):
        return [_without_redundant_enums(v) for v in schema]
    if not isinstance(schema, dict):
        return schema
    out: dict[str, Any] = {}
    for key, value in schema.items():
        if key == "propertyNames":
            continue
        if key in _DATA:
            out[key] = value
        elif key in _NAMED_SCHEMAS and isinstance(value, dict):
            out[key] = {name: _without_redundant_enums(v) for name, v in value.items()}
        else:
            out[key] = _without_redundant_enums(value)
    if "const" in out and out.get("enum") == [out["const"]]:
        del out["enum"]
    if out.get("additionalProperties") is True:
        del out["additionalProperties"]
    return out


def schema_text(schema: dict[str, Any]) -> str:
    """The schema as the file holds it: indented JSON with a final newline."""
    return json.dumps(schema, indent=2, ensure_ascii=False) + "\n"


def _write(text: str, out: Path | None) -> None:
    if out is None:
        sys.stdout.write(text)
        return
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    err_console.print(f"wrote {out}")


OutOption = Annotated[
    Path | None, typer.Option("--out", help="File to write (default: print to stdout).")]


@schema_app.command("scene")
def scene(out: OutOption = None) -> None:
    """The JSON Schema of scene files; point an editor's YAML support at it."""
    _write(schema_text(scene_schema()), out)


@schema_app.command("calibration")
def calibration(out: OutOption = None) -> None:
    """The JSON Schema of calibration files (calibration.yaml)."""
    _write(schema_text(model_schema("calibration")), out)


@schema_app.command("reality")
def reality(out: OutOption = None) -> None:
    """The JSON Schema of reality files (the simulated lab's hidden truth, --reality FILE)."""
    _write(schema_text(model_schema("reality")), out)


@schema_app.command("object")
def object_twin(out: OutOption = None) -> None:
    """The JSON Schema of object twin files (fit-object's object.yaml)."""
    _write(schema_text(model_schema("object")), out)


@schema_app.command("material")
def material(out: OutOption = None) -> None:
    """The JSON Schema of material files (calibrate brdf's fit.yaml, a scene's material file)."""
    _write(schema_text(model_schema("material")), out)


@schema_app.command("frame")
def frame(out: OutOption = None) -> None:
    """The JSON Schema of a frame folder's frame.json."""
    _write(schema_text(model_schema("frame")), out)
