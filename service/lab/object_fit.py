"""A campaign's object fit: capture its first poses, fit the object twin, store it.

A campaign created with ``object_fit`` runs this stage before its poses (and again on a resume
until it has succeeded): at its first ``poses`` distinct turntable angles it captures ``frames``
frames each, averaged (:func:`calibration.captures.average_frames`), and fits what stands on the
turntable (:func:`calibration.object_twin.fit_object`: the mount's pose offset and each object's
reflectance, with the campaign's pinned calibration). The object twin, its hash and the fit's
report are stored with the campaign in one transaction; every pose then also simulates the
fitted twin (:func:`fitted_twin`), and captures a second frame for the noise ceiling
(:mod:`service.lab.poses`).

The fit renders in this process, under :data:`service.compute.jobs.RENDER_LOCK`, after the
captures (the rig is released while it computes).
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from calibration.captures import AveragedCapture, average_frames
from calibration.object_twin.fit import fit_object
from drivers.rig import Rig, RigState
from service.compute.jobs import RENDER_LOCK
from service.lab.calibration import Twin
from service.lab.requests import ObjectFitIn
from service.lab.scenes import SceneSource, for_use_case
from service.lab.settling import settled_moves
from sim_core.twin_file import ObjectTwinFile, TwinParameters, parse_object_twin, with_object_twin


@dataclass(frozen=True)
class FitPose:
    """A rig state the fit captures."""

    turntable_deg: float
    solar_suns: float


def fit_poses(poses: Sequence[Any], n: int) -> list[FitPose]:
    """The first ``n`` distinct turntable angles of a campaign's planned poses, in order (with
    the solar level of the first pose at each angle).

    >>> from types import SimpleNamespace as P
    >>> fit_poses([P(turntable_deg=0, solar_suns=1), P(turntable_deg=0, solar_suns=0.5),
    ...            P(turntable_deg=30, solar_suns=1)], 3)
    [FitPose(turntable_deg=0.0, solar_suns=1.0), FitPose(turntable_deg=30.0, solar_suns=1.0)]
    """
    out: list[FitPose] = []
    seen: set[float] = set()
    for p in poses:
        angle = round(float(p.turntable_deg), 9)
        if angle not in seen:
            seen.add(angle)
            out.append(FitPose(float(p.turntable_deg), float(p.solar_suns)))
        if len(out) == n:
            break
    return out


def capture_for_fit(
    rig: Rig, poses: Sequence[FitPose], frames: int, stop: threading.Event,
    current: Callable[[FitPose, int], None], calibration: TwinParameters | None = None,
) -> list[AveragedCapture] | None:
    """Averaged captures at ``poses``' angles, the solar simulator's shutter closed (the rig
    held per pose, every move waited out for ``calibration``'s settling:
    :func:`service.lab.settling.settled_moves`); None if ``stop`` was set.

    Device faults propagate (:class:`drivers.errors.DeviceError`): the campaign pauses.
    """
    captures = []
    for i, pose in enumerate(poses):
        if stop.is_set():
            return None
        current(pose, i)
        with rig.hold(), settled_moves(rig, calibration):
            # The fit reads the camera's own light: the solar simulator's shutter is closed.
            target = RigState(pose.turntable_deg, 0.0, shutter_open=False)
            rig.apply(target)
            captures.append(average_frames(rig.capture(frames, target=target)))
    return captures


def run_fit(
    scene: SceneSource, twin: Twin, captures: Sequence[AveragedCapture], use_case: Any
) -> tuple[ObjectTwinFile, dict[str, Any]]:
    """Fit the object twin from ``captures`` with the campaign's calibration ``twin``.

    Raises :class:`sim_core.errors.InvalidInputError` when the frames cannot determine it.
    """
    spec = for_use_case(scene.spec, use_case)
    with RENDER_LOCK:
        fit = fit_object(spec, scene.base_dir, twin.calibration, list(captures))
    return fit.object_twin, fit.report


def fitted_twin(twin: Twin, object_twin_json: str) -> Twin:
    """The campaign's calibration with its fitted object twin applied (what the fitted
    simulations apply)."""
    return Twin.of(with_object_twin(twin.calibration,
                                    parse_object_twin(json.loads(object_twin_json))))


__all__ = ["FitPose", "ObjectFitIn", "capture_for_fit", "fit_poses", "fitted_twin", "run_fit"]
