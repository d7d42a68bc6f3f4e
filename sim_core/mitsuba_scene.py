"""Our scene as a Mitsuba 3 scene: the same triangles, camera, light, material and path
integrator, so that Mitsuba renders the DC image of the camera's own light that
:func:`sim_core.render.render` puts in ``LightField.dc_active`` (``toftwin export mitsuba``,
``toftwin bench mitsuba``; docs/export-mitsuba.md).

One description, two writers: :func:`describe_scene` turns a posed :class:`Scene` into a
:class:`MitsubaScene` of plain values (no Mitsuba object; Mitsuba need not be installed), and
that is written either as a Mitsuba XML file (:func:`write_scene_xml`: ``scene.xml`` and
``meshes/*.ply``, paths relative to the XML, for ``mi.load_file``) or as the dictionary
``mi.load_dict`` takes (:func:`scene_dict`, where the matrices become ``mi.ScalarTransform4f``).
Both walk the same plugin tree (:func:`plugin_tree`), so they cannot say different things.
This module never imports Mitsuba: the functions that need it take the module as ``mi``.

What is matched
---------------
- geometry: ``scene.triangles_m`` as one triangle mesh per material (a binary PLY of unshared
  float32 vertices, loaded with face normals), so both trace the same float32 triangles;
- camera: ``perspective`` sensor with ``to_world`` = our ``world_from_camera`` with x and y
  negated (Mitsuba's camera frame is x left, y up; ours x right, y down), horizontal field of
  view ``2 atan(W / (2 fx))`` on ``fov_axis = x``, principal point offset from ``cx, cy`` (0 for a
  centred one), the same resolution; checked by comparing Mitsuba's primary ray directions to
  ours at pixel centres and corners (:func:`camera_mismatch_deg`). Mitsuba has square pixels and
  no lens distortion, so ``fx != fy`` or distortion are refused;
- pixel filter: Mitsuba's ``box`` reconstruction filter (radius 0.5 px, a sample only counts in
  its own pixel) with the ``independent`` sampler = our uniform jitter over the pixel footprint;
- light: ``point`` emitter at the light position with intensity ``P / (4 pi)`` W/sr; a light
  with an angular profile is refused, and so is ambient light (the export is the camera's own
  light: a solar simulator at 0 sun, its shutter closed, has none);
- material: ``twosided`` ``diffuse`` with the object's albedo (ours is two-sided Lambertian);
  any other material is refused;
- integrator: ``path`` with ``max_depth = bounces + 1`` (Mitsuba counts the camera vertex) and
  ``rr_depth = russian_roulette_from_bounce - 1``: both then apply Russian roulette at the same
  vertices with the same survival probability for this scene (min(throughput, 0.95) vs.
  min(1, max(0.05, throughput))), i.e. with the default (5) only when continuing to a fifth
  bounce: never within the benchmark's 1-3 bounces.

What differs
------------
- ours also computes the modulation phasor (path lengths) and per-pixel variances, and traces
  one extra primary ray per pixel for the ground-truth images; Mitsuba computes radiance only;
- ours does float64 shading arithmetic on float32 rays; Mitsuba is float32 throughout;
- Mitsuba starts camera rays at its near clip plane (0.01 m; the corner's walls are > 1 m away);
- what follows the render in our pipeline (the optics' MTF and stray light, the sensor, the
  twin's temperature drift) is not part of a Mitsuba scene.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sim_core.errors import InvalidInputError
from sim_core.files import atomic_write
from sim_core.materials.lambertian import Lambertian
from sim_core.scene import Scene
from sim_core.scene_spec import RUSSIAN_ROULETTE_FROM_BOUNCE

__all__ = [
    "MESH_FOLDER",
    "SCENE_FILE",
    "MitsubaIntegrator",
    "MitsubaMesh",
    "MitsubaPointLight",
    "MitsubaScene",
    "MitsubaSensor",
    "camera_mismatch_deg",
    "describe_scene",
    "integrator_dict",
    "plugin_tree",
    "scene_dict",
    "scene_xml",
    "write_meshes",
    "write_ply",
    "write_scene_xml",
]

#: the XML file :func:`write_scene_xml` writes, and the folder of its meshes beside it
SCENE_FILE = "scene.xml"
MESH_FOLDER = "meshes"
#: the Mitsuba scene format version the XML declares
XML_VERSION = "3.0.0"


# -------------------------------------------------------------------------------------------
# The description: plain values, no Mitsuba objects
# -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MitsubaSensor:
    """A ``perspective`` sensor with an ``independent`` sampler and an ``hdrfilm``.

    Attributes
    ----------
    width_px, height_px : int
    fov_deg : float
        Horizontal field of view (``fov_axis = x``) [deg].
    principal_point_offset_x, principal_point_offset_y : float
        Offsets of the principal point in film units (width, height) from the centre.
    to_world : (4, 4) float64
        Mitsuba's camera frame (x left, y up, z forward) to world [m].
    spp : int
        The sampler's ``sample_count``.
    """

    width_px: int
    height_px: int
    fov_deg: float
    principal_point_offset_x: float
    principal_point_offset_y: float
    to_world: np.ndarray = field(repr=False)
    spp: int


@dataclass(frozen=True)
class MitsubaPointLight:
    """An isotropic ``point`` emitter: position [m] and radiant intensity [W/sr]."""

    position_m: tuple[float, float, float]
    intensity_w_sr: float


@dataclass(frozen=True)
class MitsubaMesh:
    """The triangles of one material as a PLY shape with a two-sided diffuse BSDF.

    Attributes
    ----------
    name : str
        The shape's id, and the PLY file's stem (``material_<index>``).
    source : str
        The scene field the material comes from (``objects[2].material``).
    triangles_m : (n, 3, 3) float32
    reflectance : float
        The diffuse albedo, in [0, 1].
    """

    name: str
    source: str
    triangles_m: np.ndarray = field(repr=False)
    reflectance: float

    @property
    def filename(self) -> str:
        """The PLY file, relative to the scene's folder (``meshes/material_0.ply``)."""
        return f"{MESH_FOLDER}/{self.name}.ply"

    @property
    def n_triangles(self) -> int:
        return int(self.triangles_m.shape[0])


