"""The twin's measurable parameters: the calibration file and the simulated lab's reality file.

Both files share one set of keys (:class:`TwinParameters`): what calibration can measure about
the camera (intrinsics, distortion, depth errors, sensor gain and noise), its light source
(effective optical power), the turntable (true axis and zero) and the solar simulator (the scale
of its level). A calibration file (:class:`CalibrationFile`) adds its provenance; a reality file
(:class:`RealityFile`) adds what only the object twin can measure (:class:`ObjectTwinParameters`):
the pose of what is mounted on the turntable and the objects' reflectance; an object file
(:class:`ObjectTwinFile`, ``object.yaml``) holds those keys alone, and :func:`with_object_twin`
combines it with a calibration into the twin a scene applies. Every key is optional; a
missing key means "as the nominal scene says". The format is documented in
``docs/calibration.md``; unknown keys and out-of-range values are errors naming the field
(:class:`sim_core.errors.InvalidInputError`).

Conventions (issue 13, section 1)
---------------------------------
- measured phase = true phase + ``phase_offset_rad[k]`` + sum over the wiggling terms of
  ``amplitude_rad * sin(harmonic * true phase + phase_rad)`` + the pixel's fixed-pattern
  offset, given as a range and converted with seed eq. 7 (:mod:`sim_core.depth_errors`);
- ``illumination.power_w`` replaces the scene's nominal source power;
- true turntable angle = reported angle + ``turntable.zero_offset_deg``, plus the table's
  ringing after a move (``turntable.settling``, :mod:`sim_core.settling`);
- true solar level = set level x ``solar_simulator.irradiance_scale``.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Annotated, Any

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    ValidationError,
    ValidationInfo,
    WithJsonSchema,
    field_validator,
    model_validator,
)

from sim_core import lens_ranges
from sim_core.errors import InvalidInputError
from sim_core.files import StructuredFileError, atomic_write, load_structured
from sim_core.scene_spec import (
    Distortion,
    ObjectPose,
    Point3,
    SensorOverrides,
    UnitVector,
    check_lens,
    range_error,
    scene_error_from_validation,
)

Finite = Annotated[float, Field(allow_inf_nan=False)]

#: largest phase offset or wiggling amplitude a file may give [rad]
MAX_PHASE_ERROR_RAD = 3.141592653589793
#: largest fixed-pattern offset a calibration may store [mm]
MAX_PIXEL_OFFSET_MM = 500.0
#: largest sum of ``amplitude_rad * harmonic`` over a frequency's wiggling terms: the slope of
#: the phase error; beyond it phi -> phi_measured is not monotonic (the phase folds) and the
#: correction's fixed-point iteration does not converge
MAX_WIGGLING_SLOPE = 0.5
#: the image a calibration or reality file describes: the preset's (height, width) [px]
PRESET_SHAPE = (lens_ranges.PRESET["height_px"], lens_ranges.PRESET["width_px"])


def grid_knots_needed(shape: tuple[int, int], grid_step_px: int) -> tuple[int, int]:
    """Rows and columns of knots a fixed-pattern grid needs to cover an image of ``shape``.

    >>> grid_knots_needed((171, 224), 4)
    (44, 57)
    """
    h, w = shape
    return (-(-(h - 1) // grid_step_px) + 1, -(-(w - 1) // grid_step_px) + 1)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


# --- camera ---------------------------------------------------------------------------------
class WigglingTerm(_Strict):
    """A harmonic of the phase error: ``amplitude_rad * sin(harmonic * phi + phase_rad)``.

    ``frequency_index`` restricts the term to one modulation frequency of the use case (0 the
    first); None applies it to every frequency.
    """

    harmonic: Annotated[int, Field(ge=1, le=16)]
    amplitude_rad: Annotated[float, Field(ge=0.0, le=0.5, allow_inf_nan=False)]
    phase_rad: Annotated[float, Field(ge=-10.0, le=10.0, allow_inf_nan=False)] = 0.0
    frequency_index: Annotated[int, Field(ge=0, le=3)] | None = None


class PixelOffsetPattern(_Strict):
    """Fixed-pattern range offsets drawn at random (a reality's way to say "some pattern").

    A Gaussian random field: white noise from ``seed``, smoothed by a Gaussian of standard
    deviation ``correlation_px``, scaled to standard deviation ``sigma`` [m].
    """

    sigma: Annotated[float, Field(ge=0.0, le=0.1, allow_inf_nan=False)]
    correlation_px: Annotated[float, Field(ge=0.0, le=200.0, allow_inf_nan=False)] = 10.0
    seed: Annotated[int, Field(ge=0, le=2**32 - 1)] = 0


class PixelOffsetGrid(_Strict):
    """Fixed-pattern range offsets as measured: values on a grid of pixels, interpolated between.

    Knot ``[i][j]`` sits at pixel (column ``j * grid_step_px``, row ``i * grid_step_px``); the
    grid covers the image (its last knots may lie beyond the last pixel). Cubic spline
    interpolation in between (:func:`sim_core.depth_errors.pixel_offsets_m`).
    """

    grid_step_px: Annotated[int, Field(ge=1, le=64)]
    offsets_mm: list[list[Annotated[float, Field(ge=-MAX_PIXEL_OFFSET_MM, le=MAX_PIXEL_OFFSET_MM,
                                                  allow_inf_nan=False)]]] = Field(min_length=1)

    @field_validator("offsets_mm")
    @classmethod
    def _rectangular(cls, v):
        widths = {len(row) for row in v}
        if len(widths) != 1 or 0 in widths:
            raise ValueError("every row of the grid must have the same, non-zero length")
        return v


def grid_coverage_problem(grid: PixelOffsetGrid, shape: tuple[int, int]) -> str | None:
    """Why ``grid`` does not cover an image of ``shape`` (height, width), or None."""
    rows, cols = len(grid.offsets_mm), len(grid.offsets_mm[0])
    need = grid_knots_needed(shape, grid.grid_step_px)
    if rows >= need[0] and cols >= need[1]:
        return None
    return (f"offsets_mm: a {rows} x {cols} grid at {grid.grid_step_px} px steps does not cover a "
            f"{shape[0]} x {shape[1]} image: it needs at least {need[0]} x {need[1]} knots "
            "(rows x columns)")


def _pixel_offset_kind(v: Any) -> str:
    """Which form a ``pixel_offset_m`` has: a grid (it has ``offsets_mm``) or a pattern; so
    that an error names the form's own fields, not the other's."""
    keys = v.keys() if isinstance(v, dict) else type(v).model_fields
    return "PixelOffsetGrid" if {"offsets_mm", "grid_step_px"} & set(keys) else (
        "PixelOffsetPattern")


class DepthErrors(_Strict):
    """The camera's systematic phase (depth) errors; see the module docstring for the model.

    The wiggling's slope is checked here (:data:`MAX_WIGGLING_SLOPE`); that a fixed-pattern
    grid covers the image, by the file's camera (:class:`CameraParameters`: the preset's image)
    and when a simulation builds the model (its image).
    """

    phase_offset_rad: list[Annotated[float, Field(ge=-MAX_PHASE_ERROR_RAD, le=MAX_PHASE_ERROR_RAD,
                                                  allow_inf_nan=False)]] = Field(
        default_factory=list, max_length=4)
    wiggling: list[WigglingTerm] = Field(default_factory=list, max_length=16)
    pixel_offset_m: Annotated[
        Annotated[PixelOffsetPattern, Tag("PixelOffsetPattern")]
        | Annotated[PixelOffsetGrid, Tag("PixelOffsetGrid")],
        Discriminator(_pixel_offset_kind),
    ] | None = None

    @field_validator("wiggling")
    @classmethod
    def _no_fold(cls, v: list[WigglingTerm]):
        for k in range(4):  # frequency_index 0-3; a term without one applies to all
            terms = [t for t in v if t.frequency_index in (None, k)]
            slope = sum(t.amplitude_rad * t.harmonic for t in terms)
            if slope >= MAX_WIGGLING_SLOPE:
                what = " + ".join(f"{t.amplitude_rad:g} x {t.harmonic}" for t in terms)
                raise range_error(
                    f"the sum of amplitude_rad x harmonic is {what} = {slope:.3g} for frequency "
                    f"{k}; allowed: below {MAX_WIGGLING_SLOPE} (a larger wiggling folds the "
                    "phase)")
        return v


#: illumination temperatures a file may give [degC]: the pico flexx's operating range and more
TEMPERATURE_RANGE_C = (-40.0, 125.0)
#: largest depth drift a file may give [mm/degC] (datasheets: a few tenths of a mm per degC)
MAX_DEPTH_DRIFT_MM_PER_C = 20.0
#: largest stray-light fraction a file may give: beyond it the lens is no imaging system
MAX_STRAY_LIGHT_FRACTION = 0.5
#: largest stray-light kernel radius a file may give [px] (beyond the image: uniform spread)
MAX_STRAY_LIGHT_RADIUS_PX = 10000.0

TemperatureC = Annotated[float, Field(ge=TEMPERATURE_RANGE_C[0], le=TEMPERATURE_RANGE_C[1],
                                      allow_inf_nan=False)]
DriftMmPerC = Annotated[float, Field(ge=-MAX_DEPTH_DRIFT_MM_PER_C, le=MAX_DEPTH_DRIFT_MM_PER_C,
                                     allow_inf_nan=False)]


#: ``depth_drift_mm_per_c`` as a file may give it: one number for every frequency, or 1-4, one
#: per frequency [mm/degC]
_DRIFT_ITEM_SCHEMA = {"type": "number", "minimum": -MAX_DEPTH_DRIFT_MM_PER_C,
                      "maximum": MAX_DEPTH_DRIFT_MM_PER_C}
_DRIFT_JSON_SCHEMA = {"title": "Depth Drift Mm Per C", "anyOf": [
    _DRIFT_ITEM_SCHEMA,
    {"type": "array", "items": _DRIFT_ITEM_SCHEMA, "minItems": 1, "maxItems": 4}]}


class CameraTemperature(_Strict):
    """The illumination's warm-up and the depth drift it causes (issue 27; TI's calibration model).

    The illumination warms from ``illumination_start_c`` towards ``illumination_end_c`` along
    ``T(t) = T_end + (T_start - T_end) exp(-t / time_constant_s)`` from the service's start
    (the simulated lab's clock); every frame's range grows by ``depth_drift_mm_per_c`` per
    degree above the start: one number for all modulation frequencies, or one per frequency in
    the use case's order (:mod:`sim_core.warmup`). A calibration uses only the start and the
    drift (it applies each measured frame's reported temperature).
    """

    illumination_start_c: TemperatureC
    illumination_end_c: TemperatureC
    time_constant_s: Annotated[float, Field(gt=0.0, le=1e6, allow_inf_nan=False)]
    #: one entry applies to every frequency (a single number is read as that; the file's
    #: JSON Schema says both forms, :data:`_DRIFT_JSON_SCHEMA`)
    depth_drift_mm_per_c: Annotated[list[DriftMmPerC], Field(min_length=1, max_length=4),
                                    WithJsonSchema(_DRIFT_JSON_SCHEMA)]

    @field_validator("depth_drift_mm_per_c", mode="before")
    @classmethod
    def _one_number_for_all(cls, v: Any):
        return [v] if isinstance(v, int | float) and not isinstance(v, bool) else v


class StrayLight(_Strict):
    """Light the lens and cover glass spread over the whole image (issue 27).

    ``fraction`` of each pixel's light (DC and phasors alike) leaves it and is spread over the
    image with a normalised Gaussian kernel of standard deviation ``kernel_radius_px``
    (:class:`sim_core.optics.StrayLight`).
    """

    fraction: Annotated[float, Field(ge=0.0, le=MAX_STRAY_LIGHT_FRACTION, allow_inf_nan=False)]
    kernel_radius_px: Annotated[float, Field(ge=0.0, le=MAX_STRAY_LIGHT_RADIUS_PX,
                                             allow_inf_nan=False)]


#: the largest image side ``camera.image_size_px`` holds [px]
MAX_IMAGE_SIDE_PX = 16384


class CameraParameters(_Strict):
    """What the camera really is: intrinsics, distortion, depth errors, sensor.

    ``image_size_px`` ([width, height]) names the image the lens was measured on; absent, it is
    the preset's 224 x 171. The lens keys are checked against that image, and a twin applies
    the file only to a scene camera of that size (:func:`sim_core.twin_apply.apply_to_spec`):
    ``toftwin calibrate intrinsics`` on another camera's photographs writes a valid file that
    no pico flexx scene takes by mistake.
    """

    image_size_px: tuple[Annotated[int, Field(ge=1, le=MAX_IMAGE_SIDE_PX)],
                         Annotated[int, Field(ge=1, le=MAX_IMAGE_SIDE_PX)]] | None = None
    fx_px: Finite | None = None
    fy_px: Finite | None = None
    cx_px: Finite | None = None
    cy_px: Finite | None = None
    distortion: Distortion | None = None
    depth: DepthErrors | None = None
    sensor: SensorOverrides = SensorOverrides()
    #: the illumination's warm-up drift (absent: none)
    temperature: CameraTemperature | None = None
    #: the optics' stray light (absent: none)
    stray_light: StrayLight | None = None

    @field_validator("fx_px", "fy_px", "cx_px", "cy_px", "distortion")
    @classmethod
    def _a_lens_for_the_image(cls, v, info: ValidationInfo):
        # The file's image (the preset's 224 x 171 when it names none): the rule and its ranges
        # are the scene's camera's.
        size = info.data.get("image_size_px")
        data = dict(info.data)
        if size is not None:
            data.update(width_px=size[0], height_px=size[1])
        return check_lens(info.field_name, v, data)

    @field_validator("depth")
    @classmethod
    def _grid_covers_the_image(cls, v: DepthErrors | None, info: ValidationInfo):
        if v is not None and isinstance(v.pixel_offset_m, PixelOffsetGrid):
            size = info.data.get("image_size_px")
            shape = PRESET_SHAPE if size is None else (size[1], size[0])
            problem = grid_coverage_problem(v.pixel_offset_m, shape)
            if problem is not None:
                raise range_error(f"pixel_offset_m.{problem}")
        return v


class IlluminationParameters(_Strict):
    """The camera's source: its effective mean optical power [W] (replaces the scene's)."""

    power_w: Annotated[float, Field(gt=0.0, le=1000.0, allow_inf_nan=False)] | None = None


#: the largest ringing amplitude ``turntable.settling`` holds [deg]
MAX_SETTLING_AMPLITUDE_DEG = 5.0
#: the longest rest after a move ``turntable.rest_after_move_s`` holds [s]
MAX_REST_AFTER_MOVE_S = 3600.0


class TurntableSettling(_Strict):
    """The table's ringing after every move (issue 27): a damped oscillation of its angle.

    ``amplitude_deg * exp(-zeta * omega * t) * cos(omega_d * t)`` from the end of the move, with
    ``omega = 2 pi frequency_hz`` (the natural frequency), ``zeta = damping_ratio`` and
    ``omega_d = omega sqrt(1 - zeta^2)`` (:mod:`sim_core.settling`). Under-damped only: a
    ratio in (0, 1) rings and decays; 0 would ring for ever, 1 and above would not ring.
    """

    amplitude_deg: Annotated[float, Field(ge=0.0, le=MAX_SETTLING_AMPLITUDE_DEG,
                                          allow_inf_nan=False)]
    frequency_hz: Annotated[float, Field(ge=0.05, le=500.0, allow_inf_nan=False)]
    damping_ratio: Annotated[float, Field(ge=0.001, le=0.9, allow_inf_nan=False)]


class TurntableParameters(_Strict):
    """The turntable's true axis (world frame), the error of its zero and its settling (absent:
    the table stops dead).

    ``rest_after_move_s`` is a calibration's key only: the table was seen ringing after a move
    but how it rings was not determined, so every capture after a move rests this long (the
    service's wait, :func:`service.lab.settling.settle_wait_s`; the calibration's settling
    stage's own rest, after which the board's yaw was at its noise). A reality's table rings by
    ``settling``; a reality file with this key is refused (:func:`load_reality`).
    """

    axis_point_m: Point3 | None = None
    axis_direction: UnitVector | None = None
    zero_offset_deg: Annotated[float, Field(ge=-180.0, le=180.0, allow_inf_nan=False)] = 0.0
    settling: TurntableSettling | None = None
    rest_after_move_s: Annotated[float, Field(gt=0.0, le=MAX_REST_AFTER_MOVE_S,
                                              allow_inf_nan=False)] | None = None


class SolarParameters(_Strict):
    """True solar level = set level x ``irradiance_scale``."""

    irradiance_scale: Annotated[float, Field(gt=0.0, le=10.0, allow_inf_nan=False)] = 1.0


class TwinParameters(_Strict):
    """The keys calibration measures (shared by calibration and reality files)."""

    camera: CameraParameters = CameraParameters()
    illumination: IlluminationParameters = IlluminationParameters()
    turntable: TurntableParameters = TurntableParameters()
    solar_simulator: SolarParameters = SolarParameters()


# --- the object twin's keys (reality files and object files) ----------------------------------
class MountParameters(_Strict):
    """What is on the turntable, as one rigid body: its pose error.

    The offset acts in the world frame at the turntable's zero, about the nominal axis point:
    ``x' = c + R (x - c) + t`` with ``R`` from ``rotation_deg`` (extrinsic x, y, z) and ``t`` =
    ``position_m``; the turntable then turns the result.
    """

    pose_offset: ObjectPose = ObjectPose()


class ObjectParameters(_Strict):
    """Per object: a factor on its material's reflectance parameters."""

    reflectance_scale: Annotated[float, Field(gt=0.0, le=10.0, allow_inf_nan=False)] = 1.0


