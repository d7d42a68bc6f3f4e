"""Response schemas of the REST API (one ``Public`` family per resource) and device commands.

The errors' schemas (RFC 9457 problem details) are in :mod:`service.api.problems`.

The request bodies of simulations, poses and campaigns are what the lab's use cases take, so they
live below the API in :mod:`service.lab.requests`; the routes use them as they are.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from service.lab.requests import Angle, Level, RequestBody, StrictBool


# -- simulate ----------------------------------------------------------------------------------
class SimulationPublic(BaseModel):
    """A simulated frame and the effect plan that produced it."""

    frame_id: str
    scene_name: str
    scene_hash: str
    calibration_hash: str | None = Field(
        None, description="The calibration the simulation applied (None: nominal).")
    effect_plan: dict[str, Any]
    timings_s: dict[str, float]
    links: dict[str, str]


# -- poses -------------------------------------------------------------------------------------
class ToFFiguresPublic(BaseModel):
    """What a ToF engineer reads of a comparison, before Table 5 (``sim_core.metrics.ToFFigures``):
    the depth difference over the mask's pixels valid in both frames and flying in neither, and
    the share of flying and invalid pixels of each frame in the mask."""

    depth_diff_median_mm: float | None = Field(
        description="Median of simulated - measured range [mm] (None: no pixel left).")
    depth_diff_mad_mm: float | None = Field(
        description="Median absolute deviation from that median [mm], unscaled.")
    depth_diff_p95_abs_mm: float | None = Field(
        description="95th percentile of |simulated - measured| [mm].")
    depth_diff_n_pixels: int = Field(description="Pixels the depth figures are taken over.")
    mask_pixels: int = Field(description="Pixels of the comparison mask; the shares are of these.")
    flying_share_measured: float = Field(description="Share of flying (mixed) pixels, 0 to 1.")
    flying_share_simulated: float
    invalid_share_measured: float = Field(description="Share of invalid pixels, 0 to 1.")
    invalid_share_simulated: float
    flying_rule: dict[str, float] = Field(
        description="The flying-pixel rule's parameters (sim_core.flying_pixels.FlyingPixelRule).")


class MetricsPublic(BaseModel):
    """A comparison's metrics: ``tof`` (the figures above; null in results stored before them),
    the seed's Table 5 indexes per image (``grey``, ``depth``: mean, variance, MSE, SSIM, PSNR,
    relative errors), ``grey_chi_square``, ``n_pixels``, the grey full scales and depth unit;
    ``error`` instead when the frames had no pixel to compare; ``explained`` for campaigns with
    an object fit (nominal, fitted and noise-ceiling comparisons, each with its ``tof``)."""

    model_config = ConfigDict(extra="allow")

    tof: ToFFiguresPublic | None = None
    camera_data: str | None = Field(
        None, description="What the camera gave: 'raw' (its raw phase frames, reconstructed by "
        "toftwin) or 'royale processed depth' (royale's own depth and grey, the camera in depth "
        "mode; compared over the pixels valid in both, each grey scaled by its 99.5th "
        "percentile). Null in results stored before it was recorded.")


class PosePublic(BaseModel):
    """The comparison of one pose: both frames, the depth difference and pixel shares
    (``metrics.tof``) and the metrics of seed Table 5."""

    id: int
    campaign_id: str | None
    pose_index: int
    repeat: int
    turntable_deg: float
    solar_suns: float
    measured_frame_id: str
    simulated_frame_id: str
    metrics: MetricsPublic
    table: list[list[str]]
    rig: dict[str, Any]
    timings_s: dict[str, float]
    created_at: float
    calibration_hash: str | None = Field(
        None, description="The calibration the simulation applied (None: nominal).")


# -- campaigns ---------------------------------------------------------------------------------
class CampaignCreated(BaseModel):
    """The id of a new campaign."""

    id: str
    state: str
    links: dict[str, str]


class CurrentPose(BaseModel):
    """The pose being worked on (running) or next to do (paused, interrupted).

    ``stage``: ``pose`` (a planned pose and repeat) or ``object_fit`` (a campaign with an
    object fit capturing its fit angles; ``pose_index`` then counts those).
    """

    stage: Literal["pose", "object_fit"] = "pose"
    pose_index: int
    repeat: int
    turntable_deg: float
    solar_suns: float


CampaignState = Literal[
    "created", "running", "paused", "interrupted", "completed", "cancelled", "failed"
]


class CampaignPublic(BaseModel):
    """Where a campaign stands."""

    id: str
    name: str
    scene_name: str
    state: CampaignState
    poses_done: int
    poses_total: int
    pose_count: int
    calibration_hash: str | None = Field(
        None, description="The calibration pinned when the campaign was created (None: nominal);"
        " every pose of it applies this one.")
    object_fit: dict[str, Any] | None = Field(
        None, description="The object fit (campaigns created with object_fit): its settings, "
        "state ('pending' or 'fitted'), the fitted object twin and the fit's report.")
    source: Literal["rig", "recording"] = Field(
        "rig", description="'recording': the campaign replays a recording instead of capturing.")
    recording: str | None = Field(
        None, description="The recording it replays (source 'recording') or writes (created "
        "with record: true; links.recording downloads it), a file in the data directory's "
        "recordings/.")
    current_pose: CurrentPose | None
    eta_s: float | None
    error: str | None
    runs: int
    created_at: float
    started_at: float | None
    updated_at: float
    finished_at: float | None
    links: dict[str, str]


class ResultPublic(BaseModel):
    """One row of a campaign's results (a pose and repeat)."""

    id: int = Field(description="The result's id: GET /api/v1/poses/{id}, its image panels.")
    pose_index: int
    repeat: int
    turntable_deg: float
    solar_suns: float
    metrics: MetricsPublic
    measured_frame_id: str
    simulated_frame_id: str
    fitted_frame_id: str | None = Field(
        None, description="The simulation with the fitted object twin (campaigns with an "
        "object fit).")
    created_at: float
    timings_s: dict[str, float]
    calibration_hash: str | None = None


