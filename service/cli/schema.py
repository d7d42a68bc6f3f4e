"""``toftwin schema``: the JSON Schema of the scene format, for editors and other tools.

The schema is generated from the pydantic models (:class:`sim_core.scene_spec.SceneSpec`); the
copy in ``docs/scene.schema.json`` is regenerated with ``toftwin schema scene --out
docs/scene.schema.json`` (a test fails when it is stale). What the schema cannot say (finite
numbers only, unique object names, one of ``preset``/``kind``, ranges of material parameters) is
still checked when a scene is loaded.
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


def _without_redundant_enums(node: Any) -> Any:
    """Drop ``enum: [x]`` beside ``const: x``: pydantic before 2.10 writes both for a one-value
    ``Literal``, later releases only ``const``; without this the file would depend on the
    pydantic version that generated it."""
    if isinstance(node, list):
        return [_without_redundant_enums(v) for v in node]
    if not isinstance(node, dict):
        return node
    out = {k: _without_redundant_enums(v) for k, v in node.items()}
    if "const" in out and out.get("enum") == [out["const"]]:
        del out["enum"]
    return out


def schema_text(schema: dict[str, Any]) -> str:
    """The schema as the file holds it: indented JSON with a final newline."""
    return json.dumps(schema, indent=2, ensure_ascii=False) + "\n"


@schema_app.command("scene")
def scene(
    out: Annotated[
        Path | None, typer.Option("--out", help="File to write (default: print to stdout).")
    ] = None,
) -> None:
    """The JSON Schema of scene files; point an editor's YAML support at it."""
    text = schema_text(scene_schema())
    if out is None:
        sys.stdout.write(text)
        return
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    err_console.print(f"wrote {out}")
