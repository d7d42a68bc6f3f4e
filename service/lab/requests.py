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

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, Strict, model_validator

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
class CampaignPoseIn(RequestBody):
    """One pose of a campaign."""

    turntable_deg: Angle
    solar_suns: Suns = 1.0
    repeats: Annotated[int, Strict()] = Field(
        1, ge=1, le=10000, description="Captures at this pose (<= max_repeats).")


class CampaignCreate(RequestBody):
    """A campaign: a scene and the poses to measure and simulate."""

    name: str = Field(min_length=1, max_length=200)
    scene: SceneRef | None = None
    poses: list[CampaignPoseIn] = Field(min_length=1, max_length=100000)
    mask: MaskSpec = MaskSpec()
    seed: Seed = 0
    spp: Spp | None = None
