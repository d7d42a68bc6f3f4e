"""The scene file format: pydantic models, loading from YAML or JSON, friendly errors.

Every field, its unit and its default is documented in ``docs/scene-format.md``; unknown
fields are errors. Loading a file only validates it; :func:`sim_core.scene.build_scene` turns a
spec into a posed :class:`~sim_core.scene.Scene`.
"""

from __future__ import annotations

import math
from itertools import pairwise
from pathlib import Path
from typing import Annotated, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from sim_core import lens_ranges
from sim_core.boards import board_problem
from sim_core.errors import SceneError
from sim_core.files import StructuredFileError, load_structured
from sim_core.lights import SUNS_RANGE
from sim_core.sensor import SENSOR_BOUNDS

#: the bundled example scenes, ``examples/NAME.yaml`` in the repository (the service's
#: ``scene: "satellite_ground_test"`` and the benchmarks' default scenes name them)
EXAMPLES_DIR = Path(__file__).resolve().parents[1] / "examples"

Finite = Annotated[float, Field(allow_inf_nan=False)]
Vec3 = tuple[Finite, Finite, Finite]

#: how far from the origin a position may lie [m]: the hard cases render scenes 2,000 km away
#: (float arithmetic still keeps sub-millimetre range there); far beyond, the ray caster's
#: arithmetic overflows (a box at 1e308 m gave NaN vertices and a failed object fit)
MAX_COORDINATE_M = 1e7
#: the sizes of a shape [m]: from a nanometre (smaller, its triangles fall under the ray
#: caster's degenerate area, 1e-24 m^2) to 10 km (far beyond any lab, far inside float range)
MIN_SIZE_M, MAX_SIZE_M = 1e-9, 1e4
#: the largest rotation angle about one axis [deg] (ten turns: any orientation, and no angle so
#: large that its sine loses every digit)
MAX_ROTATION_DEG = 3600.0
#: one coordinate of a position in the scene [m]
Coordinate = Annotated[float, Field(ge=-MAX_COORDINATE_M, le=MAX_COORDINATE_M,
                                    allow_inf_nan=False)]
#: a point in the scene [m]
Point3 = tuple[Coordinate, Coordinate, Coordinate]
#: a rotation angle [deg]
RotationDeg = Annotated[float, Field(ge=-MAX_ROTATION_DEG, le=MAX_ROTATION_DEG,
                                     allow_inf_nan=False)]
#: a size in the scene [m]
PositiveLength = Annotated[float, Field(ge=MIN_SIZE_M, le=MAX_SIZE_M, allow_inf_nan=False)]

#: allowed length of a direction (normalised when used) [any unit]
DIRECTION_LENGTH_RANGE = (1e-6, 1e6)
#: allowed deviation of a unit vector's length from 1 (it is normalised when used)
UNIT_LENGTH_TOLERANCE = 0.01


def range_error(message: str) -> PydanticCustomError:
    """A validation error whose message is ``message`` as it is (no "Value error, " prefix)."""
    return PydanticCustomError("out_of_range", "{message}", {"message": message})


def _direction(v: tuple[float, float, float]) -> tuple[float, float, float]:
    length = math.hypot(*v)  # inf when it overflows: refused below
    lo, hi = DIRECTION_LENGTH_RANGE
    if not lo <= length <= hi:
        raise range_error(f"a direction of length {length:.6g} is outside [{lo:g}, {hi:g}] "
                          "(it is normalised when used)")
    return v


def _unit_vector(v: tuple[float, float, float]) -> tuple[float, float, float]:
    length = math.hypot(*v)
    if not abs(length - 1.0) <= UNIT_LENGTH_TOLERANCE:
        raise range_error(
            f"a unit vector of length {length:.6g}; allowed: a length of 1 +- "
            f"{UNIT_LENGTH_TOLERANCE:g} (it is normalised when used)")
    return v