class ObjectTwinParameters(_Strict):
    """The object twin's keys: the mount's pose offset and the objects' reflectance (issue 14).

    The one home of these keys: a reality file holds them beside the calibration keys, an
    object file (``object.yaml``, :class:`ObjectTwinFile`) holds them alone.
    :func:`sim_core.twin_apply.apply_to_spec` and :func:`sim_core.scene.build_scene` apply them
    whenever the twin they are given has them (:func:`has_object_keys`).
    """

    mount: MountParameters = MountParameters()
    objects: dict[Annotated[str, Field(min_length=1, max_length=100)], ObjectParameters] = Field(
        default_factory=dict)


def has_object_keys(twin: Any) -> bool:
    """Whether ``twin`` carries the object twin's keys (a reality, an object file, a combination).

    >>> has_object_keys(TwinParameters()), has_object_keys(ObjectTwinParameters())
    (False, True)
    """
    return isinstance(twin, ObjectTwinParameters)


class RealityFile(ObjectTwinParameters, TwinParameters):
    """The simulated lab's world: calibration keys plus the object twin's (issue 13, section 1).

    Also what :func:`with_object_twin` returns: a calibration combined with an object file.
    """


# --- calibration-only keys ------------------------------------------------------------------
class Provenance(_Strict):
    """Where a calibration came from."""

    created_utc: str = ""
    rig: str = ""
    software: str = ""
    frames_used: Annotated[int, Field(ge=0)] = 0
    procedures: dict[str, dict[str, Any]] = Field(default_factory=dict)


