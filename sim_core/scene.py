"""A posed scene in the world frame, built from a validated :class:`SceneSpec`.

The rig state (turntable angle, solar-simulator level) may override the spec, so the service can
simulate exactly the pose the lab has just measured.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim_core import geometry
from sim_core.boards import board_triangles
from sim_core.camera import CAMERA_PRESETS, Camera, Intrinsics, look_at
from sim_core.constants import ONE_SUN_W_M2
from sim_core.depth_errors import DepthErrorModel
from sim_core.errors import InvalidInputError, SceneError
from sim_core.lights import CollimatedLight, PointLight, beam_cross_section_basis
from sim_core.materials import PRESETS, Material, make_material
from sim_core.materials.material_file import read_material_file
from sim_core.optics import StrayLight
from sim_core.radiometry import (
    earth_albedo_irradiance_w_m2,
    moon_albedo_irradiance_w_m2,
    solar_in_band_irradiance_w_m2,
)
from sim_core.scene_spec import BOARD_KINDS, MaterialSpec, ObjectSpec, OpticsSpec, SceneSpec
from sim_core.sensor import SensorParams
from sim_core.twin_apply import apply_to_spec, scale_reflectance, true_suns, true_turntable_deg
from sim_core.twin_file import (
    TEMPERATURE_RANGE_C,
    ObjectTwinFile,
    TwinParameters,
    has_object_keys,
    load_calibration,
    load_object_twin,
    twin_hash,
    with_object_twin,
)
from sim_core.warmup import TemperatureDrift

#: largest solar level a rig state may report; beyond it the lamp supply is out of its range
MAX_MEASURED_SUNS = 2.0


@dataclass(frozen=True)
class Scene:
    """Everything the renderer needs, in the world frame (metres).

    Attributes
    ----------
    camera : Camera
    light : PointLight
        The camera's modulated source.
    ambient : tuple of CollimatedLight
    triangles_m : (n, 3, 3) float64
    normals : (n, 3) float64
        Unit face normals (right-hand rule of the corner order).
    material_index : (n,) int32
        Index into ``materials`` per triangle.
    object_index : (n,) int32
        Index into ``object_names`` per triangle.
    materials : tuple of Material
        One per object, two for a board (its black and white cells).
    object_names : tuple of str
    scene_hash : str
        SHA-256 over the spec, the mesh files' bytes, the rig state and the twin parameters.
    depth_errors : DepthErrorModel or None
    twin_hash : str or None
    temperature_drift : TemperatureDrift or None
    illumination_temperature_c : float or None
        The frame's reported illumination temperature; the drift applies at it.
    stray_light : StrayLight or None
    """

    camera: Camera
    light: PointLight
    ambient: tuple[CollimatedLight, ...]
    triangles_m: np.ndarray = field(repr=False)
    normals: np.ndarray = field(repr=False)
    material_index: np.ndarray = field(repr=False)
    object_index: np.ndarray = field(repr=False)
    materials: tuple[Material, ...]
    object_names: tuple[str, ...]
    scene_hash: str
    sensor: SensorParams = field(default_factory=SensorParams)
    optics: OpticsSpec = field(default_factory=OpticsSpec)
    #: the camera's systematic depth errors (from the calibration or reality applied), if any
    depth_errors: DepthErrorModel | None = field(default=None, repr=False)
    #: :func:`sim_core.twin_file.twin_hash` of the calibration (or reality) applied, if any
    twin_hash: str | None = None
    #: the camera's warm-up drift (the twin's ``camera.temperature``), if any
    temperature_drift: TemperatureDrift | None = field(default=None, repr=False)
    #: the illumination's temperature of the frame to simulate [degC], if known
    illumination_temperature_c: float | None = None
    #: the optics' stray light (the twin's ``camera.stray_light``), if any
    stray_light: StrayLight | None = None

    @property
    def n_triangles(self) -> int:
        return int(self.triangles_m.shape[0])


def _unit(v, field_name: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(a)
    if not np.isfinite(n) or n < 1e-12:
        raise InvalidInputError(field_name, f"vector {a.tolist()} has zero length")
    return a / n


def build_camera(spec: SceneSpec) -> Camera:
    """Camera from its preset, the spec's overrides and pose."""
    cs = spec.camera
    p = dict(CAMERA_PRESETS[cs.preset])
    dist = cs.distortion
    intr = Intrinsics(
        width_px=cs.width_px or p["width_px"],
        height_px=cs.height_px or p["height_px"],
        fx_px=cs.fx_px or p["fx_px"],
        fy_px=cs.fy_px or p["fy_px"],
        cx_px=p["cx_px"] if cs.cx_px is None else cs.cx_px,
        cy_px=p["cy_px"] if cs.cy_px is None else cs.cy_px,
        distortion=(dist.k1, dist.k2, dist.p1, dist.p2, dist.k3) if dist else (0.0,) * 5,
    )
    if (cs.width_px or cs.height_px) and cs.cx_px is None and cs.cy_px is None:
        # A resized sensor keeps its principal point at the image centre.
        intr = Intrinsics(
            intr.width_px, intr.height_px, intr.fx_px, intr.fy_px,
            (intr.width_px - 1) / 2.0, (intr.height_px - 1) / 2.0,
            intr.distortion,
        )
    if cs.modulation_frequencies_hz is not None:
        freqs = tuple(cs.modulation_frequencies_hz)
    elif cs.mode == "dual":
        freqs = tuple(p["dual_frequency_hz"])
    else:
        freqs = tuple(p["modulation_frequencies_hz"])
    pose = cs.pose
    if hasattr(pose, "world_from_camera"):
        m = np.asarray(pose.world_from_camera, dtype=np.float64)
        r = m[:3, :3]
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise SceneError(
                "camera.pose.world_from_camera",
                "the upper-left 3x3 block must be a rotation (orthonormal, det = +1)",
            )
        if not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0]):
            raise SceneError("camera.pose.world_from_camera", "the last row must be [0, 0, 0, 1]")
    else:
        m = look_at(pose.position_m, pose.look_at_m, pose.up)
    return Camera(
        intrinsics=intr,
        world_from_camera=m,
        modulation_frequencies_hz=freqs,
        wavelength_m=cs.wavelength_m or p["wavelength_m"],
        filter_band_m=tuple(p["filter_band_m"]),
        aperture_diameter_m=cs.aperture_diameter_m or p["aperture_diameter_m"],
        exposure_s=cs.exposure_s or p["exposure_s"],
        preset=cs.preset,
    )