@dataclass(frozen=True)
class MitsubaIntegrator:
    """Mitsuba's ``path`` integrator: ``max_depth`` counts the camera vertex."""

    max_depth: int
    rr_depth: int

    @classmethod
    def matching(cls, bounces: int, rr_from_bounce: int = RUSSIAN_ROULETTE_FROM_BOUNCE
                 ) -> MitsubaIntegrator:
        """The integrator equivalent to our ``bounces`` (1 = direct) and Russian roulette
        start (see the module docstring).

        >>> MitsubaIntegrator.matching(3, 5)
        MitsubaIntegrator(max_depth=4, rr_depth=4)
        """
        return cls(max_depth=int(bounces) + 1, rr_depth=max(1, int(rr_from_bounce) - 1))


@dataclass(frozen=True)
class MitsubaScene:
    """Everything a Mitsuba scene of ours holds, as plain values."""

    sensor: MitsubaSensor
    light: MitsubaPointLight
    meshes: tuple[MitsubaMesh, ...]
    integrator: MitsubaIntegrator

    @property
    def n_triangles(self) -> int:
        return sum(m.n_triangles for m in self.meshes)


def describe_scene(
    scene: Scene,
    spp: int = 16,
    bounces: int = 3,
    rr_from_bounce: int = RUSSIAN_ROULETTE_FROM_BOUNCE,
) -> MitsubaScene:
    """The Mitsuba description of ``scene`` (see the module docstring).

    Parameters
    ----------
    scene : Scene
        A posed scene: Lambertian materials, an isotropic light, no ambient light, a camera
        with square pixels and no distortion.
    spp : int
        Samples per pixel of the sensor's sampler.
    bounces : int
        Surface interactions per path, as our ``RenderSettings.effective_bounces`` (1 = direct).
    rr_from_bounce : int
        Our ``russian_roulette_from_bounce``.

    Raises
    ------
    InvalidInputError
        For what a Mitsuba scene cannot match, naming the scene's field and what is allowed.
    """
    return MitsubaScene(
        sensor=_sensor(scene, spp),
        light=_light(scene),
        meshes=_meshes(scene),
        integrator=MitsubaIntegrator.matching(bounces, rr_from_bounce),
    )