#: a direction: finite, of length in :data:`DIRECTION_LENGTH_RANGE`, normalised when used
Direction = Annotated[Vec3, AfterValidator(_direction)]
#: a measured axis: a unit vector within :data:`UNIT_LENGTH_TOLERANCE`, normalised when used
UnitVector = Annotated[Vec3, AfterValidator(_unit_vector)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


# --- camera ---------------------------------------------------------------------------------
class PoseLookAt(_Strict):
    """Camera pose by position, look-at point and world up vector."""

    position_m: Point3
    look_at_m: Point3
    up: Direction = (0.0, 0.0, 1.0)


class PoseMatrix(_Strict):
    """Camera pose as a 4x4 camera-to-world matrix (rows)."""

    world_from_camera: tuple[
        tuple[Finite, Finite, Finite, Finite],
        tuple[Finite, Finite, Finite, Finite],
        tuple[Finite, Finite, Finite, Finite],
        tuple[Finite, Finite, Finite, Finite],
    ]


def _coefficient(name: str):
    limit = lens_ranges.DISTORTION_LIMITS[name]
    return Annotated[float, Field(ge=-limit, le=limit, allow_inf_nan=False)]


class Distortion(_Strict):
    """OpenCV radial-tangential distortion coefficients (bounds:
    :data:`sim_core.lens_ranges.DISTORTION_LIMITS`; over the image: :func:`check_lens`)."""

    k1: _coefficient("k1") = 0.0
    k2: _coefficient("k2") = 0.0
    p1: _coefficient("p1") = 0.0
    p2: _coefficient("p2") = 0.0
    k3: _coefficient("k3") = 0.0


_INTRINSICS = ("fx_px", "fy_px", "cx_px", "cy_px")


def check_lens(name: str, value, data: dict):
    """Validate intrinsic ``name`` (``fx_px`` ... ``cy_px``, ``distortion``) against the image
    ``data`` describes: its ``width_px`` and ``height_px`` when it has them (a scene's camera),
    else the preset's 224 x 171 (a calibration or reality file); the rules and their reasons
    are :mod:`sim_core.lens_ranges`'. One rule for scenes, calibrations and realities."""
    if value is None:
        return value
    preset = lens_ranges.PRESET
    width = data.get("width_px") or preset["width_px"]
    height = data.get("height_px") or preset["height_px"]
    if name in ("fx_px", "fy_px"):
        size, side = (width, "wide") if name == "fx_px" else (height, "high")
        problem = lens_ranges.focal_length_problem(value, size, side)
    elif name in ("cx_px", "cy_px"):
        size, side = (width, "wide") if name == "cx_px" else (height, "high")
        problem = lens_ranges.principal_point_problem(value, size, side)
    else:
        if any(k not in data for k in _INTRINSICS):
            return value  # an intrinsic is invalid: its own error says so
        cx0, cy0 = lens_ranges.default_principal_point(width, height)
        problem = lens_ranges.distortion_problem(
            width, height, data["fx_px"] or preset["fx_px"], data["fy_px"] or preset["fy_px"],
            cx0 if data["cx_px"] is None else data["cx_px"],
            cy0 if data["cy_px"] is None else data["cy_px"],
            (value.k1, value.k2, value.p1, value.p2, value.k3))
    if problem is not None:
        raise range_error(problem)
    return value


def _sensor_range(name: str, kind: type = float):
    """A field type allowing the range of :data:`sim_core.sensor.SENSOR_BOUNDS` (inclusive)."""
    lo, hi = SENSOR_BOUNDS[name]
    if kind is int:
        return Annotated[int, Field(ge=int(lo), le=int(hi))]
    return Annotated[float, Field(ge=lo, le=hi, allow_inf_nan=False)]


class SensorOverrides(_Strict):
    """Overrides of the PMD pixel parameters (defaults in docs/camera-presets.md)."""

    pixel_pitch_m: _sensor_range("pixel_pitch_m") | None = None
    fill_factor: _sensor_range("fill_factor") | None = None
    quantum_efficiency: _sensor_range("quantum_efficiency") | None = None
    demodulation_contrast: _sensor_range("demodulation_contrast") | None = None
    transmittance: _sensor_range("transmittance") | None = None
    full_well_e: _sensor_range("full_well_e") | None = None
    read_noise_e: _sensor_range("read_noise_e") | None = None
    dark_current_e_s: _sensor_range("dark_current_e_s") | None = None
    adc_bits: _sensor_range("adc_bits", int) | None = None
    adc_gain_e_per_dn: _sensor_range("adc_gain_e_per_dn") | None = None
    sbi_start_e: _sensor_range("sbi_start_e") | None = None
    sbi_limit_e: _sensor_range("sbi_limit_e") | None = None
    sbi_enabled: bool | None = None


class CameraSpec(_Strict):
    """Camera preset, pose and overrides of the preset's values."""

    preset: Literal["pmd-camboard-pico-flexx"] = "pmd-camboard-pico-flexx"
    pose: PoseLookAt | PoseMatrix
    mode: Literal["single", "dual"] = "single"
    modulation_frequencies_hz: (
        list[Annotated[float, Field(gt=1e5, le=1e9, allow_inf_nan=False)]] | None
    ) = Field(None, min_length=1, max_length=4)
    width_px: Annotated[int, Field(ge=1, le=4096)] | None = None
    height_px: Annotated[int, Field(ge=1, le=4096)] | None = None
    fx_px: Finite | None = None
    fy_px: Finite | None = None
    cx_px: Finite | None = None
    cy_px: Finite | None = None
    distortion: Distortion | None = None
    exposure_s: Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False)] | None = None
    aperture_diameter_m: Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False)] | None = None
    wavelength_m: Annotated[float, Field(gt=1e-7, lt=1e-5, allow_inf_nan=False)] | None = None
    sensor: SensorOverrides = SensorOverrides()

    @field_validator(*_INTRINSICS, "distortion")
    @classmethod
    def _a_lens_for_this_image(cls, v, info: ValidationInfo):
        return check_lens(info.field_name, v, info.data)