def build_light(spec: SceneSpec, camera: Camera) -> PointLight:
    """The camera's point source, placed at the camera centre plus its offset."""
    ill = spec.illumination
    pos = camera.world_from_camera[:3, :3] @ np.asarray(ill.offset_m) + camera.position_m
    axis = camera.world_from_camera[:3, 2].copy()
    if ill.angular_profile is None:
        return PointLight(position_m=pos, axis=axis, power_w=ill.power_w)
    table = np.asarray(ill.angular_profile, dtype=np.float64)
    return PointLight(
        position_m=pos,
        axis=axis,
        power_w=ill.power_w,
        profile_angle_rad=np.radians(table[:, 0]),
        profile_relative=table[:, 1],
    )


def build_ambient(
    spec: SceneSpec, camera: Camera, solar_suns: float | None = None
) -> tuple[CollimatedLight, ...]:
    """Collimated ambient sources with in-band irradiance for the camera's filter.

    ``solar_suns`` overrides the solar simulator's level (a measured rig state, which may lie
    slightly outside the ``SUNS_RANGE`` a scene file may ask for, e.g. while the lamp warms up);
    0 means its shutter is closed.
    """
    amb = spec.ambient
    out: list[CollimatedLight] = []
    band = camera.filter_band_m
    if amb.solar_simulator is not None and (solar_suns is None or solar_suns > 0.0):
        ss = amb.solar_simulator
        suns = ss.irradiance_suns if solar_suns is None else solar_suns
        if not (np.isfinite(suns) and 0.0 <= suns <= MAX_MEASURED_SUNS):
            raise InvalidInputError(
                "solar_suns", f"solar level {suns} sun is outside [0, {MAX_MEASURED_SUNS}]"
            )
        d = _unit(ss.direction, "ambient.solar_simulator.direction")
        u, v = beam_cross_section_basis(d)
        out.append(
            CollimatedLight(
                name="solar_simulator",
                direction=d,
                irradiance_w_m2=suns * ONE_SUN_W_M2 * ss.in_band_fraction,
                footprint_centre_m=np.asarray(ss.beam_centre_m, dtype=np.float64),
                footprint_size_m=tuple(ss.footprint_m),
                footprint_u=u,
                footprint_v=v,
            )
        )
    sun_e = None
    if amb.sun is not None:
        sun_e = solar_in_band_irradiance_w_m2(band, amb.sun.distance_m, amb.sun.temperature_k)
        out.append(
            CollimatedLight("sun", _unit(amb.sun.direction, "ambient.sun.direction"), sun_e)
        )
    if amb.earth is not None or amb.moon is not None:
        # Earth and Moon reflect the Sun at 1 AU unless a sun block sets another distance.
        e_s = sun_e if sun_e is not None else solar_in_band_irradiance_w_m2(band)
        if amb.earth is not None:
            e = earth_albedo_irradiance_w_m2(
                e_s, np.radians(amb.earth.sun_angle_deg), amb.earth.altitude_m, amb.earth.albedo
            )
            out.append(
                CollimatedLight("earth", _unit(amb.earth.direction, "ambient.earth.direction"), e)
            )
        if amb.moon is not None:
            e = moon_albedo_irradiance_w_m2(
                e_s, np.radians(amb.moon.sun_angle_deg), amb.moon.distance_m, amb.moon.albedo
            )
            out.append(
                CollimatedLight("moon", _unit(amb.moon.direction, "ambient.moon.direction"), e)
            )
    return tuple(out)


