"""A camera's own depth: royale's processed depth of one frame, for labs without raw access.

royale reconstructs depth itself and hands it to an ``IDepthDataListener`` as ``DepthData``:
per pixel a point (x, y, z) in the camera's frame [m], a noise estimate, a grey value and a
depth confidence. Such a frame has no phase images, so it cannot go through
:func:`sim_core.raw.reconstruct_raw`; :meth:`ProcessedDepthFrame.image` makes the same
:class:`~sim_core.tof.ToFImage` of it (range, z-depth, grey as amplitude and intensity, royale's
validity), and :func:`measured_image` is the one place a measured frame of either kind becomes
an image. royale has applied its own calibration to these points (lens, wiggling, temperature):
a comparison of them says so (docs/devices.md, "royale's processed depth").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sim_core.raw import RawFrame, reconstruct_raw
from sim_core.tof import ToFImage

__all__ = ["CAMERA_DATA_DEPTH", "CAMERA_DATA_RAW", "ProcessedDepthFrame", "camera_data",
           "measured_image"]

#: what a comparison names as its camera data: the raw phase frames, reconstructed by us
CAMERA_DATA_RAW = "raw"
#: ... or royale's processed depth and grey
CAMERA_DATA_DEPTH = "royale processed depth"


@dataclass(frozen=True)
class ProcessedDepthFrame:
    """royale's processed depth of one frame (module docstring); arrays are (H, W).

    Attributes
    ----------
    x_m, y_m, z_m : float32
        The point of each pixel in the camera's frame [m] (z along the optical axis).
    noise_m : float32
        royale's noise estimate [m]; NaN where royale gives none (royale 5).
    grey : float32
        royale's grey value [DN].
    confidence : float32
        royale's depth confidence scaled to 0..1; 0: royale marks the pixel invalid.
    frequencies_hz : (n_f,) float64
        The use case's modulation frequencies (royale's depth does not say them).
    exposure_s : float
    timestamp_s : float
        Seconds since the epoch.
    meta : dict
    illumination_temperature_c : float or None
    """

    x_m: np.ndarray
    y_m: np.ndarray
    z_m: np.ndarray
    noise_m: np.ndarray
    grey: np.ndarray
    confidence: np.ndarray
    frequencies_hz: np.ndarray
    exposure_s: float
    timestamp_s: float = 0.0
    meta: dict[str, Any] = field(default_factory=dict)
    illumination_temperature_c: float | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.z_m.shape

    @property
    def valid(self) -> np.ndarray:
        """royale's validity: a positive confidence and a finite point in front of the camera."""
        return ((self.confidence > 0) & np.isfinite(self.x_m) & np.isfinite(self.y_m)
                & np.isfinite(self.z_m) & (self.z_m > 0))

    def image(self) -> ToFImage:
        """The frame as a :class:`~sim_core.tof.ToFImage`: range ``|(x, y, z)|`` and z-depth
        [m] where royale says valid (NaN elsewhere), the grey value as amplitude and intensity,
        no phase (NaN: royale's depth does not give it)."""
        valid = self.valid
        x, y, z = (np.asarray(a, dtype=np.float64) for a in (self.x_m, self.y_m, self.z_m))
        with np.errstate(invalid="ignore", over="ignore"):
            rng = np.sqrt(x * x + y * y + z * z)
        grey = np.asarray(self.grey, dtype=np.float64)
        freqs = np.asarray(self.frequencies_hz, dtype=np.float64)
        return ToFImage(
            range_m=np.where(valid, rng, np.nan), depth_z_m=np.where(valid, z, np.nan),
            amplitude=grey, intensity=grey.copy(),
            phase_rad=np.full((len(freqs), *self.shape), np.nan), valid=valid,
            frequencies_hz=freqs)


def measured_image(frame: RawFrame | ProcessedDepthFrame, z_over_range: np.ndarray) -> ToFImage:
    """A measured frame's image: a raw frame reconstructed (:func:`sim_core.raw.reconstruct_raw`
    with ``z_over_range``), royale's processed depth as it is (its own z)."""
    if isinstance(frame, ProcessedDepthFrame):
        return frame.image()
    return reconstruct_raw(frame, z_over_range)


def camera_data(frame: RawFrame | ProcessedDepthFrame) -> str:
    """What a comparison of ``frame`` names as its camera data (:data:`CAMERA_DATA_RAW`,
    :data:`CAMERA_DATA_DEPTH`)."""
    return CAMERA_DATA_DEPTH if isinstance(frame, ProcessedDepthFrame) else CAMERA_DATA_RAW
