"""What the use cases take: requests to simulate, to run a pose, to create a campaign.

These are the bodies of the REST API's calls (:mod:`service.api` serves them as they are), and
also what the CLI, the benchmarks and tests hand the lab directly. Field constraints live here,
so the OpenAPI document states them and a bad request is a 422 naming the field and the allowed
range before any route code runs. Limits that depend on the hardware (the stage's software
limits) or on the settings (``max_spp``, ``max_poses``) are checked by the lab and give the same
kind of error.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    Strict,
    field_validator,
    model_validator,
)

from calibration.angles import (
    SWEEP_COUNT_RANGE,
    SWEEP_FROM_DEG,
    SWEEP_STEP_DEG,
    SWEEP_STEP_RANGE_DEG,
    SWEEP_TO_DEG,
    sweep_angles,
)
from calibration.rig_sequence import (
    DEFAULT_FIXTURES,
    FRAMES_PER_VIEW_RANGE,
    NOISE_FRAMES_RANGE,
    SOLAR_FRAMES_RANGE,
    SOLAR_LEVELS_COUNT,
    RigCalibrationPlan,
    build_rig_plan,
    stage_counts,
)
from calibration.solar import REFERENCE_SUNS_RANGE, check_reference_suns
from sim_core.adaptive import NOISE_FRACTION_RANGE
from sim_core.errors import InvalidInputError
from sim_core.lights import SUNS_RANGE

SUNS_LOW, SUNS_HIGH = SUNS_RANGE

#: numbers and switches as JSON gives them: a number field takes an integer or a float but never
#: ``true`` (which lax validation would read as 1), a switch only ``true`` or ``false``
StrictNumber = Annotated[float, Strict()]
StrictBool = Annotated[bool, Strict()]


def _in_range(lo: float, hi: float, unit: str):
    def check(v: float) -> float:
        if not (math.isfinite(v) and lo <= v <= hi):
            raise ValueError(f"got {v!r} {unit}; allowed: {lo:g} to {hi:g} {unit}")
        return v

    return check


def _check_suns(v: float) -> float:
    if math.isfinite(v) and (v == 0.0 or SUNS_LOW <= v <= SUNS_HIGH):
        return v
    raise ValueError(
        f"got {v!r} sun; allowed: {SUNS_LOW:g} to {SUNS_HIGH:g} sun, or 0 (lamp off)"
    )


def _reference_suns(v: float) -> float:
    try:
        return check_reference_suns(v)
    except InvalidInputError as exc:
        raise ValueError(exc.message) from None


def _check_level(v: float) -> float:
    if math.isfinite(v) and SUNS_LOW <= v <= SUNS_HIGH:
        return v
    raise ValueError(f"got {v!r} sun; allowed: {SUNS_LOW:g} to {SUNS_HIGH:g} sun")


Angle = Annotated[
    float,
    Strict(),
    Field(
        description="Turntable angle [deg]; also checked against the stage's software limits "
        "(see GET /api/v1/devices).",
        json_schema_extra={"minimum": -360, "maximum": 360},
    ),
    AfterValidator(_in_range(-360.0, 360.0, "deg")),
]
Suns = Annotated[
    float,
    Strict(),
    Field(
        description=f"Solar simulator level [sun]: {SUNS_LOW:g} to {SUNS_HIGH:g}, or 0 (off).",
        json_schema_extra={"minimum": 0, "maximum": SUNS_HIGH},
    ),
    AfterValidator(_check_suns),
]
Level = Annotated[
    float,
    Strict(),
    Field(
        description=f"Solar simulator level [sun], {SUNS_LOW:g} to {SUNS_HIGH:g}.",
        json_schema_extra={"minimum": SUNS_LOW, "maximum": SUNS_HIGH},
    ),
    AfterValidator(_check_level),
]
SceneName = Annotated[str, Field(pattern=r"^[A-Za-z0-9_-]{1,64}$")]
SceneRef = Annotated[
    SceneName | dict[str, Any],
    Field(description="A bundled example's name (e.g. 'satellite_ground_test') or an inline "
          "scene (docs/scene-format.md; no file meshes)."),
]
Seed = Annotated[
    int, Strict(), Field(ge=0, le=2**31 - 1, description="Seed of the simulation's noise.")
]
Spp = Annotated[int, Strict(), Field(ge=1, le=65536, description="Samples per pixel (<= max_spp).")]
PixelIndex = Annotated[int, Strict(), Field(ge=0, le=4096)]
PixelRange = tuple[PixelIndex, PixelIndex]


class RequestBody(BaseModel):
    model_config = ConfigDict(extra="forbid")


# -- masks -------------------------------------------------------------------------------------
class MaskSpec(RequestBody):
    """Which pixels the comparison counts (always intersected with both frames' valid pixels).

    ``turntable`` (default): the simulator's object mask of the objects on the turntable;
    ``objects``: the simulator's mask of the objects in ``names``; ``depth_window``: measured
    range within [near_m, far_m]; ``region``: rows [r0, r1) and cols [c0, c1); ``all``.
    """

    kind: Literal["turntable", "objects", "depth_window", "region", "all"] = "turntable"
    names: list[Annotated[str, Field(min_length=1, max_length=100)]] | None = Field(
        None, min_length=1, max_length=100
    )
    near_m: StrictNumber | None = Field(None, ge=0.0, le=1000.0)
    far_m: StrictNumber | None = Field(None, ge=0.0, le=1000.0)
    rows: PixelRange | None = None
    cols: PixelRange | None = None

    @model_validator(mode="after")
    def _fields_of_kind(self) -> MaskSpec:
        need = {"objects": ("names",), "depth_window": ("near_m", "far_m"),
                "region": ("rows", "cols")}.get(self.kind, ())
        for name in need:
            if getattr(self, name) is None:
                raise ValueError(f"mask of kind {self.kind!r} needs '{name}'")
        if self.kind == "depth_window" and not self.far_m > self.near_m:
            raise ValueError(f"far_m ({self.far_m}) must be greater than near_m ({self.near_m})")
        return self


# -- simulate ----------------------------------------------------------------------------------
class SimulationCreate(RequestBody):
    """Simulate one frame of a scene at a rig state."""

    scene: SceneRef | None = None
    turntable_deg: Angle | None = None
    solar_suns: Suns | None = None
    effects: Literal["auto", "all"] = "auto"
    ideal: StrictBool = False
    seed: Seed = 0
    spp: Spp | None = None


# -- poses -------------------------------------------------------------------------------------
class PoseCreate(RequestBody):
    """Move, illuminate, capture, simulate and compare one pose."""

    scene: SceneRef | None = None
    turntable_deg: Angle
    solar_suns: Suns
    mask: MaskSpec = MaskSpec()
    seed: Seed = 0
    spp: Spp | None = None


# -- campaigns ---------------------------------------------------------------------------------
#: a recording's file name in the data directory's recordings/ folder (no folder, no '..')
RECORDING_NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]*\.h5$"


class CampaignPoseIn(RequestBody):
    """One pose of a campaign."""

    turntable_deg: Angle
    solar_suns: Suns = 1.0
    repeats: Annotated[int, Strict()] = Field(
        1, ge=1, le=10000, description="Captures at this pose (<= max_repeats).")


class ObjectFitIn(RequestBody):
    """Fit the object twin first, then explain every pose's difference.

    Before its poses the campaign captures averaged frames at its first ``poses`` distinct
    turntable angles and fits what stands on the turntable: its pose offset and each object's
    reflectance (``toftwin fit-object``). Every pose is then compared with the nominal twin
    (the campaign's calibration), with the fitted twin (calibration and fitted object), and with
    a second capture of the same state (the noise ceiling).
    """

    poses: Annotated[int, Strict()] = Field(
        3, ge=1, le=20, description="Distinct turntable angles of the campaign's first poses "
        "the fit captures (fewer if the campaign has fewer).")
    frames: Annotated[int, Strict()] = Field(
        16, ge=1, le=256, description="Frames averaged per fit angle.")
    effects: Literal["all", "auto"] = Field(
        "all", description="The effects every pose's simulations (nominal and fitted) render: "
        "'all' (the default: what is left after the fit is then the model's error, not an "
        "effect the planner judged below one frame's depth noise, such as the interreflections "
        "that change the grey image) or 'auto' (the effect planner's choice, faster).")
    noise_fraction: Annotated[
        float, Strict(),
        Field(description="Every pose's simulations (nominal and fitted) take the campaign's "
              "samples per pixel and more where their Monte Carlo error is above this "
              f"fraction of the camera's own noise (glints, edges), {NOISE_FRACTION_RANGE[0]:g} "
              f"to {NOISE_FRACTION_RANGE[1]:g}; null: the "
              "campaign's spp everywhere. A twin at fraction k has (1 + k^2) times the "
              "noise variance of a capture: 0.35 keeps the fitted twin within 0.5 dB of the "
              "noise ceiling when the fit is right.",
              json_schema_extra={"minimum": NOISE_FRACTION_RANGE[0],
                                 "maximum": NOISE_FRACTION_RANGE[1]}),
        AfterValidator(_in_range(*NOISE_FRACTION_RANGE, "")),
    ] | None = 0.35


#: speeds a campaign may capture while turning at [deg/s]: the SMC100 stage's top speed at most
TURNING_SPEED_RANGE_DEG_S = (0.1, 20.0)


class CampaignCreate(RequestBody):
    """A campaign: a scene and the poses to measure and simulate."""

    name: str = Field(min_length=1, max_length=200)
    scene: SceneRef | None = None
    source: Literal["rig", "recording"] = Field(
        "rig", description="Where the frames come from: 'rig' captures them; 'recording' "
        "replays the recording named by 'recording' (its poses, scene, mask, seed and spp, "
        "unless given; the active calibration, as every campaign) without the rig.")
    recording: Annotated[str, Field(pattern=RECORDING_NAME_PATTERN, max_length=200)] | None = \
        Field(None, description="With source 'recording': the file in the data directory's "
              "recordings/ folder to replay (a campaign created with record: true wrote "
              "<campaign id>.h5 there).")
    record: Annotated[bool, Strict()] = Field(
        False, description="Record every captured frame with its rig state, temperature and "
        "timestamp into recordings/<campaign id>.h5 in the data directory (HDF5, "
        "docs/recordings.md), to replay later.")
    poses: list[CampaignPoseIn] = Field(
        default_factory=list, max_length=100000,
        description="At least one pose (source 'rig'); none with source 'recording' (the "
        "recording's poses are replayed).")
    mask: MaskSpec = MaskSpec()
    seed: Seed = 0
    spp: Spp | None = None
    object_fit: ObjectFitIn | None = Field(
        None, description="true (the defaults) or the fit's settings: fit the object twin "
        "from the first poses, then compare every pose with the nominal twin, the fitted twin "
        "and the noise ceiling (docs/calibration.md, the object twin); false or absent: no fit.")
    turning_deg_s: Annotated[
        float, Strict(),
        Field(description="Capture while turning (issue 27): the table turns through the "
              "poses' angles without stopping at this speed [deg/s], "
              f"{TURNING_SPEED_RANGE_DEG_S[0]:g} to {TURNING_SPEED_RANGE_DEG_S[1]:g}; a frame "
              "is taken as it passes each pose and simulated with its sub-frames at their "
              "times. Absent: stop and go, waiting for the calibrated settling.",
              json_schema_extra={"minimum": TURNING_SPEED_RANGE_DEG_S[0],
                                 "maximum": TURNING_SPEED_RANGE_DEG_S[1]}),
        AfterValidator(_in_range(*TURNING_SPEED_RANGE_DEG_S, "deg/s")),
    ] | None = None

    @field_validator("object_fit", mode="before")
    @classmethod
    def _object_fit_switch(cls, v: Any) -> Any:
        if v is True:
            return {}
        if v is False:
            return None
        if v is not None and not isinstance(v, dict):
            raise ValueError(f"got {v!r}; allowed: true, false, or an object with 'poses' "
                             "and 'frames'")
        return v

    @model_validator(mode="after")
    def _source_fields(self) -> CampaignCreate:
        replay = self.source == "recording"
        refused = {"poses": bool(self.poses), "record": self.record,
                   "object_fit": self.object_fit is not None,
                   "turning_deg_s": self.turning_deg_s is not None}
        if not replay and not self.poses:
            raise InvalidInputError("poses", "no pose given; allowed: 1 to 100000 poses")
        if not replay and self.recording is not None:
            raise InvalidInputError("recording", "names a recording to replay: needs "
                                    "source 'recording'")
        if replay and self.recording is None:
            raise InvalidInputError("recording", "source 'recording' needs the recording's "
                                    "file name")
        for name, given in refused.items():
            if replay and given:
                raise InvalidInputError(
                    name, "a replay takes it from the recording (poses, the object fit and "
                    "its result, the turning speed) and records nothing; leave it out")
        return self

    def object_fit_settings(self) -> ObjectFitIn | None:
        """The fit's settings, or None without a fit."""
        return self.object_fit


# -- calibration jobs ----------------------------------------------------------------------------
#: the board fixtures of the calibration sequence, by name
FIXTURE_NAMES: tuple[str, ...] = tuple(f.name for f in DEFAULT_FIXTURES)
FixtureName = Literal[FIXTURE_NAMES]  # type: ignore[valid-type]


class SweepIn(RequestBody):
    """The board sweep: reported turntable angles ``from_deg``, ``from_deg + step_deg``, ... up to
    ``to_deg`` (each fixture): the rule of :func:`calibration.angles.sweep_angles`, the same as
    ``toftwin calibrate rig``'s; also checked against the stage's software limits."""

    from_deg: Angle = SWEEP_FROM_DEG
    to_deg: Angle = SWEEP_TO_DEG
    step_deg: Annotated[
        float, Strict(),
        Field(description=f"Step between views [deg], {SWEEP_STEP_RANGE_DEG[0]:g} to "
              f"{SWEEP_STEP_RANGE_DEG[1]:g}; the sweep has {SWEEP_COUNT_RANGE[0]} to "
              f"{SWEEP_COUNT_RANGE[1]} angles, to_deg above from_deg.",
              json_schema_extra={"minimum": SWEEP_STEP_RANGE_DEG[0],
                                 "maximum": SWEEP_STEP_RANGE_DEG[1]}),
        AfterValidator(_in_range(*SWEEP_STEP_RANGE_DEG, "deg")),
    ] = SWEEP_STEP_DEG

    def angles(self) -> tuple[float, ...]:
        """The reported angles of the sweep (the end included when the step reaches it); an
        input error naming ``sweep`` or ``sweep.step_deg`` when they break the rule."""
        return sweep_angles(self.from_deg, self.to_deg, self.step_deg)


class CalibrationCreate(RequestBody):
    """Run the calibration sequence (``toftwin calibrate rig``) on the rig as a background job.

    Every field has the sequence's default; a reduced plan (fewer fixtures, a coarser sweep,
    fewer frames) runs faster and measures less well.
    """

    fixtures: list[FixtureName] = Field(
        default_factory=lambda: list(FIXTURE_NAMES), min_length=1,
        max_length=len(FIXTURE_NAMES),
        description="Board fixtures to sweep (each once). Several tilts are needed for the "
        "principal point: the upright board alone is a degenerate set and is refused.")
    sweep: SweepIn = SweepIn()
    frames_per_view: Annotated[int, Strict()] = Field(
        4, ge=FRAMES_PER_VIEW_RANGE[0], le=FRAMES_PER_VIEW_RANGE[1],
        description="Frames averaged per board view.")
    noise_frames: Annotated[int, Strict()] = Field(
        24, ge=NOISE_FRAMES_RANGE[0], le=NOISE_FRAMES_RANGE[1],
        description="Frames of the noise stack (16 or more for gain within 2 %).")
    solar_levels_suns: list[Level] = Field(
        default_factory=lambda: [0.8, 1.0, 1.2], min_length=SOLAR_LEVELS_COUNT[0],
        max_length=SOLAR_LEVELS_COUNT[1],
        description="Set levels of the solar simulator for its scale.")
    solar_frames: Annotated[int, Strict()] = Field(
        8, ge=SOLAR_FRAMES_RANGE[0], le=SOLAR_FRAMES_RANGE[1],
        description="Frames averaged per solar level.")
    solar_reference_suns: Annotated[
        float, Strict(),
        Field(description="A reference cell's reading at a set level of 1 sun [sun], used when "
              "the frames do not determine the solar simulator's scale; above "
              f"{REFERENCE_SUNS_RANGE[0]:g}, up to {REFERENCE_SUNS_RANGE[1]:g}.",
              json_schema_extra={"exclusiveMinimum": REFERENCE_SUNS_RANGE[0],
                                 "maximum": REFERENCE_SUNS_RANGE[1]}),
        AfterValidator(_reference_suns),
    ] | None = None
    warmup_stage: StrictBool = Field(
        True, description="Run the warm-up stage first (about 18 minutes of a fixed target "
        "after power-on, measuring the depth's temperature drift); off for a camera already "
        "warm, whose drift the calibration then leaves unmeasured.")
    settling_stage: StrictBool = Field(
        True, description="Run the settling stage (frames right after one move, measuring "
        "the turntable's ringing); off leaves the settling unmeasured.")
    activate: StrictBool = Field(
        False, description="Make the result the active calibration when the job is done.")

    @field_validator("fixtures")
    @classmethod
    def _distinct_fixtures(cls, v: list[str]) -> list[str]:
        if len(set(v)) != len(v):
            raise ValueError(f"{v} names a fixture twice; each once")
        return v

    def plan(self) -> RigCalibrationPlan:
        """The sequence's plan: :func:`calibration.rig_sequence.build_rig_plan`, the builder
        ``toftwin calibrate rig`` uses too (the same plan for the same inputs); an input error
        names the request's field (``sweep``, ``sweep.step_deg``, ...)."""
        return build_rig_plan(
            fixtures=self.fixtures, sweep_from_deg=self.sweep.from_deg,
            sweep_to_deg=self.sweep.to_deg, sweep_step_deg=self.sweep.step_deg,
            frames_per_view=self.frames_per_view, noise_frames=self.noise_frames,
            solar_levels_suns=self.solar_levels_suns, solar_frames=self.solar_frames,
            solar_reference_suns=self.solar_reference_suns,
            **stage_counts(warmup=self.warmup_stage, settling=self.settling_stage))