class _Provenanced(_Strict):
    """A file's provenance: where its values came from; not applied, not hashed."""

    provenance: Provenance = Provenance()

    @model_validator(mode="after")
    def _json_safe_provenance(self):
        try:
            json.dumps(self.provenance.procedures, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"provenance.procedures must be plain finite JSON: {exc}") from None
        return self


class CalibrationFile(_Provenanced, TwinParameters):
    """``calibration.yaml``: the measured keys plus their provenance (issue 13, section 3)."""


class ObjectTwinFile(_Provenanced, ObjectTwinParameters):
    """``object.yaml``: the object twin's keys as fitted, plus their provenance (issue 14).

    The provenance (``procedures.object_fit``: residuals, uncertainties, what was determined) is
    not applied and not hashed.
    """


def with_object_twin(calibration: TwinParameters | None,
                     object_twin: ObjectTwinParameters | None) -> TwinParameters | None:
    """The twin :func:`sim_core.scene.build_scene` applies: a calibration and an object file.

    ``calibration`` None means the nominal camera and rig; ``object_twin`` None the nominal
    mount and reflectance. Without an object twin the calibration comes back unchanged (its
    hash too); otherwise a :class:`RealityFile` with the calibration's keys (not its provenance)
    and the object file's keys (not its provenance), whose :func:`twin_hash` covers both.

    >>> cal = CalibrationFile(illumination=IlluminationParameters(power_w=1.2))
    >>> obj = ObjectTwinFile(objects={"body": ObjectParameters(reflectance_scale=0.9)})
    >>> twin = with_object_twin(cal, obj)
    >>> twin.illumination.power_w, twin.objects["body"].reflectance_scale
    (1.2, 0.9)
    >>> with_object_twin(cal, None) is cal, with_object_twin(None, None)
    (True, None)
    """
    if object_twin is None:
        return calibration
    base = calibration if calibration is not None else TwinParameters()
    keys = {k: getattr(base, k) for k in TwinParameters.model_fields}
    return RealityFile(**keys, mount=object_twin.mount, objects=dict(object_twin.objects))