def build_material(m: MaterialSpec | str, field_name: str,
                   base_dir: str | Path = ".") -> Material:
    """Material from a preset name, a kind with parameters or a material file (a relative path
    resolved against ``base_dir``, the scene file's folder); errors name the field.

    A tabulated material's ``table`` (a goniometer CSV) is resolved against ``base_dir`` too.
    """
    try:
        if isinstance(m, str):
            kind, params = _preset(m)
        elif m.preset is not None:
            kind, base = _preset(m.preset)
            params = {**base, **m.params}
        elif m.file is not None:
            kind, base = _material_file(material_file_path(m, base_dir))
            params = {**base, **m.params}
        else:
            kind, params = m.kind, dict(m.params)
        params = _resolve_table_path(kind, params, base_dir)
        return make_material(kind, **params)
    except InvalidInputError as exc:
        raise SceneError(f"{field_name}.{exc.field}", str(exc).split(": ", 1)[-1]) from None
    except TypeError as exc:
        raise SceneError(field_name, f"invalid material parameters: {exc}") from None


def _resolve_table_path(kind: str | None, params: dict, base_dir: str | Path | None) -> dict:
    """``params`` with a tabulated material's relative ``table`` path made relative to
    ``base_dir`` (unchanged for other kinds, absolute paths or no ``base_dir``)."""
    table = params.get("table")
    if kind != "tabulated" or not isinstance(table, str) or base_dir is None:
        return params
    path = Path(table)
    return {**params, "table": str(path if path.is_absolute() else Path(base_dir) / path)}


