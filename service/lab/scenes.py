"""Scenes the service accepts: a bundled example by name, or an inline scene dict.

An inline scene may not reference mesh files: its paths would be read on the server (any file
the service can read). Bundled scenes may, relative to the examples folder. Either way the
spec is validated here, so a bad scene is a 422 before anything moves.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drivers.camera import UseCase
from sim_core.camera import Camera
from sim_core.errors import InvalidInputError
from sim_core.scene import build_camera
from sim_core.scene_spec import SceneSpec, load_scene_spec, parse_scene_spec


@dataclass(frozen=True)
class SceneSource:
    """A validated scene and where its relative mesh paths resolve.

    Attributes
    ----------
    spec : SceneSpec
    base_dir : Path
        Folder relative mesh paths resolve against.
    name : str
        The bundled name or the spec's own ``name``.
    """

    spec: SceneSpec
    base_dir: Path
    name: str

    @property
    def turntable_object_ids(self) -> list[int]:
        """Indices of the objects that ride on the turntable."""
        return [i for i, o in enumerate(self.spec.objects) if o.on_turntable]

    def to_json(self) -> str:
        """The spec as JSON (stored with a campaign, so a resume uses the same scene)."""
        return self.spec.model_dump_json()

    @classmethod
    def from_json(cls, text: str, base_dir: str, name: str) -> SceneSource:
        """Inverse of :meth:`to_json`."""
        return cls(parse_scene_spec(json.loads(text)), Path(base_dir), name)


def bundled_scenes(examples_dir: Path) -> list[str]:
    """Names of the bundled example scenes."""
    return sorted(p.stem for p in Path(examples_dir).glob("*.yaml"))


#: triangles of each generated mesh kind (icosphere: 20 * 4**subdivisions)
_TRIANGLES = {"box": lambda m: 12, "rectangle": lambda m: 2,
              "sphere": lambda m: 20 * 4 ** m.subdivisions}


def resolve_scene(
    ref: str | dict[str, Any],
    examples_dir: Path,
    max_objects: int,
    field: str = "scene",
    max_pixels: int = 1_000_000,
    max_triangles: int = 2_000_000,
) -> SceneSource:
    """Validate a scene reference; raises :class:`InvalidInputError` naming ``field``.

    An inline scene is also bounded in size - objects, triangles and image pixels - so that one
    request cannot occupy the renderer (or its memory) for hours.
    """
    if isinstance(ref, str):
        names = bundled_scenes(examples_dir)
        if ref not in names:
            raise InvalidInputError(field, f"unknown bundled scene {ref!r}; allowed: {names}")
        path = Path(examples_dir) / f"{ref}.yaml"
        return SceneSource(load_scene_spec(path), path.parent, ref)
    try:
        spec = parse_scene_spec(ref)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{field}.{exc.field}", str(exc).split(": ", 1)[-1]) from None
    if len(spec.objects) > max_objects:
        raise InvalidInputError(
            f"{field}.objects",
            f"{len(spec.objects)} objects; allowed: at most {max_objects} in an inline scene",
        )
    cam = spec.camera
    pixels = (cam.width_px or 224) * (cam.height_px or 171)
    if pixels > max_pixels:
        raise InvalidInputError(
            f"{field}.camera.width_px",
            f"{cam.width_px or 224} x {cam.height_px or 171} = {pixels} pixels; allowed: at most "
            f"{max_pixels} pixels in an inline scene",
        )
    triangles = 0
    for i, obj in enumerate(spec.objects):
        if obj.mesh.kind == "file":
            raise InvalidInputError(
                f"{field}.objects[{i}].mesh.kind",
                "'file' meshes are not allowed in an inline scene; allowed: box, rectangle, "
                "sphere (or use a bundled scene)",
            )
        triangles += _TRIANGLES[obj.mesh.kind](obj.mesh)
        if triangles > max_triangles:
            raise InvalidInputError(
                f"{field}.objects[{i}].mesh",
                f"the scene reaches {triangles} triangles here; allowed: at most "
                f"{max_triangles} in an inline scene",
            )
    return SceneSource(spec, Path(examples_dir), spec.name)


def scene_from_request(settings, ref: str | dict[str, Any] | None) -> SceneSource:
    """The scene of a request (the service's default scene when None), within the settings'
    bounds for inline scenes."""
    return resolve_scene(
        settings.scene if ref is None else ref, settings.examples_dir,
        settings.max_scene_objects, max_pixels=settings.max_scene_pixels,
        max_triangles=settings.max_scene_triangles,
    )


def for_use_case(spec: SceneSpec, use_case: UseCase) -> SceneSpec:
    """The spec with the camera set up as the real camera is (frequencies, exposure, size).

    The simulation of a pose must produce the frame the configured camera would: the same
    modulation frequencies, exposure and image size as the use case.
    """
    camera = spec.camera.model_copy(
        update={
            "modulation_frequencies_hz": list(use_case.frequencies_hz),
            "exposure_s": use_case.exposure_s,
            "width_px": use_case.shape[1],
            "height_px": use_case.shape[0],
        }
    )
    return spec.model_copy(update={"camera": camera})


def camera_of(spec: SceneSpec) -> Camera:
    """The camera model of a spec (intrinsics for reconstructing measured frames)."""
    return build_camera(spec)