def _sensor(scene: Scene, spp: int) -> MitsubaSensor:
    intr = scene.camera.intrinsics
    if intr.has_distortion:
        raise InvalidInputError(
            "camera.distortion", f"{list(intr.distortion)}: Mitsuba's perspective sensor has no "
            "lens distortion; allowed: all five coefficients 0")
    if not math.isclose(intr.fx_px, intr.fy_px, rel_tol=1e-9):
        raise InvalidInputError(
            "camera.fy_px", f"{intr.fy_px} differs from fx_px = {intr.fx_px}: Mitsuba's "
            "perspective sensor has square pixels; allowed: fy_px = fx_px")
    w, h = intr.width_px, intr.height_px
    # Mitsuba's camera frame: x left, y up, z forward; ours: x right, y down, z forward.
    to_world = scene.camera.world_from_camera @ np.diag([-1.0, -1.0, 1.0, 1.0])
    return MitsubaSensor(
        width_px=int(w),
        height_px=int(h),
        fov_deg=float(2.0 * np.degrees(np.arctan(0.5 * w / intr.fx_px))),
        # film position (u + 0.5) / W of our pixel u; Mitsuba adds the offset to it
        principal_point_offset_x=float(0.5 - (intr.cx_px + 0.5) / w),
        principal_point_offset_y=float(0.5 - (intr.cy_px + 0.5) / h),
        to_world=np.array(to_world, dtype=np.float64),
        spp=int(spp),
    )


def _light(scene: Scene) -> MitsubaPointLight:
    light = scene.light
    if light.profile_angle_rad is not None:
        raise InvalidInputError(
            "illumination.angular_profile", "Mitsuba's point emitter is isotropic; allowed: "
            "none (an isotropic source)")
    if scene.ambient:
        names = [a.name for a in scene.ambient]
        raise InvalidInputError(
            f"ambient.{names[0]}", f"the scene has ambient light ({', '.join(names)}); the "
            "Mitsuba scene is the camera's own light only; allowed: no ambient source (a "
            "solar simulator at 0 sun, its shutter closed, has none)")
    return MitsubaPointLight(
        position_m=tuple(float(x) for x in light.position_m),
        intensity_w_sr=float(light.power_w / (4.0 * np.pi)),
    )


def _material_field(scene: Scene, m_idx: int) -> str:
    """The scene field material ``m_idx`` comes from: ``objects[i].material``, or a board's
    ``objects[i].mesh.black`` / ``.white``."""
    sel = scene.material_index == m_idx
    if not sel.any():
        return f"materials[{m_idx}]"
    obj = int(scene.object_index[sel][0])
    own = np.unique(scene.material_index[scene.object_index == obj])
    if own.size == 1:
        return f"objects[{obj}].material"
    return f"objects[{obj}].mesh.{'black' if m_idx == own.min() else 'white'}"


def _meshes(scene: Scene) -> tuple[MitsubaMesh, ...]:
    meshes = []
    for m_idx, material in enumerate(scene.materials):
        sel = scene.material_index == m_idx
        if not sel.any():
            continue
        source = _material_field(scene, m_idx)
        if not isinstance(material, Lambertian):
            raise InvalidInputError(
                source, f"is {material.name}; Mitsuba's diffuse BSDF matches lambertian only; "
                "allowed: lambertian")
        meshes.append(MitsubaMesh(
            name=f"material_{m_idx}",
            source=source,
            triangles_m=np.asarray(scene.triangles_m[sel], dtype=np.float32),
            reflectance=float(material.albedo),
        ))
    return tuple(meshes)


# -------------------------------------------------------------------------------------------
# The plugin tree both writers walk
# -------------------------------------------------------------------------------------------
#: the XML element of each plugin type the tree holds
_CATEGORY = {
    "scene": "scene", "perspective": "sensor", "independent": "sampler", "hdrfilm": "film",
    "box": "rfilter", "point": "emitter", "ply": "shape", "twosided": "bsdf",
    "diffuse": "bsdf", "path": "integrator",
}


def integrator_dict(integrator: MitsubaIntegrator) -> dict:
    """The ``path`` integrator as ``mi.load_dict`` takes it."""
    return {"type": "path", "max_depth": int(integrator.max_depth),
            "rr_depth": int(integrator.rr_depth)}


