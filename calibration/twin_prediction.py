"""What the twin predicts for a calibration view: noise-free frames at the calibrated geometry.

Photometry and the solar scale compare averaged frames with the twin's prediction of the same
view, made with everything calibrated so far (intrinsics, distortion, gain, turntable axis and
zero) and the board in its fixture. The prediction is the sensor's mean response: no shot or
read noise, no quantisation (:func:`sim_core.pipeline.expose_light` with ``noise=False``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

import numpy as np

from sim_core.optics import StrayLight
from sim_core.pipeline import (
    RenderedLight,
    SimulatedFrame,
    expose_light,
    mean_intensities,
    render_light,
)
from sim_core.plan import Effect
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import Scene, build_scene
from sim_core.scene_spec import ObjectSpec, SceneSpec
from sim_core.twin_file import TwinParameters

#: samples per pixel of a prediction (direct light only: the board is flat and matte)
PREDICTION_SPP = 64


class CameraUseCase(Protocol):
    """What a calibration needs of the camera's use case (the frames' modulation and size)."""

    @property
    def frequencies_hz(self) -> Sequence[float]: ...
    @property
    def exposure_s(self) -> float: ...
    @property
    def shape(self) -> tuple[int, int]: ...


def mounted_spec(spec: SceneSpec, objects: list[ObjectSpec],
                 use_case: CameraUseCase) -> SceneSpec:
    """``spec`` with ``objects`` on the turntable instead of its own, for ``use_case``'s frames."""
    fixed = [o for o in spec.objects if not o.on_turntable]
    camera = spec.camera.model_copy(update={
        "modulation_frequencies_hz": [float(f) for f in use_case.frequencies_hz],
        "exposure_s": use_case.exposure_s,
        "width_px": use_case.shape[1],
        "height_px": use_case.shape[0],
    })
    return spec.model_copy(update={"objects": fixed + list(objects), "camera": camera})


@dataclasses.dataclass
class Prediction:
    """A rendered view of the twin, ready to be exposed at any solar level."""

    scene: Scene
    rendered: RenderedLight

    def frame(self, ambient_scale: float = 1.0) -> SimulatedFrame:
        """The noise-free frame, with the ambient light scaled by ``ambient_scale``."""
        rendered = self.rendered
        if ambient_scale != 1.0:
            lf = dataclasses.replace(rendered.light_field,
                                     dc_ambient=rendered.light_field.dc_ambient * ambient_scale)
            rendered = dataclasses.replace(rendered, light_field=lf)
        return expose_light(self.scene, rendered, noise=False)

    def intensities(self, ambient_scales: Sequence[float],
                    active_scale: float = 1.0) -> list[np.ndarray]:
        """The noise-free frames' intensity [DN] at each ambient scale, the camera's own light
        scaled by ``active_scale`` (:func:`sim_core.pipeline.mean_intensities`:
        ``frame(k).raw.intensity`` for each ``k``, the optics applied once)."""
        return mean_intensities(self.scene, self.rendered, ambient_scales, active_scale)

    def with_stray_light(self, stray: StrayLight | None) -> Prediction:
        """The same rendered light seen through optics with ``stray`` (None: none): the stray
        light acts after the render (:func:`sim_core.pipeline.expose_light`), so a fit of its
        fraction and radius re-exposes one render instead of rendering again."""
        effects = tuple(e for e in self.rendered.plan.effects if e.name != "stray_light")
        effects += (Effect("stray_light", stray is not None,
                           "the calibration's stray-light fit" if stray is not None
                           else "no stray light"),)
        plan = dataclasses.replace(self.rendered.plan, effects=effects)
        return Prediction(dataclasses.replace(self.scene, stray_light=stray),
                          dataclasses.replace(self.rendered, plan=plan))


def predict_view(
    spec: SceneSpec,
    base_dir: str | Path,
    twin: TwinParameters,
    turntable_deg: float,
    solar_suns: float = 0.0,
    spp: int = PREDICTION_SPP,
    seed: int = 0,
) -> Prediction:
    """Render the view the rig reported (``turntable_deg``, ``solar_suns`` as set) in the twin."""
    scene = build_scene(spec, base_dir, turntable_deg=turntable_deg, solar_suns=solar_suns,
                        twin=twin)
    settings = RenderSettings(integrator="direct", spp=spp, seed=seed)
    return Prediction(scene, render_light(scene, RenderRequest(settings, effects="auto")))
