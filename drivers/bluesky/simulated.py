"""The rig's Bluesky devices on the device simulators: the simulated backend.

:func:`simulated_devices` starts the simulated rig (:func:`drivers.sim.rig.simulated_rig`: the
SMC100 and Oriel simulators on pseudo-terminals, the camera simulator behind pyusb, our real
drivers talking their bytes to them) and returns its devices (:func:`drivers.bluesky.
rig_devices.rig_devices`): the same device classes as on the real rig, over the same drivers;
only the far end of the wire differs. With a scene, the simulated camera's frames are the
scene rendered by our path tracer for the simulators' turntable angle, level and shutter
(:class:`drivers.sim.world.SimulatedWorld`, at few samples per pixel: fast, noisy), and
reconstructed with the scene's camera; without one, the camera simulator's own plane at 1 m.
"""

from __future__ import annotations

from pathlib import Path

from ophyd_async.core import PathProvider

from drivers.bluesky.camera import CameraModel, OnFrame
from drivers.bluesky.rig_devices import RigDevices, rig_devices
from drivers.camera import UseCase
from drivers.sim.rig import simulated_rig
from sim_core.camera import Camera
from sim_core.scene_spec import SceneSpec

__all__ = ["DEFAULT_SPP", "simulated_devices"]

#: samples per pixel of the simulated camera's renders unless told otherwise (the satellite
#: ground test: about 0.1 s a frame at 2 or 4 on two cores, once the renderer is compiled)
DEFAULT_SPP = 2
#: bounces of the simulated camera's path tracer (the service's simulated camera's)
MAX_BOUNCES = 2


def scene_camera(spec: SceneSpec) -> CameraModel:
    """The scene's camera model at a use case's frequencies, exposure and image size (as the
    service reconstructs a measured frame of that scene)."""
    from sim_core.scene import build_camera

    def model(use_case: UseCase) -> Camera:
        camera = spec.camera.model_copy(update={
            "modulation_frequencies_hz": list(use_case.frequencies_hz),
            "exposure_s": use_case.exposure_s,
            "width_px": use_case.shape[1], "height_px": use_case.shape[0]})
        return build_camera(spec.model_copy(update={"camera": camera}))

    return model


def simulated_devices(path_provider: PathProvider, *, scene: str | Path | None = None,
                      spp: int = DEFAULT_SPP, integrator: str = "path", seed: int = 0,
                      on_frame: OnFrame | None = None) -> RigDevices:
    """The turntable, solar level and camera devices of a freshly started simulated rig.

    Parameters
    ----------
    path_provider : PathProvider
        Where the camera writes each run's frames.
    scene : path or None
        A scene file (``examples/satellite_ground_test.yaml``) the simulated camera renders;
        None: the camera simulator's plane at 1 m (no rendering).
    spp, integrator : int, str
        The simulated camera's samples per pixel and integrator (``"path"`` or ``"direct"``).
    seed : int
        The camera simulator's noise seed.
    on_frame : callable or None
        Handed every frame written (:class:`~drivers.bluesky.camera.ToFCamera`).

    Close the result (or use it as a context manager) to stop the simulators.
    """
    if scene is None:
        return rig_devices(simulated_rig(seed=seed), path_provider, on_frame=on_frame)
    from drivers.sim.world import SimulatedWorld
    from sim_core.render import RenderSettings
    from sim_core.render_request import RenderRequest
    from sim_core.scene_spec import load_scene_spec

    path = Path(scene)
    spec = load_scene_spec(path)
    world = SimulatedWorld(spec, path.parent, RenderRequest(
        RenderSettings(integrator=integrator, spp=spp, max_bounces=MAX_BOUNCES), effects="all"))
    rig = simulated_rig(world, seed=seed, lab_wait=world.clock.wait)
    return rig_devices(rig, path_provider, camera_model=scene_camera(spec), on_frame=on_frame)