def _tabulated_files(spec: SceneSpec, base_dir: Path) -> list[Path]:
    """The goniometer CSVs the scene's tabulated materials read (for the scene hash)."""
    specs = []
    for obj in spec.objects:
        specs.extend([obj.material, getattr(obj.mesh, "black", None),
                      getattr(obj.mesh, "white", None)])
    paths = []
    for m in specs:
        if isinstance(m, MaterialSpec) and m.kind == "tabulated":
            table = _resolve_table_path(m.kind, dict(m.params), base_dir).get("table")
            if isinstance(table, str) and Path(table).is_file():
                paths.append(Path(table))
    return paths


def material_file_path(m: MaterialSpec, base_dir: str | Path) -> Path:
    """The material file ``m.file`` refers to, relative paths resolved against ``base_dir``."""
    path = Path(m.file or "")
    return path if path.is_absolute() else Path(base_dir) / path


def _material_file(path: Path) -> tuple[str, dict]:
    """``(kind, params)`` of a material file; any error in it is reported under ``file``."""
    kind, params = read_material_file(path)
    try:
        make_material(kind, **params)
    except InvalidInputError as exc:
        raise InvalidInputError("file", f"material file '{path}': {exc}") from None
    return kind, params


def inline_material_files(spec: SceneSpec, base_dir: str | Path) -> SceneSpec:
    """``spec`` with every ``{file: ...}`` material replaced by the file's ``{kind, params}``
    (adjusted by its ``params``), for a worker that has not the scene's folder.

    Raises
    ------
    SceneError
        A material file is missing or invalid (the field names it).
    """
    data = spec.model_dump(mode="json")
    for i, obj in enumerate(spec.objects):
        for key, m in (("material", obj.material), ("black", getattr(obj.mesh, "black", None)),
                       ("white", getattr(obj.mesh, "white", None))):
            if not isinstance(m, MaterialSpec) or m.file is None:
                continue
            field_name = f"objects[{i}].{'material' if key == 'material' else 'mesh.' + key}"
            try:
                kind, params = _material_file(material_file_path(m, base_dir))
            except InvalidInputError as exc:
                raise SceneError(f"{field_name}.{exc.field}", exc.message) from None
            inlined = {"preset": None, "kind": kind, "file": None,
                       "params": {**params, **m.params}}
            target = data["objects"][i] if key == "material" else data["objects"][i]["mesh"]
            target[key] = inlined
    return SceneSpec.model_validate(data)


def _preset(name: str) -> tuple[str, dict]:
    if name not in PRESETS:
        raise InvalidInputError(
            "preset", f"unknown material preset '{name}'; allowed: {sorted(PRESETS)}"
        )
    kind, params = PRESETS[name]
    return kind, dict(params)


def _object_triangles(obj: ObjectSpec, base_dir: Path, field_name: str) -> np.ndarray:
    mesh = obj.mesh
    if mesh.kind in BOARD_KINDS:
        tris = board_triangles(mesh)[0]
    elif mesh.kind == "box":
        tris = geometry.box_triangles(mesh.size_m)
    elif mesh.kind == "rectangle":
        tris = geometry.rectangle_triangles(mesh.size_m)
    elif mesh.kind == "sphere":
        tris = geometry.sphere_triangles(mesh.radius_m, mesh.subdivisions)
    else:
        path = Path(mesh.path)
        if not path.is_absolute():
            path = base_dir / path
        tris = geometry.load_mesh_file(path, f"{field_name}.mesh.path") * mesh.scale
    tris = geometry.validate_triangles(tris, f"{field_name}.mesh")
    m = np.eye(4)
    m[:3, :3] = geometry.rotation_matrix_xyz_deg(obj.pose.rotation_deg)
    m[:3, 3] = obj.pose.position_m
    return geometry.transform_triangles(tris, m)