def _sensor_tree(s: MitsubaSensor) -> dict:
    return {
        "type": "perspective",
        "fov": s.fov_deg,
        "fov_axis": "x",
        "principal_point_offset_x": s.principal_point_offset_x,
        "principal_point_offset_y": s.principal_point_offset_y,
        "to_world": np.array(s.to_world, dtype=np.float64),
        "sampler": {"type": "independent", "sample_count": int(s.spp)},
        "film": {
            "type": "hdrfilm",
            "width": int(s.width_px),
            "height": int(s.height_px),
            "pixel_format": "luminance",
            "component_format": "float32",
            "rfilter": {"type": "box"},
        },
    }


def plugin_tree(desc: MitsubaScene) -> dict:
    """``desc`` as Mitsuba's nested plugin dictionary, in plain values: a 4x4 numpy array for
    a transform, a tuple of three floats for a point, mesh files relative to the scene's
    folder. :func:`scene_xml` and :func:`scene_dict` are its two renderings."""
    tree: dict[str, Any] = {
        "type": "scene",
        "integrator": integrator_dict(desc.integrator),
        "sensor": _sensor_tree(desc.sensor),
        "light": {
            "type": "point",
            "position": tuple(float(x) for x in desc.light.position_m),
            "intensity": float(desc.light.intensity_w_sr),
        },
    }
    for mesh in desc.meshes:
        tree[mesh.name] = {
            "type": "ply",
            "filename": mesh.filename,
            "face_normals": True,
            "bsdf": {
                "type": "twosided",
                "material": {"type": "diffuse", "reflectance": float(mesh.reflectance)},
            },
        }
    return tree


# -------------------------------------------------------------------------------------------
# Writer 1: files (PLY meshes and the XML)
# -------------------------------------------------------------------------------------------
def write_ply(path: Path, triangles: np.ndarray) -> Path:
    """Binary little-endian PLY of unshared float32 triangles ``(n, 3, 3)``, written whole or
    not at all (:func:`sim_core.files.atomic_write`)."""
    tris = np.asarray(triangles, dtype="<f4").reshape(-1, 3)
    n = tris.shape[0] // 3
    faces = np.empty(n, dtype=[("k", "u1"), ("i", "<i4", (3,))])
    faces["k"] = 3
    faces["i"] = np.arange(3 * n, dtype="<i4").reshape(n, 3)
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {3 * n}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {n}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    return atomic_write(path, header.encode("ascii") + tris.tobytes() + faces.tobytes())


def write_meshes(desc: MitsubaScene, folder: Path) -> list[Path]:
    """Every mesh of ``desc`` as ``folder/meshes/<name>.ply`` (the folder must exist)."""
    mesh_dir = Path(folder) / MESH_FOLDER
    mesh_dir.mkdir(exist_ok=True)
    return [write_ply(Path(folder) / m.filename, m.triangles_m) for m in desc.meshes]


def _number(x: float) -> str:
    """The shortest text that reads back as the same float64."""
    return repr(float(x))


def _xml_element(parent: ET.Element | None, key: str, node: dict) -> ET.Element:
    """The XML element of plugin ``node`` (its properties as children), under ``parent``."""
    attrs = {"type": node["type"]}
    tag = _CATEGORY[node["type"]]
    if tag == "scene":
        attrs = {"version": XML_VERSION}
    elif parent is not None and parent.tag == "scene":
        attrs["id"] = key
    elif tag == "bsdf" and parent is not None and parent.tag == "bsdf":
        attrs["name"] = key
    el = ET.Element(tag, attrs) if parent is None else ET.SubElement(parent, tag, attrs)
    for name, value in node.items():
        if name == "type":
            continue
        if isinstance(value, dict):
            _xml_element(el, name, value)
        elif isinstance(value, bool):  # before int: a bool is an int
            ET.SubElement(el, "boolean", name=name, value="true" if value else "false")
        elif isinstance(value, int):
            ET.SubElement(el, "integer", name=name, value=str(value))
        elif isinstance(value, float):
            ET.SubElement(el, "float", name=name, value=_number(value))
        elif isinstance(value, str):
            ET.SubElement(el, "string", name=name, value=value)
        elif isinstance(value, tuple) and len(value) == 3:
            ET.SubElement(el, "point", name=name, x=_number(value[0]), y=_number(value[1]),
                          z=_number(value[2]))
        elif isinstance(value, np.ndarray) and value.shape == (4, 4):
            t = ET.SubElement(el, "transform", name=name)
            ET.SubElement(t, "matrix", value=" ".join(_number(v) for v in value.ravel()))
        else:  # the tree holds nothing else; a new kind of value needs its XML form here
            raise TypeError(f"no XML form for {name} = {value!r}")
    return el


