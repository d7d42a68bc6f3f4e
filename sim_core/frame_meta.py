"""``frame.json`` as a model: the keys other tools rely on, for its JSON Schema
(``toftwin schema frame``, docs/frame.schema.json) and for reading a frame's camera.

:mod:`sim_core.frame_io` writes the file; this model states the keys every frame has (shape,
frequencies, grey full scale, array units, package version), the camera keys a reader needs to
turn the frame into points (``intrinsics``, ``world_from_camera``) and the keys of each kind.
Other keys (a simulation's timings and effect plan, the service's rig state and ids) are
allowed: frame.json grows with the product, and a reader ignores what it does not know.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]


class FrameIntrinsics(BaseModel):
    """The pinhole and lens the frame was reconstructed (measured) or rendered (simulated)
    with: OpenCV's camera model, pixel centres at integers."""

    model_config = ConfigDict(extra="forbid")

    width_px: Annotated[int, Field(ge=1)]
    height_px: Annotated[int, Field(ge=1)]
    fx_px: Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
    fy_px: Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
    cx_px: FiniteFloat
    cy_px: FiniteFloat
    distortion: Annotated[list[FiniteFloat], Field(min_length=5, max_length=5,
                                                   description="k1, k2, p1, p2, k3")] = Field(
        default_factory=lambda: [0.0] * 5)


Row4 = Annotated[list[FiniteFloat], Field(min_length=4, max_length=4)]


class FrameJson(BaseModel):
    """A frame folder's ``frame.json`` (docs/frame-format.md)."""

    model_config = ConfigDict(extra="allow")

    package_version: str = Field(description="The toftwin version that wrote the frame.")
    shape: Annotated[list[Annotated[int, Field(ge=1)]], Field(min_length=2, max_length=2,
                                                               description="[H, W]")]
    frequencies_hz: Annotated[list[Annotated[float, Field(gt=0.0, allow_inf_nan=False)]],
                              Field(min_length=1, description="Modulation frequencies [Hz].")]
    grey_preview_full_scale: Annotated[float, Field(ge=0.0, allow_inf_nan=False)] = Field(
        description="Amplitude shown as grey 255; 0: an all-black grey image.")
    arrays: dict[str, str] = Field(description="The unit of each frame.npz array.")
    kind: Literal["measured", "simulated"] | None = Field(
        None, description="measured (the store's captures), or simulated (absent in a frame "
                          "written by toftwin simulate).")
    intrinsics: FrameIntrinsics | None = Field(
        None, description="The camera model of the frame; without it a reader uses the pico "
                          "flexx preset with the principal point at the image centre.")
    world_from_camera: Annotated[list[Row4], Field(min_length=4, max_length=4)] | None = Field(
        None, description="4 x 4 rigid transform from the camera frame (x right, y down, z "
                          "forward) to the scene's world frame [m]; a simulated frame's "
                          "camera pose, absent where the pose is not known.")
    scene_name: str | None = None
    scene_hash: str | None = None
    calibration_hash: str | None = Field(None, description="The calibration the frame used.")
    ideal_sensor: bool | None = Field(None, description="Simulated: no noise, SBI or ADC.")
    frame_id: Annotated[str, Field(pattern=r"^[0-9a-f]{32}$")] | None = None
    exposure_s: Annotated[float, Field(ge=0.0, allow_inf_nan=False)] | None = None
    timestamp_s: FiniteFloat | None = None
    rig: dict[str, Any] | None = Field(None, description="The rig state (the service's).")