# --- illumination ---------------------------------------------------------------------------
class Illumination(_Strict):
    """The camera's own modulated light source."""

    power_w: Annotated[float, Field(ge=0.0, le=1000.0, allow_inf_nan=False)] = 1.0
    offset_m: Point3 = (0.0, 0.0, 0.0)
    angular_profile: list[tuple[Finite, Finite]] | None = Field(None, min_length=2)

    @field_validator("angular_profile")
    @classmethod
    def _profile_is_a_table(cls, v):
        if v is None:
            return v
        angles = [a for a, _ in v]
        if any(a < 0.0 or a > 180.0 for a in angles):
            raise ValueError("angles must lie in [0, 180] degrees")
        if any(b <= a for a, b in pairwise(angles)):
            raise ValueError("angles must be strictly increasing")
        if any(r < 0.0 for _, r in v):
            raise ValueError("relative intensities must be >= 0")
        if not any(r > 0.0 for _, r in v):
            raise ValueError("at least one relative intensity must be > 0")
        return v


# --- ambient --------------------------------------------------------------------------------
class SolarSimulatorSpec(_Strict):
    """A collimated solar-simulator beam with a square footprint (Oriel Sol3A 94123A)."""

    direction: Direction
    irradiance_suns: Annotated[
        float, Field(ge=SUNS_RANGE[0], le=SUNS_RANGE[1], allow_inf_nan=False)
    ] = 1.0
    in_band_fraction: Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False)] = 0.04
    beam_centre_m: Point3 = (0.0, 0.0, 0.0)
    footprint_m: tuple[PositiveLength, PositiveLength] = (0.305, 0.305)


class Sun(_Strict):
    """Direct sunlight, in-band irradiance from the Planck integral (seed eq. 12)."""

    direction: Direction
    distance_m: Annotated[float, Field(gt=1e9, le=1e14, allow_inf_nan=False)] = 1.495978707e11
    temperature_k: Annotated[float, Field(gt=1000.0, le=20000.0, allow_inf_nan=False)] = 5900.0


class EarthAlbedo(_Strict):
    """Sunlight reflected by the Earth (seed eq. 13)."""

    direction: Direction
    altitude_m: Annotated[float, Field(ge=1e5, le=1e9, allow_inf_nan=False)]
    sun_angle_deg: Annotated[float, Field(ge=0.0, le=180.0, allow_inf_nan=False)]
    albedo: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)] = 0.35


class MoonAlbedo(_Strict):
    """Sunlight reflected by the Moon (seed eq. 14)."""

    direction: Direction
    distance_m: Annotated[float, Field(ge=1.8e6, le=1e10, allow_inf_nan=False)]
    sun_angle_deg: Annotated[float, Field(ge=0.0, le=180.0, allow_inf_nan=False)]
    albedo: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)] = 0.12


class Ambient(_Strict):
    """Ambient (unmodulated) light sources; all optional."""

    solar_simulator: SolarSimulatorSpec | None = None
    sun: Sun | None = None
    earth: EarthAlbedo | None = None
    moon: MoonAlbedo | None = None


# --- objects --------------------------------------------------------------------------------
class MaterialSpec(_Strict):
    """A material: a preset name, a model ``kind`` with its parameters, or a material file.

    ``{preset: thermal-control-film}``, ``{kind: lambertian, params: {albedo: 0.5}}`` or
    ``{file: fit.yaml}`` (a material file, e.g. written by ``toftwin calibrate brdf``, holding
    ``kind`` and ``params``; a relative path is resolved against the scene file's folder);
    a preset or a file may be adjusted with ``params``.
    """

    preset: str | None = None
    kind: str | None = None
    file: str | None = None
    params: dict[str, Finite | str] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _preset_or_kind(self):
        if sum(v is not None for v in (self.preset, self.kind, self.file)) != 1:
            raise ValueError("give exactly one of 'preset', 'kind' or 'file'")
        return self


