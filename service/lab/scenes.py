"""Scenes the service accepts: a bundled example by name, or an inline scene dict.

An inline scene may not reference mesh files: its paths would be read on the server (any file
the service can read). Bundled scenes may, relative to the examples folder. Either way the
scene is checked completely here - the spec validated and the scene built (materials resolved,
the camera outside every closed mesh, a turntable for objects that ride on one) - so a bad scene
is a 422 when the request arrives, before anything moves, and never an error in a worker.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drivers.camera import UseCase
from service.errors import ConflictError
from service.lab.requests import MaskSpec
from sim_core.boards import board_triangles
from sim_core.camera import Camera
from sim_core.errors import InvalidInputError
from sim_core.scene import build_camera, build_scene
from sim_core.scene_checks import assert_camera_outside_closed_meshes
from sim_core.scene_spec import SceneSpec, load_scene_spec, parse_scene_spec
from sim_core.tracing import RayTracer


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

    @property
    def turntable_object_names(self) -> list[str]:
        """Names of the objects that ride on the turntable, in the scene's order."""
        return [o.name for o in self.spec.objects if o.on_turntable]

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
              "sphere": lambda m: 20 * 4 ** m.subdivisions,
              "charuco_board": lambda m: len(board_triangles(m)[0]),
              "checkerboard": lambda m: len(board_triangles(m)[0])}


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
        source = SceneSource(load_scene_spec(path), path.parent, ref)
        _check_builds(source, field)
        return source
    try:
        spec = parse_scene_spec(ref)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{field}.{exc.field}", str(exc).split(": ", 1)[-1]) from None
    if spec.calibration is not None:
        raise InvalidInputError(
            f"{field}.calibration",
            "an inline scene may not name a calibration file (it would be read on the server); "
            "the service applies its active calibration (PUT /api/v1/calibration)",
        )
    if spec.object_twin is not None:
        raise InvalidInputError(
            f"{field}.object_twin",
            "an inline scene may not name an object file (it would be read on the server)",
        )
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
    source = SceneSource(spec, Path(examples_dir), spec.name)
    _check_builds(source, field)
    return source


def _check_builds(source: SceneSource, field: str) -> None:
    """Build the scene once, as a render would, so that what only building finds is a 422 now.

    Materials are resolved, objects posed and the camera probed for being inside a closed
    mesh (a few ms for the bundled scenes; an Embree scene of the inline scene's triangles).
    """
    try:
        scene = build_scene(source.spec, source.base_dir)
        tracer = RayTracer(scene.triangles_m, scene.camera.position_m, threads=1)
        assert_camera_outside_closed_meshes(scene, tracer)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{field}.{exc.field}", exc.message) from None


def image_shape(source: SceneSource, use_case: UseCase | None) -> tuple[int, int]:
    """(rows, cols) of the frames a pose of ``source`` gives: the camera's use case decides."""
    if use_case is not None:
        return tuple(use_case.shape)
    return camera_of(source.spec).intrinsics.shape


def check_mask(mask: MaskSpec, source: SceneSource, shape: tuple[int, int]) -> None:
    """422 for a mask the frames of ``source`` at image ``shape`` (rows, cols) cannot have."""
    names = [o.name for o in source.spec.objects]
    if mask.kind == "objects":
        for i, name in enumerate(mask.names or []):
            if name not in names:
                raise InvalidInputError(
                    f"mask.names[{i}]", f"unknown object {name!r}; allowed: {names}")
    if mask.kind == "region":
        for axis, (lo, hi), size in (("rows", mask.rows, shape[0]), ("cols", mask.cols, shape[1])):
            if not 0 <= lo < hi <= size:
                raise InvalidInputError(
                    f"mask.{axis}", f"[{lo}, {hi}) is not a non-empty range inside the image's "
                    f"{size} {axis}; allowed: 0 <= start < stop <= {size}")


def scene_from_request(settings, ref: str | dict[str, Any] | None) -> SceneSource:
    """The scene of a request (the service's default scene when None), within the settings'
    bounds for inline scenes."""
    return resolve_scene(
        settings.scene if ref is None else ref, settings.examples_dir,
        settings.max_scene_objects, max_pixels=settings.max_scene_pixels,
        max_triangles=settings.max_scene_triangles,
    )


def require_mounted(scene: SceneSource, mounted: SceneSource, inline: bool) -> None:
    """409 unless ``scene`` is what stands on the rig's turntable (``mounted``).

    A pose or a campaign compares the camera's frames of the mounted object with a simulation
    of ``scene``: a bundled scene must be the mounted one by name; an inline scene (a variant of
    the mounted scene: other materials, another camera pose) must carry the same objects on its
    turntable, by name. Anything else would compare frames of one object with a simulation of
    another, with no word of it (a satellite's frames against a plane's simulation).
    """
    ours, theirs = mounted.turntable_object_names, scene.turntable_object_names
    if inline and sorted(ours) == sorted(theirs):
        return
    if not inline and scene.name == mounted.name:
        return
    remount = "" if inline else f" (TOFTWIN_SCENE={scene.name})"
    raise ConflictError(
        f"the rig's turntable holds scene {mounted.name!r} (objects on the turntable: "
        f"{ours}); the request's scene {scene.name!r} has {theirs or 'no object'} on it. A "
        f"pose compares frames of what is mounted: name scene {mounted.name!r} (or an inline "
        "variant with the same objects on its turntable), or mount the other object and "
        f"restart the service with its scene{remount}")


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
