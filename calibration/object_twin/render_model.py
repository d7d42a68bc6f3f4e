"""The twin's prediction of the measured views for a candidate object twin (our own renderer).

For a candidate mount offset and reflectance scales (an :class:`~sim_core.twin_file.
ObjectTwinParameters`), the calibration is combined with it
(:func:`sim_core.twin_file.with_object_twin`, the same path a scene's ``object_twin: FILE``
takes) and every captured view is rendered at the angle the rig reported, with the solar
simulator's shutter closed, and exposed noise-free (the sensor's mean response, as
:mod:`calibration.twin_prediction` does): the camera's depth errors, optics and sensor included,
so the prediction is compared with the averaged capture as measured.

The comparison quantity is the mean correlation phasor of the first modulation frequency,
``z = a exp(-1j phi)`` with the amplitude ``a`` [DN] and phase ``phi`` (seed eqs. 4-5): it
carries range and amplitude together, and at a silhouette it mixes the object and the background
as the pixel does. Renders use a fixed seed, so that predictions of nearby candidates differ by
the candidates, not by Monte Carlo noise (common random numbers for finite differences).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calibration.captures import AveragedCapture
from calibration.object_twin.views import capture_spec
from sim_core.pipeline import expose_light, render_light
from sim_core.render import RenderSettings
from sim_core.scene import build_scene
from sim_core.scene_spec import SceneSpec
from sim_core.twin_file import ObjectTwinParameters, TwinParameters, with_object_twin

#: how the fit renders: path tracing with one bounce between surfaces where the effect plan asks
#: for multipath (it decides per scene), 32 samples per pixel, a fixed seed
FIT_RENDER = RenderSettings(integrator="path", spp=32, max_bounces=2, seed=14)


def measured_phasor(capture: AveragedCapture) -> np.ndarray:
    """The averaged capture's phasor ``a exp(-1j phi)`` at its first frequency, (H, W)."""
    return capture.amplitude * np.exp(-1j * capture.phase_rad[0])


@dataclass(frozen=True)
class PredictedView:
    """The twin's noise-free prediction of one captured view.

    Attributes
    ----------
    phasor : (H, W) complex128
        ``a exp(-1j phi)`` at the first frequency [DN].
    object_id : (H, W) int
        Index into the scene's objects of what each pixel centre sees (-1: nothing).
    saturated : (H, W) bool
        Pixels the sensor model saturates (or holds at its SBI limit).
    multipath : bool
        Whether the effect plan rendered interreflections.
    """

    phasor: np.ndarray = field(repr=False)
    object_id: np.ndarray = field(repr=False)
    saturated: np.ndarray = field(repr=False)
    multipath: bool = False


@dataclass
class TwinRenderer:
    """Renders the captured views for candidate object twins.

    Parameters
    ----------
    spec, base_dir
        The nominal scene and its folder.
    calibration : TwinParameters or None
        The rig's calibration (camera, rig); never the object keys being fitted.
    captures : list of AveragedCapture
    settings : RenderSettings
    """

    spec: SceneSpec
    base_dir: Path
    calibration: TwinParameters | None
    captures: list[AveragedCapture]
    settings: RenderSettings = FIT_RENDER
    renders: int = 0

    def predict(self, object_twin: ObjectTwinParameters) -> list[PredictedView]:
        """The prediction of every captured view under ``object_twin``."""
        twin = with_object_twin(self.calibration or TwinParameters(), object_twin)
        out = []
        for cap in self.captures:
            spec = capture_spec(self.spec, cap)
            spec = spec.model_copy(update={"calibration": None, "object_twin": None})
            scene = build_scene(spec, self.base_dir, turntable_deg=cap.turntable_angle_deg,
                                solar_suns=0.0, twin=twin)
            rendered = render_light(scene, dataclasses.replace(self.settings))
            frame = expose_light(scene, rendered, noise=False)
            img = frame.image
            raw = frame.raw
            out.append(PredictedView(
                phasor=img.amplitude * np.exp(-1j * img.phase_rad[0]),
                object_id=rendered.light_field.object_id,
                saturated=raw.saturated | raw.sbi_limit,
                multipath=rendered.plan.enabled("multipath")))
            self.renders += 1
        return out
