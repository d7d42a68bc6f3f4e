"""The service's active calibration: what every simulation it runs applies.

A calibration (:class:`sim_core.twin_file.CalibrationFile`) is made active by
``PUT /api/v1/calibration`` (its content, validated with the same model as a file:
an unknown key or an out-of-range value is a 422 naming the field, and nothing changes), by
activating a calibration job's result, and made inactive (nominal twin) by
``DELETE /api/v1/calibration``. Each change is a row of ``calibration_activations`` (the newest
is in force), committed in one transaction, so the active calibration survives a restart and its
history says where each came from.

Which calibration a simulation applies (:func:`effective_twin`): the active one; without one,
the scene's own ``calibration: FILE`` if it names one (bundled scenes only: inline scenes may
not name files); else none (nominal). It travels inside the simulation job, so a worker on
another machine applies the same values, and its hash (:func:`sim_core.twin_file.twin_hash`) is
recorded with the frame and the pose result. A campaign pins the calibration active when it is
created (:mod:`service.lab.campaigns`).

The simulated lab's reality is never read or returned here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from decimal import Decimal
from typing import Any

from pydantic import ValidationError
from sqlalchemy.orm import sessionmaker

from service.errors import NotFoundError
from service.lab.scenes import SceneSource
from service.store import queries
from service.store.tables import CalibrationActivationRow
from sim_core.errors import InvalidInputError
from sim_core.scene import scene_object_twin, scene_twin
from sim_core.scene_spec import scene_error_from_validation
from sim_core.twin_file import (
    CalibrationFile,
    TwinParameters,
    parse_twin,
    twin_hash,
    with_object_twin,
)


@dataclass(frozen=True)
class Twin:
    """A calibration to apply and its hash (both None: nominal)."""

    calibration: TwinParameters | None = None
    hash: str | None = None

    @classmethod
    def of(cls, calibration: TwinParameters | None) -> Twin:
        return cls(calibration, None if calibration is None else twin_hash(calibration))

    def to_json(self) -> dict[str, Any] | None:
        """The calibration as plain JSON (what a simulation job carries), or None."""
        if self.calibration is None:
            return None
        return self.calibration.model_dump(mode="json")


def parse_body(data: Any) -> CalibrationFile:
    """Validate a calibration given as parsed JSON, strictly: the model of the file format, and
    numbers must be numbers (``true`` is not 1). Raises :class:`InvalidInputError` naming the
    field as it is in the body (``camera.fx_px``)."""
    if not isinstance(data, dict):
        raise InvalidInputError("body", f"must be a JSON object, got {type(data).__name__}")
    try:
        text = json.dumps(data, allow_nan=True)
        return CalibrationFile.model_validate_json(text, strict=True)
    except ValidationError as exc:
        err = scene_error_from_validation(exc)
        field = "provenance.procedures" if err.field == "scene" else err.field
        raise InvalidInputError(
            field, err.message.replace("docs/scene-format.md", "docs/calibration.md")) from None


def calibration_from_json(text: str | None) -> TwinParameters | None:
    """A stored calibration (validated again, as a file would be), or None.

    A scene's calibration combined with its object file (``object_twin: FILE``,
    :func:`sim_core.twin_file.with_object_twin`) is stored with the object keys: it comes back
    as that combination.
    """
    return None if text is None else parse_twin(json.loads(text))


def active_twin(sessions: sessionmaker) -> Twin:
    """The active calibration (``Twin()`` when none)."""
    with sessions() as s:
        row = queries.active_calibration(s)
    if row is None or row.calibration_json is None:
        return Twin()
    return Twin(calibration_from_json(row.calibration_json), row.calibration_hash)


def effective_twin(active: Twin, scene: SceneSource) -> Twin:
    """What a simulation of ``scene`` applies: the active calibration, else the scene's own
    ``calibration: FILE``, else nothing; combined with the scene's ``object_twin: FILE`` if it
    names one (the rig's calibration and the object's are independent)."""
    if active.calibration is not None:
        obj = scene_object_twin(scene.spec, scene.base_dir)
        return active if obj is None else Twin.of(with_object_twin(active.calibration, obj))
    return Twin.of(scene_twin(scene.spec, scene.base_dir))


def activate(sessions: sessionmaker, calibration: CalibrationFile, source: str) -> dict[str, Any]:
    """Make ``calibration`` the active one; returns its public form."""
    text = json.dumps(calibration.model_dump(mode="json"), sort_keys=True, allow_nan=False)
    with sessions() as s:
        row = queries.add_activation(s, calibration_json=text,
                                     calibration_hash=twin_hash(calibration), source=source)
    return calibration_public(row)


def deactivate(sessions: sessionmaker) -> None:
    """Back to the nominal twin (404 if no calibration is active)."""
    with sessions() as s:
        row = queries.active_calibration(s)
        if row is None or row.calibration_json is None:
            raise NotFoundError("no calibration is active; the simulations apply the nominal twin")
        queries.add_activation(s, calibration_json=None, calibration_hash=None,
                               source="DELETE /api/v1/calibration")


def active_public(sessions: sessionmaker) -> dict[str, Any]:
    """``GET /calibration``: the active calibration, or 404 saying none is."""
    with sessions() as s:
        row = queries.active_calibration(s)
    if row is None or row.calibration_json is None:
        raise NotFoundError(
            "no calibration is active; the simulations apply the nominal twin. Activate one with "
            "PUT /api/v1/calibration or POST /api/v1/calibrations/{id}/activate")
    return calibration_public(row)


def calibration_public(row: CalibrationActivationRow) -> dict[str, Any]:
    cal = calibration_from_json(row.calibration_json)
    assert cal is not None
    data = cal.model_dump(mode="json")
    provenance = data.pop("provenance")
    return {"calibration_hash": row.calibration_hash, "calibration": data,
            "provenance": provenance, "source": row.source, "activated_at": row.activated_at}


def calibration_residuals(provenance: dict[str, Any]) -> list[tuple[str, str, float | str]]:
    """(procedure, name, value) of every residual a calibration's provenance records: the
    numbers of ``provenance.procedures`` whose name says RMS or residual.

    The provenance is free JSON (never applied): an integer too large for a float is given as
    text in the table's notation, not refused (issue 25: it made the page a 500).

    >>> calibration_residuals({"procedures": {"depth": {"rms_after_mm": 1.5, "n": 3}}})
    [('depth', 'rms_after_mm', 1.5)]
    >>> calibration_residuals({"procedures": {"depth": {"rms_mm": 10**400}}})
    [('depth', 'rms_mm', '1.000e+400')]
    """
    out: list[tuple[str, str, float | str]] = []
    for procedure, values in (provenance.get("procedures") or {}).items():
        if not isinstance(values, dict):
            continue
        for key, v in values.items():
            if ("rms" in key or "residual" in key) and isinstance(v, int | float) \
                    and not isinstance(v, bool):
                out.append((procedure, key, _as_number(v)))
    return out


def _as_number(v: int | float) -> float | str:
    """``v`` as a float, or an integer beyond a float's range as text (4 significant digits)."""
    try:
        return float(v)
    except OverflowError:
        return f"{Decimal(v):.4g}"
