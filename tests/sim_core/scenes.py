"""Small scenes built in code for the physics tests."""

from __future__ import annotations

from pathlib import Path

import yaml

from sim_core.scene import Scene, build_scene
from sim_core.scene_spec import load_scene_spec, parse_scene_spec

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def example(name: str, **kw) -> Scene:
    path = EXAMPLES / f"{name}.yaml"
    return build_scene(load_scene_spec(path), base_dir=path.parent, **kw)


def small_example(name: str, width: int = 32, **kw) -> Scene:
    """An example scene seen by a camera of ``width`` columns with the preset's field of view."""
    path = EXAMPLES / f"{name}.yaml"
    data = yaml.safe_load(path.read_text())
    scale = width / 224.0
    data["camera"].update(
        width_px=width, height_px=max(1, round(171 * scale)), fx_px=208.33 * scale,
        fy_px=208.33 * scale,
    )
    return build_scene(parse_scene_spec(data), base_dir=path.parent, **kw)


def scene_from(camera_pos, look_at, objects, power_w=1.0, width=None, height=None, **extra):
    cam = {"pose": {"position_m": list(camera_pos), "look_at_m": list(look_at),
                    "up": [0.0, 0.0, 1.0]}}
    if width:
        cam.update(width_px=width, height_px=height)
    spec = {"camera": cam, "illumination": {"power_w": power_w}, "objects": objects,
            "optics": {"diffraction": False, "pixel_aperture": False}, **extra}
    return build_scene(parse_scene_spec(spec))


def lambert(albedo: float) -> dict:
    return {"kind": "lambertian", "params": {"albedo": albedo}}


def fronto_parallel_wall(distance_m: float = 2.0, albedo: float = 0.8, power_w: float = 1.0):
    """A 20 m x 20 m Lambertian wall ``distance_m`` in front of a camera looking along +y."""
    wall = {"name": "wall", "mesh": {"kind": "rectangle", "size_m": [20.0, 20.0]},
            "material": lambert(albedo),
            "pose": {"position_m": [0.0, distance_m, 0.0], "rotation_deg": [90.0, 0.0, 0.0]}}
    return scene_from([0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [wall], power_w=power_w)
