"""From a posed scene to a frame: render, (later: optics, sensor), reconstruct, save.

Until the imaging chain lands, frames come from an ideal sensor: depth from the phase of the
rendered phasor, grey from its magnitude, no noise.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from sim_core import frame_io
from sim_core.camera import pixel_centre_grid, pixel_to_camera_direction
from sim_core.render import LightField, RenderSettings, render
from sim_core.scene import Scene
from sim_core.scene_checks import assert_camera_outside_closed_meshes
from sim_core.tof import ToFImage, reconstruct
from sim_core.tracing import RayTracer


def package_version() -> str:
    try:
        return metadata.version("toftwin")
    except metadata.PackageNotFoundError:  # running from a source tree without install
        return "0+unknown"


@dataclass
class SimulatedFrame:
    """A simulated frame with everything needed to save, compare and explain it."""

    image: ToFImage
    light_field: LightField
    settings: RenderSettings
    scene_hash: str
    timings_s: dict[str, float]
    rays_traced: int
    embree_seconds: float
    ideal: bool = True
    extra: dict[str, Any] = field(default_factory=dict)


def z_over_range(scene: Scene) -> np.ndarray:
    """Cosine between each pixel-centre ray and the optical axis, (H, W)."""
    intr = scene.camera.intrinsics
    u, v = pixel_centre_grid(intr)
    return pixel_to_camera_direction(intr, u, v)[:, 2].reshape(intr.shape)


def simulate(
    scene: Scene,
    settings: RenderSettings,
    tracer: RayTracer | None = None,
    progress=None,
) -> SimulatedFrame:
    """Render a scene and reconstruct the ideal ToF image."""
    t0 = time.perf_counter()
    own_tracer = tracer is None
    if tracer is None:
        tracer = RayTracer(scene.triangles_m, scene.camera.position_m, threads=settings.threads)
    try:
        assert_camera_outside_closed_meshes(scene, tracer)
        result = render(scene, settings, tracer=tracer, progress=progress)
    finally:
        if own_tracer:
            tracer.close()
    lf = result.light_field
    timings = {"render": result.seconds, **{f"render.{k}": v for k, v in result.timings_s.items()}}
    t1 = time.perf_counter()
    amplitude = np.abs(lf.phasor[0])
    image = reconstruct(
        phasor=lf.phasor,
        intensity=lf.dc_active + lf.dc_ambient,
        frequencies_hz=lf.frequencies_hz,
        z_over_range=z_over_range(scene),
        valid=amplitude > 0.0,
    )
    timings["reconstruct"] = time.perf_counter() - t1
    timings["total"] = time.perf_counter() - t0
    return SimulatedFrame(
        image=image,
        light_field=lf,
        settings=settings,
        scene_hash=scene.scene_hash,
        timings_s=timings,
        rays_traced=result.rays_traced,
        embree_seconds=result.embree_seconds,
    )


#: what each saved array holds, written into frame.json
ARRAY_UNITS = {
    "range_m": "m, radial; NaN where not valid",
    "depth_z_m": "m, along the optical axis; NaN where not valid",
    "amplitude": "W m^-2 sr^-1 (ideal sensor: |phasor| of the first frequency)",
    "intensity": "W m^-2 sr^-1 (ideal sensor: dc_active + dc_ambient)",
    "phase_rad": "rad in [0, 2 pi), first frequency",
    "phase_all_rad": "rad in [0, 2 pi), (n_f, H, W)",
    "valid": "bool",
    "frequencies_hz": "Hz",
    "phasor": "W m^-2 sr^-1, complex, (n_f, H, W)",
    "dc_active": "W m^-2 sr^-1",
    "dc_ambient": "W m^-2 sr^-1",
    "truth_range_m": "m, radial, pixel-centre ray; NaN where nothing is hit",
    "truth_depth_z_m": "m, along the optical axis; NaN where nothing is hit",
    "object_id": "index into objects of the scene, -1 for none",
    "hit": "bool",
}


def frame_arrays(frame: SimulatedFrame) -> dict[str, np.ndarray]:
    """The arrays of ``frame.npz``."""
    im, lf = frame.image, frame.light_field
    return {
        "range_m": im.range_m,
        "depth_z_m": im.depth_z_m,
        "amplitude": im.amplitude,
        "intensity": im.intensity,
        "phase_rad": im.phase_rad[0],
        "phase_all_rad": im.phase_rad,
        "valid": im.valid,
        "frequencies_hz": lf.frequencies_hz,
        "phasor": lf.phasor,
        "dc_active": lf.dc_active,
        "dc_ambient": lf.dc_ambient,
        "truth_range_m": lf.truth_range_m,
        "truth_depth_z_m": lf.truth_depth_z_m,
        "object_id": lf.object_id,
        "hit": lf.hit,
    }


def save_frame(out_dir: str | Path, frame: SimulatedFrame, scene_name: str = "") -> Path:
    """Write ``frame.npz``, ``frame.json``, ``depth.png`` and ``grey.png`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    frame_io.write_npz(out / "frame.npz", frame_arrays(frame))
    grey, full_scale = frame_io.grey_preview_8bit(frame.image.amplitude, frame.image.valid)
    frame_io.write_png(out / "depth.png", frame_io.depth_preview_mm(frame.image.range_m))
    frame_io.write_png(out / "grey.png", grey)
    s = frame.settings
    meta = {
        "scene_name": scene_name,
        "scene_hash": frame.scene_hash,
        "package_version": package_version(),
        "ideal_sensor": frame.ideal,
        "settings": {
            "integrator": s.integrator,
            "spp": s.spp,
            "max_bounces": s.max_bounces,
            "effective_bounces": s.effective_bounces,
            "seed": s.seed,
            "russian_roulette_from_bounce": s.russian_roulette_from_bounce,
            "threads": s.threads,
        },
        "timings_s": frame.timings_s,
        "rays_traced": frame.rays_traced,
        "embree_seconds": frame.embree_seconds,
        "shape": list(frame.image.range_m.shape),
        "frequencies_hz": frame.light_field.frequencies_hz.tolist(),
        "grey_preview_full_scale": full_scale,
        "arrays": ARRAY_UNITS,
        **frame.extra,
    }
    frame_io.write_json(out / "frame.json", meta)
    return out
