"""royale's raw data as our :class:`~sim_core.raw.RawFrame` (pure; no roypy needed).

:func:`royale_to_raw_frame` is a pure function of a :class:`~toftwin_camera_bridge.RawDataCopy`
(a plain copy of ``royale::RawData`` made in royale's callback by
:func:`toftwin_camera_bridge.copy_roypy_raw_data`, in this process or in the camera bridge): it
finds the grey frame (the exposure group of one frame, else the one frame with illumination off,
else the first), groups the other frames in fours by frequency, orders each group by phase
angle, and applies our convention C = raw - 2048 (12-bit values in 16-bit words; ``value_shift``
for left-aligned data). A pico flexx use case is a grey raw frame set (one frame, exposure group
``"gray"``) and one four-phase set (0, 90, 180, 270 degrees) per modulation frequency; royale can
put the grey frame first or last (``IntensityPhaseOrder``).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from drivers.camera.wire import (
    MAX_RAW,
    N_PHASES,
    RAW_OFFSET,
    UseCase,
    get_use_case,
    raw_to_wire_values,
)
from drivers.errors import DeviceInputError, ProtocolError
from sim_core.processed_depth import ProcessedDepthFrame
from sim_core.raw import RawFrame, reconstruct_raw
from toftwin_camera_bridge import DEPTH_CHANNELS, DepthDataCopy, RawDataCopy

__all__ = ["RoyaleDataError", "raw_frame_to_royale", "raw_frame_to_royale_depth",
           "royale_depth_to_frame", "royale_to_raw_frame"]


class RoyaleDataError(ProtocolError):
    """Raw data from royale does not have the form a pico flexx use case gives."""


def _per_frame(values: tuple[int, ...], counts: tuple[int, ...], n: int, what: str) -> list[int]:
    """Values given per raw frame or per exposure group, expanded to one per raw frame."""
    if len(values) == n:
        return list(values)
    if counts and len(values) == len(counts) and sum(counts) == n:
        return [v for v, c in zip(values, counts, strict=True) for _ in range(c)]
    raise RoyaleDataError(
        f"{len(values)} {what} for {n} raw frames in exposure groups {list(counts)}: "
        "neither one per raw frame nor one per exposure group"
    )


def _grey_index(data: RawDataCopy, n: int) -> tuple[int, str]:
    """Index of the grey raw frame and how it was found."""
    counts = data.raw_frame_count
    if counts and sum(counts) == n:
        singles = [g for g, c in enumerate(counts) if c == 1]
        if len(singles) == 1:
            return sum(counts[: singles[0]]), "exposure group of one raw frame"
    if len(data.illumination_enabled) == n:
        dark = [i for i, on in enumerate(data.illumination_enabled) if not on]
        if len(dark) == 1:
            return dark[0], "illumination disabled"
    return 0, "assumed first (royale reported no groups or illumination flags)"


def royale_to_raw_frame(
    data: RawDataCopy,
    *,
    use_case: str | UseCase | None = None,
    value_shift: int = 0,
    timestamp_s: float | None = None,
    meta: dict[str, Any] | None = None,
) -> RawFrame:
    """Convert one copy of royale raw data into a :class:`RawFrame` (pure; no roypy needed).

    Parameters
    ----------
    data : RawDataCopy
        ``1 + 4 n_f`` raw frames of 12-bit values.
    use_case : name, UseCase or None
        When given, the frequencies found must be the use case's (same order).
    value_shift : int
        Right shift applied to every word first (4 for 12-bit values stored left-aligned).
    timestamp_s : float or None
        Used when royale's timestamp could not be read (the host's arrival time).
    meta : dict or None
        Merged into the frame's metadata.

    Raises
    ------
    RoyaleDataError
        Shapes, frame counts, frequencies or phase angles that a pico flexx use case cannot
        produce, or values above 4095 after the shift; the message says which.
    """
    if not 0 <= value_shift <= 4:
        raise DeviceInputError("value_shift", f"got {value_shift!r}; 0..4 bits")
    frames = np.asarray(data.raw_frames)
    n = frames.shape[0] if frames.ndim == 3 else -1
    if frames.ndim != 3 or frames.shape[1:] != (data.height, data.width):
        raise RoyaleDataError(
            f"raw frames of shape {frames.shape}; expected (n, {data.height}, {data.width})"
        )
    if n < 1 + N_PHASES or (n - 1) % N_PHASES:
        raise RoyaleDataError(f"{n} raw frames; a use case gives 1 grey + 4 per frequency")
    words = frames.astype(np.uint16) >> np.uint16(value_shift)
    if int(words.max()) > MAX_RAW:
        raise RoyaleDataError(
            f"raw values up to {int(words.max())} exceed 12 bits (0..{MAX_RAW}); for 12-bit "
            "values stored left-aligned in 16-bit words pass value_shift=4"
        )
    counts = data.raw_frame_count
    freqs = _per_frame(data.modulation_frequencies_hz, counts, n, "modulation frequencies")
    exposures = (
        _per_frame(data.exposure_times_us, counts, n, "exposure times")
        if data.exposure_times_us
        else [0] * n
    )
    grey, grey_source = _grey_index(data, n)
    phase_idx = [i for i in range(n) if i != grey]
    sets: list[list[int]] = []
    for i in phase_idx:
        if sets and len(sets[-1]) < N_PHASES:
            if freqs[i] != freqs[sets[-1][0]]:
                raise RoyaleDataError(
                    f"raw frame {i} at {freqs[i]} Hz inside a four-phase set at "
                    f"{freqs[sets[-1][0]]} Hz (frequencies per frame: {freqs})"
                )
            sets[-1].append(i)
        else:
            sets.append([i])
    if len(data.phase_angles_deg) == n:
        ordered = []
        for s in sets:
            angles = [data.phase_angles_deg[i] % 360 for i in s]
            if sorted(angles) != [0, 90, 180, 270]:
                raise RoyaleDataError(
                    f"phase angles {angles} deg of raw frames {s}; expected 0, 90, 180, 270"
                )
            ordered.append([i for _, i in sorted(zip(angles, s, strict=True))])
        sets = ordered
    set_freqs = tuple(float(freqs[s[0]]) for s in sets)
    uc = None if use_case is None else get_use_case(use_case)
    if uc is not None and (
        len(set_freqs) != uc.n_frequencies
        or any(abs(a - b) > 1.0 for a, b in zip(set_freqs, uc.frequencies_hz, strict=False))
    ):
        raise RoyaleDataError(
            f"frequencies {list(set_freqs)} Hz do not match use case {uc.name} "
            f"({list(uc.frequencies_hz)} Hz)"
        )
    phases = words[np.array(sets)]  # (n_f, 4, H, W)
    grey_img = words[grey]
    saturated = np.any((phases == 0) | (phases == MAX_RAW), axis=(0, 1)) | (grey_img == MAX_RAW)
    if data.timestamp_us is not None:
        stamp, stamp_source = data.timestamp_us * 1e-6, "royale"
    else:
        stamp = time.time() if timestamp_s is None else timestamp_s
        stamp_source = "host"
    info: dict[str, Any] = {
        "backend": "royale",
        "use_case": uc.name if uc else None,
        "grey_index": grey,
        "grey_index_source": grey_source,
        "exposure_times_us": [exposures[s[0]] for s in sets],
        "grey_exposure_us": exposures[grey],
        "exposure_group_names": list(data.exposure_group_names),
        "illumination_temperature_c": data.illumination_temperature_c,
        "timestamp_source": stamp_source,
        "stream_id": data.stream_id,
    }
    info.update(meta or {})
    exposure_us = exposures[sets[0][0]] or (uc.exposure_us if uc else 0)
    return RawFrame(
        phase_images=phases.astype(np.float32) - np.float32(RAW_OFFSET),
        intensity=grey_img.astype(np.float32),
        frequencies_hz=np.asarray(set_freqs, dtype=np.float64),
        saturated=saturated,
        sbi_limit=np.zeros(grey_img.shape, dtype=bool),
        exposure_s=exposure_us * 1e-6,
        timestamp_s=stamp,
        meta=info,
        illumination_temperature_c=data.illumination_temperature_c,
    )




def raw_frame_to_royale(raw: RawFrame, use_case: str | UseCase, *, grey_last: bool = False,
                        timestamp_us: int | None = None) -> RawDataCopy:
    """The raw data royale would give for ``raw`` (the inverse of :func:`royale_to_raw_frame`
    up to the 12-bit quantisation of :func:`drivers.camera.wire.raw_to_wire_values`).

    One exposure group of four phase frames (0, 90, 180, 270 deg) per modulation frequency, in
    the use case's order, and the grey frame (illumination off) first or, with ``grey_last``,
    last; frequencies and exposure times per exposure group. The simulated camera behind the
    camera bridge (:mod:`drivers.sim.bridge_source`) serves its frames so.

    >>> from drivers.camera.wire import USE_CASES
    >>> uc = USE_CASES["MODE_5_45FPS_500"]
    >>> frame = RawFrame(np.zeros((1, 4, 2, 3), np.float32), np.full((2, 3), 7.0, np.float32),
    ...                  np.array(uc.frequencies_hz), np.zeros((2, 3), bool),
    ...                  np.zeros((2, 3), bool), uc.exposure_s)
    >>> copy = raw_frame_to_royale(frame, uc)
    >>> copy.raw_frame_count, copy.phase_angles_deg, int(copy.raw_frames[0, 0, 0])
    ((1, 4), (0, 0, 90, 180, 270), 7)
    >>> np.array_equal(royale_to_raw_frame(copy, use_case=uc).phase_images, frame.phase_images)
    True
    """
    uc = get_use_case(use_case)
    grey, phases = raw_to_wire_values(raw)
    n_f, height, width = phases.shape[0], grey.shape[0], grey.shape[1]
    groups = [(f"mod{k}", phases[k], int(uc.frequencies_hz[k]), 1) for k in range(n_f)]
    grey_group = ("gray", grey[None], int(uc.frequencies_hz[-1]), 0)
    groups = [*groups, grey_group] if grey_last else [grey_group, *groups]
    exposure_us = round(raw.exposure_s * 1e6)
    stamp = timestamp_us if timestamp_us is not None else (
        int(raw.timestamp_s * 1e6) if raw.timestamp_s > 0 else None)
    return RawDataCopy(
        width=width, height=height,
        raw_frames=np.concatenate([frames for _, frames, _, _ in groups]).astype(np.uint16),
        modulation_frequencies_hz=tuple(f for _, _, f, _ in groups),
        exposure_times_us=(exposure_us,) * len(groups),
        raw_frame_count=tuple(len(frames) for _, frames, _, _ in groups),
        exposure_group_names=tuple(name for name, _, _, _ in groups),
        phase_angles_deg=tuple(a for _, frames, _, on in groups
                               for a in ((0, 90, 180, 270) if on else (0,))),
        illumination_enabled=tuple(on for _, frames, _, on in groups for _ in range(len(frames))),
        timestamp_us=stamp,
        illumination_temperature_c=raw.illumination_temperature_c,
    )


def royale_depth_to_frame(
    data: DepthDataCopy,
    *,
    use_case: str | UseCase,
    timestamp_s: float | None = None,
    meta: dict[str, Any] | None = None,
) -> ProcessedDepthFrame:
    """One copy of royale's processed depth as a
    :class:`~sim_core.processed_depth.ProcessedDepthFrame` of ``use_case`` (whose frequencies
    and exposure it carries: royale's depth data does not say them).

    Raises
    ------
    RoyaleDataError
        Points of another shape than the copy's width and height, or the use case's image size.
    """
    uc = get_use_case(use_case)
    points = np.asarray(data.points, dtype=np.float32)
    if points.shape != (data.height, data.width, len(DEPTH_CHANNELS)):
        raise RoyaleDataError(f"depth points of shape {points.shape}; expected ({data.height}, "
                              f"{data.width}, {len(DEPTH_CHANNELS)})")
    if (data.height, data.width) != uc.shape:
        raise RoyaleDataError(f"depth data of {data.width} x {data.height} px; use case "
                              f"{uc.name} is {uc.width} x {uc.height}")
    if data.timestamp_us is not None:
        stamp, stamp_source = data.timestamp_us * 1e-6, "royale"
    else:
        stamp = time.time() if timestamp_s is None else timestamp_s
        stamp_source = "host"
    info: dict[str, Any] = {"backend": "royale", "camera_data": "depth", "use_case": uc.name,
                            "exposure_times_us": list(data.exposure_times_us),
                            "illumination_temperature_c": data.illumination_temperature_c,
                            "timestamp_source": stamp_source, "stream_id": data.stream_id}
    info.update(meta or {})
    exposure_us = data.exposure_times_us[0] if data.exposure_times_us else uc.exposure_us
    channels = [points[..., k].copy() for k in range(len(DEPTH_CHANNELS))]
    return ProcessedDepthFrame(
        *channels, frequencies_hz=np.asarray(uc.frequencies_hz, dtype=np.float64),
        exposure_s=exposure_us * 1e-6, timestamp_s=stamp, meta=info,
        illumination_temperature_c=data.illumination_temperature_c)


def raw_frame_to_royale_depth(raw: RawFrame, intrinsics: Any, *,
                              timestamp_us: int | None = None) -> DepthDataCopy:
    """The processed depth royale would give for ``raw`` seen through ``intrinsics``
    (:class:`sim_core.camera.Intrinsics`): our reconstruction's z-depth, each pixel's point on
    its undistorted ray, royale 4's channels (the amplitude as the noise-free grey value, no
    noise estimate: NaN), confidence 1 where valid. The simulated camera behind the camera
    bridge serves its depth mode so."""
    from sim_core.camera import pixel_centre_grid, pixel_to_camera_direction, z_over_range

    image = reconstruct_raw(raw, z_over_range(intrinsics))
    rays = pixel_to_camera_direction(intrinsics, *pixel_centre_grid(intrinsics)).reshape(
        *intrinsics.shape, 3)  # unit directions in the camera frame
    z = image.depth_z_m
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = z / rays[..., 2]
    points = np.stack([rays[..., 0] * scale, rays[..., 1] * scale, z,
                       np.full(z.shape, np.nan), image.amplitude,
                       image.valid.astype(np.float64)], axis=-1).astype(np.float32)
    points[~image.valid, :3] = 0.0  # royale's invalid points are zeros with confidence 0
    stamp = timestamp_us if timestamp_us is not None else (
        int(raw.timestamp_s * 1e6) if raw.timestamp_s > 0 else None)
    return DepthDataCopy(width=z.shape[1], height=z.shape[0], points=points,
                         exposure_times_us=(round(raw.exposure_s * 1e6),),
                         timestamp_us=stamp,
                         illumination_temperature_c=raw.illumination_temperature_c)