# -- frames ------------------------------------------------------------------------------------
class FramePublic(BaseModel):
    """Metadata of a stored frame."""

    id: str
    kind: Literal["measured", "simulated"]
    created_at: float
    campaign_id: str | None
    scene_name: str
    scene_hash: str
    calibration_hash: str | None = Field(
        None, description="Simulated: the calibration applied; measured: the calibration whose "
        "intrinsics reconstructed it. None: nominal.")
    rig: dict[str, Any] | None
    summary: dict[str, Any]
    metadata: dict[str, Any]
    links: dict[str, str]


# -- devices -----------------------------------------------------------------------------------
class MoveIn(RequestBody):
    """Target of a turntable move."""

    angle_deg: Angle


class LampIn(RequestBody):
    """Lamp on or off."""

    on: StrictBool


class LevelIn(RequestBody):
    """Solar simulator level."""

    suns: Level


class ShutterIn(RequestBody):
    """Shutter open or closed."""

    open: StrictBool


class DeviceStatus(BaseModel):
    """One device: reachable or not, and what it reports."""

    name: str
    ok: bool
    error: str | None = None
    details: dict[str, Any] = {}


class DevicesPublic(BaseModel):
    """Every device of the rig."""

    simulated: bool
    campaign_id: str | None = Field(description="The campaign holding the rig, if any.")
    calibration_id: str | None = Field(
        None, description="The calibration job holding the rig, if any.")
    devices: list[DeviceStatus]


class TurntablePosition(BaseModel):
    """Turntable angle and the range a move may ask for."""

    angle_deg: float
    limits_deg: tuple[float, float]


class SolarPublic(BaseModel):
    """Solar simulator state."""

    lamp_on: bool
    suns: float
    shutter_open: bool


class CaptureOut(BaseModel):
    """A captured (measured) frame."""

    frame_id: str
    rig: dict[str, Any]
    links: dict[str, str]


class StopOut(BaseModel):
    """What the emergency stop did."""

    stopped: list[str]
    errors: dict[str, str]
    campaign_paused: str | None
    calibration_cancelled: str | None = None


class Health(BaseModel):
    """Service status."""

    status: Literal["ok"]
    version: str
    simulated: bool
    executor: str
    workers: int
    scenes: list[str]
    mounted_scene: str = Field(
        description="The scene whose object stands on the rig's turntable (TOFTWIN_SCENE): "
        "poses and campaigns compare frames of it; another scene is refused with 409.")
    mounted_objects: list[str] = Field(
        description="The mounted scene's objects on the turntable, by name.")


# -- calibration -------------------------------------------------------------------------------
class CalibrationPublic(BaseModel):
    """The active calibration: its values, hash, provenance, and when and how it was activated."""

    calibration_hash: str = Field(description="sim_core.twin_file.twin_hash of the values; "
                                  "recorded with every frame and result that applied it.")
    calibration: dict[str, Any] = Field(description="The values (docs/calibration.md), without "
                                        "the provenance.")
    provenance: dict[str, Any]
    source: str = Field(description="PUT /api/v1/calibration or the calibration job it came from.")
    activated_at: float


class VerdictPublic(BaseModel):
    """What the estimator may say of one key (calibration.verdicts)."""

    verdict: Literal["determined", "not determined", "unexplained"]
    std: float | list[float] | None = Field(
        description="Standard deviation in the key's unit (one per component of a vector), "
        "never smaller than the residual supports; null when the data give none.")
    reason: str | None = Field(description="Why, for a key not determined or unexplained; a "
                               "condition (the span it holds over) for some determined ones.")


CalibrationJobState = Literal["queued", "running", "done", "failed", "cancelled"]


class CalibrationJobPublic(BaseModel):
    """Where a calibration job stands."""

    id: str
    state: CalibrationJobState
    plan: dict[str, Any]
    activate: bool
    steps_done: int
    steps_total: int
    progress: float = Field(description="steps_done / steps_total, 0 to 1.")
    message: str = Field(description="What the sequence is doing (or did last).")
    error: str | None
    calibration_hash: str | None = Field(description="The result's hash, once done.")
    activated: bool = Field(description="Whether its result has been made the active calibration.")
    files: dict[str, str] = Field(description="Output files once done: calibration.yaml, "
                                  "verdicts.json, report.json, report.html, and the camera "
                                  "in OpenCV's form, opencv_intrinsics.yml (jobs since it was "
                                  "written), each by its URL.")
    verdicts: dict[str, VerdictPublic] | None = Field(
        None, description="Once done: every key of calibration.yaml (camera.fx_px, "
        "turntable.zero_offset_deg, ...) with its verdict (verdicts.json, "
        "docs/calibration.md); null before.")
    operator_instruction: str | None = Field(
        None, description="Real rig: what the operator must mount now; confirm with "
        "POST /api/v1/calibrations/{id}/continue.")
    created_at: float
    started_at: float | None
    updated_at: float
    finished_at: float | None
    links: dict[str, str]