def _hash_inputs(spec: SceneSpec, base_dir: Path, rig: dict) -> str:
    h = hashlib.sha256(spec.model_dump_json().encode())
    for obj in spec.objects:
        if obj.mesh.kind == "file":
            p = Path(obj.mesh.path)
            p = p if p.is_absolute() else base_dir / p
            h.update(p.read_bytes())
        for m in (obj.material, getattr(obj.mesh, "black", None), getattr(obj.mesh, "white", None)):
            if isinstance(m, MaterialSpec) and m.file is not None:
                h.update(material_file_path(m, base_dir).read_bytes())
    for p in _tabulated_files(spec, base_dir):
        h.update(p.read_bytes())
    h.update(repr(sorted(rig.items())).encode())
    return h.hexdigest()


def scene_twin(spec: SceneSpec, base_dir: str | Path = ".") -> TwinParameters | None:
    """The twin the scene references: its ``calibration: FILE`` combined with its
    ``object_twin: FILE`` (:func:`sim_core.twin_file.with_object_twin`), both relative to
    ``base_dir``; None when it names neither."""
    base = Path(base_dir)
    cal = None
    if spec.calibration is not None:
        path = Path(spec.calibration)
        cal = load_calibration(path if path.is_absolute() else base / path)
    return with_object_twin(cal, scene_object_twin(spec, base))


def scene_object_twin(spec: SceneSpec, base_dir: str | Path = ".") -> ObjectTwinFile | None:
    """The object file the scene references (``object_twin: FILE``, relative to ``base_dir``),
    or None."""
    if spec.object_twin is None:
        return None
    path = Path(spec.object_twin)
    return load_object_twin(path if path.is_absolute() else Path(base_dir) / path)