def scene_xml(desc: MitsubaScene) -> str:
    """The Mitsuba 3 XML of ``desc``, its mesh files relative to the XML's folder."""
    root = _xml_element(None, "scene", plugin_tree(desc))
    root.insert(0, ET.Comment(
        " written by toftwin (sim_core.mitsuba_scene): the DC of the camera's own light; "
        "render with mi.load_file and mi.render, variant llvm_ad_mono or scalar_rgb "))
    for shape in root.iter("shape"):
        mesh = next(m for m in desc.meshes if m.name == shape.get("id"))
        shape.insert(0, ET.Comment(f" {mesh.source}: {mesh.n_triangles} triangles "))
    ET.indent(root, space="    ")
    return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"


def write_scene_xml(desc: MitsubaScene, folder: Path) -> Path:
    """``folder/scene.xml`` and ``folder/meshes/*.ply`` (``folder`` must exist); returns the
    XML's path. The meshes are written first, so a ``scene.xml`` finds its files."""
    write_meshes(desc, folder)
    return atomic_write(Path(folder) / SCENE_FILE, scene_xml(desc))


# -------------------------------------------------------------------------------------------
# Writer 2: the dictionary of ``mi.load_dict``
# -------------------------------------------------------------------------------------------
def _dict_values(mi, node: dict, folder: Path) -> dict:
    out: dict[str, Any] = {}
    for name, value in node.items():
        if isinstance(value, dict):
            out[name] = _dict_values(mi, value, folder)
        elif isinstance(value, np.ndarray):
            out[name] = mi.ScalarTransform4f(value.tolist())
        elif isinstance(value, tuple):
            out[name] = list(value)
        elif name == "filename":
            out[name] = str(Path(folder) / value)
        else:
            out[name] = value
    return out


def scene_dict(mi, desc: MitsubaScene, folder: Path) -> dict:
    """The dictionary ``mi.load_dict`` takes for ``desc``; its meshes are written into
    ``folder/meshes`` (``folder`` must exist until the dictionary has been loaded).

    ``mi`` is the ``mitsuba`` module with a variant set (only its ``ScalarTransform4f`` is
    used here).
    """
    write_meshes(desc, folder)
    return _dict_values(mi, plugin_tree(desc), Path(folder))


# -------------------------------------------------------------------------------------------
# The camera check
# -------------------------------------------------------------------------------------------
def camera_mismatch_deg(mi, mscene, scene: Scene) -> float:
    """Largest angle between Mitsuba's and our primary rays at pixel centres and corners [deg].

    ``mscene`` is the loaded Mitsuba scene of ``scene`` (from either writer).
    """
    intr = scene.camera.intrinsics
    w, h = intr.width_px, intr.height_px
    us = np.array([-0.5, 0.0, w / 2 - 0.5, w - 1.0, w - 0.5])
    vs = np.array([-0.5, 0.0, h / 2 - 0.5, h - 1.0, h - 0.5])
    u, v = (a.ravel() for a in np.meshgrid(us, vs))
    sensor = mscene.sensors()[0]
    pos = mi.Point2f(((u + 0.5) / w).astype(np.float32), ((v + 0.5) / h).astype(np.float32))
    ray, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
    dm = np.asarray(ray.d, dtype=np.float64)
    if dm.shape[0] == 3 and dm.shape[1] != 3:
        dm = dm.T
    do = scene.camera.pixel_directions_world(u, v)
    # atan2 of |cross| and dot: accurate for tiny angles, unlike arccos of the dot
    ang = np.arctan2(np.linalg.norm(np.cross(dm, do), axis=1), np.einsum("ij,ij->i", dm, do))
    return float(np.degrees(ang.max()))
