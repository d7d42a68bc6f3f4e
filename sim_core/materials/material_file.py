"""Material files: a material (``kind`` and ``params``) in a YAML file of its own.

A scene's ``material: {file: fit.yaml}`` references such a file, e.g. one written by
``toftwin calibrate brdf --out fit.yaml``::

    kind: cook-torrance
    params: {kd: 0.78, ks: 0.20, m: 0.08, n2: 1.67, fresnel_angle: incidence}
    fit: {e_fit: 0.0026, ...}        # the fit report: ignored here

Only ``kind`` and ``params`` are read; ``fit`` (the report of the fit that made the file) is
ignored, and any other top-level key is an error (a typo would otherwise go unnoticed).
"""

from __future__ import annotations

import math
import numbers
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from sim_core.errors import InvalidInputError
from sim_core.files import StructuredFileError, load_structured
from sim_core.materials.presets import MATERIAL_KINDS

_KINDS = tuple(MATERIAL_KINDS)

__all__ = ["MATERIAL_FILE_KEYS", "MaterialFile", "read_material_file"]

#: the top-level keys a material file may have
MATERIAL_FILE_KEYS = ("kind", "params", "fit")


class MaterialFile(BaseModel):
    """A material file as its JSON Schema states it (``toftwin schema material``): what
    :func:`read_material_file` accepts, with ``kind`` one of the material kinds
    (:data:`sim_core.materials.presets.MATERIAL_KINDS`; the scene checks it, and each
    parameter's range, when it makes the material)."""

    model_config = ConfigDict(extra="forbid")

    kind: Literal[tuple(_KINDS)] = Field(  # type: ignore[valid-type]
        description="The material model (docs/scene-format.md, Materials).")
    params: dict[str, Annotated[float, Field(allow_inf_nan=False)] | str] = Field(
        default_factory=dict, description="The model's parameters: finite numbers or names.")
    fit: dict[str, Any] | None = Field(
        None, description="The report of the fit that made the file (ignored when read).")


def read_material_file(path: str | Path) -> tuple[str, dict[str, Any]]:
    """``(kind, params)`` of the material file ``path``.

    Raises
    ------
    InvalidInputError
        With field ``"file"`` and a message naming the path and what is wrong: the file is
        missing or no YAML mapping, ``kind`` is missing or no string, ``params`` is no mapping
        of names to finite numbers or strings, or an unknown top-level key.
    """
    p = Path(path)
    if not p.is_file():
        raise InvalidInputError("file", f"material file '{p}' does not exist")
    try:
        data = load_structured(p, json_only=False)
    except StructuredFileError as exc:
        raise InvalidInputError("file", f"material file {exc}") from None
    if not isinstance(data, dict):
        raise InvalidInputError("file", f"material file '{p}' holds no mapping with "
                                        f"'kind' and 'params'")
    unknown = sorted(str(k) for k in data if k not in MATERIAL_FILE_KEYS)
    if unknown:
        raise InvalidInputError("file", f"material file '{p}' has unknown key(s) "
                                        f"{', '.join(unknown)}; allowed: "
                                        f"{', '.join(MATERIAL_FILE_KEYS)}")
    kind = data.get("kind")
    if not isinstance(kind, str):
        raise InvalidInputError("file", f"material file '{p}': 'kind' must be a material kind "
                                        f"name, got {kind!r}")
    params = data.get("params", {})
    if not isinstance(params, dict):
        raise InvalidInputError("file", f"material file '{p}': 'params' must be a mapping")
    for name, value in params.items():
        ok = isinstance(value, str) or (isinstance(value, numbers.Real)
                                        and not isinstance(value, bool)
                                        and math.isfinite(float(value)))
        if not ok:
            raise InvalidInputError("file", f"material file '{p}': params.{name} = {value!r} "
                                            f"is not a finite number or a name")
    return kind, {str(k): v for k, v in params.items()}