def build_scene(
    spec: SceneSpec,
    base_dir: str | Path = ".",
    turntable_deg: float | None = None,
    solar_suns: float | None = None,
    twin: TwinParameters | None = None,
    illumination_temperature_c: float | None = None,
) -> Scene:
    """Pose a scene: load meshes, apply object poses and the turntable, build lights.

    ``twin`` (a calibration, the simulated lab's reality, or a calibration combined with an
    object file) says how the rig really is (:mod:`sim_core.twin_file`); without it the scene's
    own ``calibration`` and ``object_twin`` files apply, if it names them (:func:`scene_twin`).
    Reported turntable angles and set solar levels are converted to true ones.

    Parameters
    ----------
    spec : SceneSpec
        A validated scene.
    base_dir : path
        Directory that relative mesh paths are resolved against (the scene file's folder).
    turntable_deg : float, optional
        Overrides ``spec.turntable.angle_deg`` (the rig's measured angle) [deg].
    solar_suns : float, optional
        Overrides the solar simulator level [sun]; 0 closes its shutter.
    twin : TwinParameters, optional
        The calibration or reality to apply.
    illumination_temperature_c : float, optional
        The illumination's temperature of the frame (a measured frame's report, the simulated
        lab's clock): the twin's ``camera.temperature`` drift applies at it [degC].

    Raises
    ------
    SceneError
        For anything invalid, naming the field.
    """
    base = Path(base_dir)
    if twin is None:
        twin = scene_twin(spec, base)
    if twin is not None:
        spec = apply_to_spec(spec, twin)
        if solar_suns is None and spec.ambient.solar_simulator is not None:
            solar_suns = spec.ambient.solar_simulator.irradiance_suns
        solar_suns = true_suns(solar_suns, twin)
    camera = build_camera(spec)
    light = build_light(spec, camera)
    ambient = build_ambient(spec, camera, solar_suns)
    materials: list[Material] = []
    tris_all, mat_all, obj_all = [], [], []
    angle = spec.turntable.angle_deg if spec.turntable else 0.0
    if turntable_deg is not None:
        if not np.isfinite(turntable_deg) or abs(turntable_deg) > 360.0:
            raise InvalidInputError(
                "turntable_deg", f"{turntable_deg} is outside [-360, 360] degrees"
            )
        angle = float(turntable_deg)
    angle = true_turntable_deg(angle, twin)
    scales = twin.objects if has_object_keys(twin) else {}
    unknown = sorted(set(scales) - {o.name for o in spec.objects})
    if unknown:
        raise SceneError("twin.objects", f"names no object of the scene: {unknown}")
    for i, obj in enumerate(spec.objects):
        fname = f"objects[{i}]"
        tris = _object_triangles(obj, base, fname)
        if obj.on_turntable:
            if spec.turntable is None:
                raise SceneError(f"{fname}.on_turntable", "is true but the scene has no turntable")
            tt = spec.turntable
            r = geometry.axis_angle_matrix(tt.axis_direction, np.radians(angle))
            c = np.asarray(tt.axis_point_m, dtype=np.float64)
            m = np.eye(4)
            m[:3, :3] = r
            m[:3, 3] = c - r @ c
            tris = geometry.transform_triangles(tris, m)
        if obj.mesh.kind in BOARD_KINDS:
            # Two materials: black cells (0) and white cells (1) of the pattern.
            own = [build_material(obj.mesh.black, f"{fname}.mesh.black", base),
                   build_material(obj.mesh.white, f"{fname}.mesh.white", base)]
            local = board_triangles(obj.mesh)[1]
        else:
            own = [build_material(obj.material, f"{fname}.material", base)]
            local = np.zeros(tris.shape[0], dtype=np.int32)
        if obj.name in scales:
            own = [scale_reflectance(m, scales[obj.name].reflectance_scale) for m in own]
        first_material = len(materials)
        materials.extend(own)
        tris_all.append(tris)
        mat_all.append((first_material + local).astype(np.int32))
        obj_all.append(np.full(tris.shape[0], i, dtype=np.int32))
    if tris_all:
        tris = np.concatenate(tris_all)
        mat_idx, obj_idx = np.concatenate(mat_all), np.concatenate(obj_all)
    else:
        tris = np.zeros((0, 3, 3))
        mat_idx = obj_idx = np.zeros(0, dtype=np.int32)
    rig = {"turntable_deg": angle, "solar_suns": solar_suns}
    temperature_c = _checked_temperature(illumination_temperature_c)
    if temperature_c is not None:  # absent: the hash of a scene without one is unchanged
        rig["illumination_temperature_c"] = temperature_c
    t_hash = twin_hash(twin) if twin is not None else None
    depth = twin.camera.depth if twin is not None else None
    warm = twin.camera.temperature if twin is not None else None
    stray = twin.camera.stray_light if twin is not None else None
    return Scene(
        camera=camera,
        light=light,
        ambient=ambient,
        triangles_m=tris,
        normals=geometry.face_normals(tris) if len(tris) else np.zeros((0, 3)),
        material_index=mat_idx,
        object_index=obj_idx,
        materials=tuple(materials),
        object_names=tuple(o.name for o in spec.objects),
        scene_hash=_hash_inputs(spec, base, {**rig, "twin": t_hash}),
        sensor=SensorParams(**spec.camera.sensor.model_dump(exclude_none=True)),
        optics=spec.optics,
        depth_errors=None if depth is None else DepthErrorModel.from_spec(
            depth, camera.modulation_frequencies_hz, camera.intrinsics.shape),
        twin_hash=t_hash,
        temperature_drift=None if warm is None else TemperatureDrift.from_spec(
            warm, camera.modulation_frequencies_hz),
        illumination_temperature_c=temperature_c,
        stray_light=None if stray is None else StrayLight(stray.fraction,
                                                          stray.kernel_radius_px),
    )


def _checked_temperature(value: float | None) -> float | None:
    """A frame's illumination temperature, checked against the files' range [degC]."""
    if value is None:
        return None
    lo, hi = TEMPERATURE_RANGE_C
    if not (math.isfinite(float(value)) and lo <= float(value) <= hi):
        raise InvalidInputError("illumination_temperature_c",
                                f"{value!r} is outside [{lo:g}, {hi:g}] degC")
    return float(value)