class BoxMesh(_Strict):
    kind: Literal["box"]
    size_m: tuple[PositiveLength, PositiveLength, PositiveLength]


class RectangleMesh(_Strict):
    kind: Literal["rectangle"]
    size_m: tuple[PositiveLength, PositiveLength]


class SphereMesh(_Strict):
    kind: Literal["sphere"]
    radius_m: PositiveLength
    subdivisions: Annotated[int, Field(ge=0, le=7)] = 4


class FileMesh(_Strict):
    kind: Literal["file"]
    path: str
    scale: Annotated[float, Field(gt=0.0, allow_inf_nan=False)] = 1.0


def _lambertian(albedo: float):
    return lambda: MaterialSpec(kind="lambertian", params={"albedo": albedo})


class CharucoBoardMesh(_Strict):
    """A ChArUco calibration board (OpenCV's pattern), flat in the local xy plane, facing +z."""

    kind: Literal["charuco_board"]
    squares_x: Annotated[int, Field(ge=3, le=40)]
    squares_y: Annotated[int, Field(ge=3, le=40)]
    square_m: PositiveLength
    marker_m: PositiveLength
    dictionary: Annotated[str, Field(pattern=r"^DICT_[A-Z0-9_]+$")] = "DICT_4X4_50"
    white: MaterialSpec = Field(default_factory=_lambertian(0.85))
    black: MaterialSpec = Field(default_factory=_lambertian(0.04))
    margin_m: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)] = 0.0

    @model_validator(mode="after")
    def _marker_fits(self):
        if self.marker_m >= self.square_m:
            raise ValueError("marker_m must be smaller than square_m")
        problem = board_problem(self)
        if problem is not None:
            raise range_error(problem)
        return self


class CheckerboardMesh(_Strict):
    """A plain checkerboard (top-left square black), flat in the local xy plane, facing +z."""

    kind: Literal["checkerboard"]
    squares_x: Annotated[int, Field(ge=3, le=40)]
    squares_y: Annotated[int, Field(ge=3, le=40)]
    square_m: PositiveLength
    white: MaterialSpec = Field(default_factory=_lambertian(0.85))
    black: MaterialSpec = Field(default_factory=_lambertian(0.04))
    margin_m: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)] = 0.0


_MESH_KINDS = ("box", "rectangle", "sphere", "file", "charuco_board", "checkerboard")
BOARD_KINDS = ("charuco_board", "checkerboard")
MeshSpec = Annotated[
    BoxMesh | RectangleMesh | SphereMesh | FileMesh | CharucoBoardMesh | CheckerboardMesh,
    Field(discriminator="kind"),
]


class ObjectPose(_Strict):
    """Object placement: rotation (extrinsic x, y, z, degrees) then translation."""

    position_m: Point3 = (0.0, 0.0, 0.0)
    rotation_deg: tuple[RotationDeg, RotationDeg, RotationDeg] = (0.0, 0.0, 0.0)


class ObjectSpec(_Strict):
    """An object: a mesh, its material (boards bring their own two), a pose."""

    name: Annotated[str, Field(min_length=1, max_length=100)]
    mesh: MeshSpec
    material: MaterialSpec | str | None = None
    pose: ObjectPose = ObjectPose()
    on_turntable: bool = False

    @model_validator(mode="after")
    def _material_unless_board(self):
        board = self.mesh.kind in BOARD_KINDS
        if board and self.material is not None:
            raise ValueError("a board brings its own materials (mesh.white, mesh.black); "
                             "remove 'material'")
        if not board and self.material is None:
            raise ValueError("material: Field required for a mesh of kind "
                             f"'{self.mesh.kind}'")
        return self


class TurntableSpec(_Strict):
    """Rotation stage; its angle rotates every object marked ``on_turntable``."""

    axis_point_m: Point3 = (0.0, 0.0, 0.0)
    axis_direction: UnitVector = (0.0, 0.0, 1.0)
    angle_deg: Annotated[float, Field(ge=-360.0, le=360.0, allow_inf_nan=False)] = 0.0


class MotionSpec(_Strict):
    """Uniform linear image motion during the exposure."""

    length_px: Annotated[float, Field(ge=0.0, le=200.0, allow_inf_nan=False)]
    direction_deg: Finite = 0.0


class OpticsSpec(_Strict):
    """The MTF chain of seed eq. 33; each component optional."""

    diffraction: bool = True
    pixel_aperture: bool = True
    electronics_cutoff_cycles_per_px: (
        Annotated[float, Field(gt=0.0, le=100.0, allow_inf_nan=False)] | None
    ) = None
    motion: MotionSpec | None = None
    vibration_sigma_px: Annotated[float, Field(ge=0.0, le=50.0, allow_inf_nan=False)] | None = None


