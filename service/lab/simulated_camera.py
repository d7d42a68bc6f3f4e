"""The simulated camera's frame source: the renderer, for the state the simulated rig is in.

The simulated pico flexx (``drivers.sim.usb_camera``) asks a frame source for every frame it
streams. This one renders the scene for the rig's current turntable angle, solar level and
shutter, through the full imaging chain, with the camera simulator's own noise seed, and with
small, configurable differences from the nominal scene (object pose offset, turntable offset,
material reflectance scale) so that comparing a "measured" frame with a simulation of the
nominal scene is never trivially perfect.
"""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.rig import RigState
from drivers.sim.usb_camera import CameraRequest
from sim_core.pipeline import simulate
from sim_core.raw import RawFrame
from sim_core.render import RenderSettings
from sim_core.scene import Scene, build_scene
from sim_core.scene_spec import SceneSpec

#: material parameters that scale reflectance (scaled by ``reflectance_scale``)
_REFLECTANCE_FIELDS = ("albedo", "kd", "ks", "w")


@dataclass(frozen=True)
class TwinDifferences:
    """How the simulated "real" rig differs from the nominal scene.

    Attributes
    ----------
    pose_offset_m : (3,) float
        Translation of every object (as an error of the camera's extrinsic calibration) [m].
    turntable_offset_deg : float
        Error of the turntable's zero [deg].
    reflectance_scale : float
        Factor on every material's reflectance parameters (clipped to their allowed range).
    """

    pose_offset_m: tuple[float, float, float] = (0.004, -0.003, 0.002)
    turntable_offset_deg: float = 0.5
    reflectance_scale: float = 0.92


def perturb_scene(scene: Scene, diff: TwinDifferences) -> Scene:
    """Apply :class:`TwinDifferences` (pose offset, material scale) to a posed scene."""
    materials = []
    for m in scene.materials:
        changes = {}
        for f in _REFLECTANCE_FIELDS:
            if hasattr(m, f):
                changes[f] = float(np.clip(getattr(m, f) * diff.reflectance_scale, 0.0, 1.0))
        materials.append(dataclasses.replace(m, **changes) if changes else m)
    return dataclasses.replace(
        scene,
        triangles_m=scene.triangles_m + np.asarray(diff.pose_offset_m, dtype=np.float64),
        materials=tuple(materials),
    )


class RenderedFrameSource:
    """``CameraRequest -> RawFrame`` by rendering the rig's current state.

    Parameters
    ----------
    spec : SceneSpec
        The nominal scene.
    base_dir : path
        Folder relative mesh paths resolve against.
    settings : RenderSettings
        Render settings of the simulated camera (few spp keep it fast).
    differences : TwinDifferences
    """

    def __init__(
        self,
        spec: SceneSpec,
        base_dir: str | Path,
        settings: RenderSettings | None = None,
        differences: TwinDifferences | None = None,
    ) -> None:
        self.spec = spec
        self.base_dir = Path(base_dir)
        self.settings = settings or RenderSettings(integrator="path", spp=8, max_bounces=2)
        self.differences = differences or TwinDifferences()
        self._lock = threading.Lock()

    def __call__(self, request: CameraRequest) -> RawFrame:
        state = request.rig_state
        if not isinstance(state, RigState):  # a camera simulator without a rig: nominal state
            angle = self.spec.turntable.angle_deg if self.spec.turntable else 0.0
            sim = self.spec.ambient.solar_simulator
            state = RigState(turntable_angle_deg=angle,
                             solar_suns=sim.irradiance_suns if sim else 0.0,
                             shutter_open=sim is not None)
        uc = request.use_case
        spec = self.spec.model_copy(update={"camera": self.spec.camera.model_copy(update={
            "modulation_frequencies_hz": list(uc.frequencies_hz),
            "exposure_s": uc.exposure_s,
            "width_px": uc.shape[1],
            "height_px": uc.shape[0],
        })})
        suns = state.solar_suns if state.shutter_open else 0.0
        angle = state.turntable_angle_deg + self.differences.turntable_offset_deg
        scene = build_scene(spec, self.base_dir, turntable_deg=angle,
                            solar_suns=suns if suns > 0.0 else 0.0)
        scene = perturb_scene(scene, self.differences)
        settings = dataclasses.replace(self.settings, seed=request.seed * 1_000_003
                                       + request.frame_index)
        with self._lock:  # one render at a time; the camera thread and tests may both ask
            frame = simulate(scene, settings, noise_rng=request.rng())
        raw = frame.raw
        meta = {**raw.meta, "source": "rendered", "frame_index": request.frame_index,
                "rig": dataclasses.asdict(state), "differences":
                dataclasses.asdict(self.differences)}
        return dataclasses.replace(raw, timestamp_s=request.timestamp_s, meta=meta)