def twin_hash(params: TwinParameters | ObjectTwinParameters) -> str:
    """SHA-256 of the parameters that change a simulation (provenance excluded), 16 hex digits.

    Every simulated frame and pose result records this, so a result says which calibration made
    it. Two files with the same measured values have the same hash.

    >>> twin_hash(TwinParameters()) == twin_hash(CalibrationFile(provenance=Provenance(rig="x")))
    True
    """
    data = params.model_dump(mode="json", exclude={"provenance"})
    if data.get("camera", {}).get("image_size_px", 0) is None:
        del data["camera"]["image_size_px"]  # absent: the preset's, as before the key existed
    text = json.dumps(data, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _parse(model: type[_Strict], data: Any, what: str):
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InvalidInputError(what, f"must be a mapping, got {type(data).__name__}")
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        err = scene_error_from_validation(exc)
        message = err.message.replace("docs/scene-format.md", "docs/calibration.md")
        raise InvalidInputError(f"{what}.{err.field}", message) from None


def parse_calibration(data: Any) -> CalibrationFile:
    """Validate a calibration given as a dict; errors name the field and the allowed range.

    >>> parse_calibration({"camera": {"fx_px": 210.0}}).camera.fx_px
    210.0
    >>> parse_calibration({"camera": {"fx": 210.0}})
    Traceback (most recent call last):
    ...
    sim_core.errors.InvalidInputError: calibration.camera.fx: unknown field (see ...)
    """
    return _parse(CalibrationFile, data, "calibration")


def parse_reality(data: Any) -> RealityFile:
    """Validate a reality given as a dict (same errors as :func:`parse_calibration`)."""
    return _parse(RealityFile, data, "reality")


def parse_twin(data: Any) -> TwinParameters:
    """A twin as the service stores it and sends it to workers: a calibration, or a calibration
    combined with an object twin (:func:`with_object_twin`: it has ``mount`` or ``objects``).

    >>> type(parse_twin({"camera": {"fx_px": 210.0}})).__name__
    'CalibrationFile'
    >>> type(parse_twin({"objects": {"body": {"reflectance_scale": 0.9}}})).__name__
    'RealityFile'
    """
    if isinstance(data, dict) and ({"mount", "objects"} & data.keys()):
        return parse_reality(data)
    return parse_calibration(data)


def _read_mapping(path: str | Path, what: str) -> Any:
    p = Path(path)
    if not p.is_file():
        raise InvalidInputError(what, f"file '{p}' does not exist")
    try:
        return load_structured(p)
    except StructuredFileError as exc:
        raise InvalidInputError(what, f"file {exc}") from None


def load_calibration(path: str | Path) -> CalibrationFile:
    """Read and validate a calibration file (YAML or JSON)."""
    return parse_calibration(_read_mapping(path, "calibration"))


def load_reality(path: str | Path) -> RealityFile:
    """Read and validate a reality file (YAML or JSON). A calibration's own key,
    ``turntable.rest_after_move_s`` (a wait, not a property of the world), is refused."""
    reality = parse_reality(_read_mapping(path, "reality"))
    if reality.turntable.rest_after_move_s is not None:
        raise InvalidInputError(
            "reality.turntable.rest_after_move_s", "is a calibration's key (how long the "
            "service rests after a move when it does not know how the table rings); a "
            "reality's table rings by turntable.settling {amplitude_deg, frequency_hz, "
            "damping_ratio}")
    return reality


def parse_object_twin(data: Any) -> ObjectTwinFile:
    """Validate an object file given as a dict (same errors as :func:`parse_calibration`).

    >>> parse_object_twin({"objects": {"body": {"reflectance_scale": 0.93}}}).objects["body"]
    ObjectParameters(reflectance_scale=0.93)
    """
    return _parse(ObjectTwinFile, data, "object_twin")


def load_object_twin(path: str | Path) -> ObjectTwinFile:
    """Read and validate an object file (``object.yaml``, YAML or JSON)."""
    return parse_object_twin(_read_mapping(path, "object_twin"))


def dump_yaml(params: TwinParameters | ObjectTwinParameters) -> str:
    """The YAML text of a calibration, reality or object file, without keys at their defaults."""
    data = params.model_dump(mode="json", exclude_defaults=True)
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)


def _write_atomic(path: str | Path, text: str) -> Path:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(p, text)


def write_calibration(path: str | Path, calibration: CalibrationFile) -> Path:
    """Write ``calibration`` as YAML, atomically (a temporary file renamed over the target)."""
    return _write_atomic(path, dump_yaml(calibration))


def write_object_twin(path: str | Path, object_twin: ObjectTwinFile) -> Path:
    """Write an object file (``object.yaml``) as YAML, atomically, like a calibration."""
    return _write_atomic(path, dump_yaml(object_twin))