#: default first bounce at which paths may end by Russian roulette: none within the usual 3
#: bounces. Starting at bounce 3 (the former default) killed 75-85 % of the paths before their
#: third vertex and weighted the survivors 4-20x, which raised the per-sample range variance
#: 1.5x on the Lambertian corner and 3.2x on the glossy one for 14-17 % fewer rays (issue 16,
#: docs/performance.md); from bounce 5 it costs 5 % variance at 5 bounces for 4 % fewer rays.
RUSSIAN_ROULETTE_FROM_BOUNCE = 5


class RenderSpec(_Strict):
    """Integrator settings."""

    integrator: Literal["direct", "path"] = "path"
    spp: Annotated[int, Field(ge=1, le=65536)] = 16
    max_bounces: Annotated[int, Field(ge=1, le=16)] = 3
    seed: Annotated[int, Field(ge=0, le=2**63 - 1)] = 0
    russian_roulette_from_bounce: Annotated[int, Field(ge=2, le=64)] = (
        RUSSIAN_ROULETTE_FROM_BOUNCE)


class SceneSpec(_Strict):
    """A complete scene file."""

    name: Annotated[str, Field(min_length=1, max_length=200)] = "scene"
    description: str = ""
    camera: CameraSpec
    illumination: Illumination = Illumination()
    ambient: Ambient = Ambient()
    objects: list[ObjectSpec] = Field(default_factory=list, max_length=10000)
    turntable: TurntableSpec | None = None
    optics: OpticsSpec = OpticsSpec()
    render: RenderSpec = RenderSpec()
    calibration: Annotated[str, Field(min_length=1, max_length=4096)] | None = None
    object_twin: Annotated[str, Field(min_length=1, max_length=4096)] | None = None

    @model_validator(mode="after")
    def _unique_names(self):
        names = [o.name for o in self.objects]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"object names must be unique; repeated: {sorted(dup)}")
        return self


def _format_loc(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out or "scene"


def scene_error_from_validation(exc: ValidationError) -> SceneError:
    """One :class:`SceneError` naming every invalid field of a pydantic validation error."""
    parts = []
    first = None
    for err in exc.errors():
        # Drop the union-member tags pydantic inserts (e.g. 'PoseLookAt', or the mesh kind
        # 'box' of the discriminated union) from the path.
        loc = []
        for part in err["loc"]:
            if isinstance(part, str) and (
                part[:1].isupper() or (loc and loc[-1] == "mesh" and part in _MESH_KINDS)
            ):
                continue
            loc.append(part)
        field = _format_loc(tuple(loc))
        first = first or field
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown field (see docs/scene-format.md for the allowed fields)"
        elif "input" in err and err["type"] not in ("missing", "out_of_range"):
            # (a range error of :func:`range_error` states the value it refuses itself)
            msg = f"{msg} (got {err['input']!r})"
        parts.append((field, msg))
    # The first field leads the message (SceneError prefixes it); the others follow by name.
    text = "; ".join([parts[0][1]] + [f"{f}: {m}" for f, m in parts[1:8]])
    return SceneError(first or "scene", text)


def parse_scene_spec(data: dict) -> SceneSpec:
    """Validate a scene given as a dict; raises :class:`SceneError`.

    The error names the field and the allowed range:

    >>> camera = {"pose": {"position_m": [0, 0, 1], "look_at_m": [0, 0, 0]}}
    >>> parse_scene_spec({"camera": camera}).render.spp
    16
    >>> parse_scene_spec({"camera": camera, "render": {"spp": 0}})
    Traceback (most recent call last):
    ...
    sim_core.errors.SceneError: render.spp: Input should be greater than or equal to 1 (got 0)
    """
    if not isinstance(data, dict):
        raise SceneError("scene", f"a scene must be a mapping, got {type(data).__name__}")
    try:
        return SceneSpec.model_validate(data)
    except ValidationError as exc:
        raise scene_error_from_validation(exc) from None


def load_scene_spec(path: str | Path) -> SceneSpec:
    """Read and validate a YAML (``.yaml``/``.yml``) or JSON scene file."""
    p = Path(path)
    if not p.is_file():
        raise SceneError("scene", f"scene file '{p}' does not exist")
    try:
        data = load_structured(p)
    except StructuredFileError as exc:
        raise SceneError("scene", f"scene file {exc}") from None
    return parse_scene_spec(data)
