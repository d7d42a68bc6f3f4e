"""The frame format: the one module that writes and reads frame folders (docs/frame-format.md).

A frame folder holds, for a measured and a simulated frame alike:

- ``frame.npz``: the reconstruction (:data:`IMAGE_ARRAYS`), plus for a simulated frame the
  rendered light field and ground truth (:data:`LIGHT_FIELD_ARRAYS`); units in
  :data:`ARRAY_UNITS`;
- ``frame.json``: metadata (strict JSON, sorted keys; keys in docs/frame-format.md);
- ``raw.npz``: the four-phase raw frame (:func:`write_raw`) - always for a measured frame, for a
  simulated one only with a non-ideal sensor;
- ``grey.png`` (8 bit, :func:`grey_preview_8bit` at the frame's grey full scale) and
  ``depth.png`` (16 bit millimetres, :func:`depth_preview_mm`).

The grey full scale (amplitude shown as grey 255) is a property of the frame, chosen by
:func:`grey_full_scale` and recorded in ``frame.json`` as ``grey_preview_full_scale``; every
stored grey image of the frame (the PNG, the ``grey_8bit`` array) and the service's comparison
metrics use it. Pictures for people (``toftwin preview``, the report's and the operator page's
panels) stretch the amplitude to its own percentiles instead (:mod:`sim_core.preview`): at the
fixed full scale a dim scene is black to the eye.

Every file is written to a temporary name in the target directory and renamed into place, so a
reader never sees a half-written file and a crash leaves at most a stray ``*.tmp``.
"""

from __future__ import annotations

import json
import struct
import zipfile
import zlib
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any, Literal

import numpy as np
from PIL import Image

from sim_core.camera import CAMERA_PRESETS, Camera, Intrinsics
from sim_core.errors import InvalidInputError
from sim_core.files import StructuredFileError, atomic_write, load_structured
from sim_core.json_safe import json_safe
from sim_core.processed_depth import ProcessedDepthFrame, camera_data, measured_image
from sim_core.raw import RawFrame, ValidityThresholds, reconstruct_raw
from sim_core.sensor import SensorParams
from sim_core.tof import ToFImage

# -- file names ------------------------------------------------------------------------------
FRAME_NPZ = "frame.npz"
FRAME_JSON = "frame.json"
RAW_NPZ = "raw.npz"
#: a measured frame of royale's processed depth (:class:`~sim_core.processed_depth.
#: ProcessedDepthFrame`) keeps it here instead of ``raw.npz``
DEPTH_POINTS_NPZ = "depth_points.npz"
GREY_PNG = "grey.png"
DEPTH_PNG = "depth.png"
#: the files of a frame folder (simulated, or measured from raw frames; a measured frame of
#: royale's processed depth has ``depth_points.npz`` instead of ``raw.npz``)
FRAME_FILES = (FRAME_NPZ, FRAME_JSON, GREY_PNG, DEPTH_PNG, RAW_NPZ)

#: what reading a damaged frame file (npz, JSON or PNG) raises: a truncated or corrupt archive,
#: JSON out of its form, a PNG whose chunks do not check
FRAME_READ_ERRORS = (OSError, EOFError, ValueError, KeyError, zipfile.BadZipFile, zlib.error,
                     InvalidInputError, SyntaxError, struct.error)

FrameKind = Literal["measured", "simulated"]
FRAME_KINDS: tuple[FrameKind, ...] = ("measured", "simulated")

# -- arrays ----------------------------------------------------------------------------------
#: what each ``frame.npz`` array holds, written into frame.json (``arrays``)
ARRAY_UNITS = {
    "range_m": "m, radial; NaN where not valid",
    "depth_z_m": "m, along the optical axis; NaN where not valid",
    "amplitude": "DN, seed eq. 5 (ideal sensor: W m^-2 sr^-1, |phasor| of the first frequency)",
    "intensity": "DN, mean tap sum, seed eq. 6 (ideal sensor: W m^-2 sr^-1, DC)",
    "grey_8bit": "uint8 grey image in the camera tools' convention (see grey_full_scale)",
    "depth_mm": "uint16 radial range in millimetres, 0 where not valid",
    "phase_rad": "rad in [0, 2 pi), first frequency",
    "phase_all_rad": "rad in [0, 2 pi), (n_f, H, W)",
    "valid": "bool",
    "frequencies_hz": "Hz",
    "phasor": "W m^-2 sr^-1, complex, (n_f, H, W)",
    "dc_active": "W m^-2 sr^-1",
    "dc_ambient": "W m^-2 sr^-1",
    "truth_range_m": "m, radial, pixel-centre ray; NaN where nothing is hit",
    "truth_depth_z_m": "m, along the optical axis; NaN where nothing is hit",
    "object_id": "index into objects of the scene, -1 for none",
    "hit": "bool",
}
#: arrays of every frame (the reconstruction and its previews)
IMAGE_ARRAYS = (
    "grey_8bit", "depth_mm", "range_m", "depth_z_m", "amplitude", "intensity", "phase_rad",
    "phase_all_rad", "valid", "frequencies_hz",
)
#: arrays of a simulated frame only (rendered light field and ground truth)
LIGHT_FIELD_ARRAYS = (
    "phasor", "dc_active", "dc_ambient", "truth_range_m", "truth_depth_z_m", "object_id", "hit",
)
#: arrays of ``raw.npz`` (``taps`` only where the source exposes them), plus ``meta_json``
RAW_ARRAYS = ("phase_images", "intensity", "frequencies_hz", "saturated", "sbi_limit", "taps")

# -- grey and depth previews -----------------------------------------------------------------
GREY_FULL_SCALE_PERCENTILE = 99.5
"""Percentile of the valid amplitude used as grey full scale where the amplitude has no DN."""


def package_version() -> str:
    """The toftwin version written into ``frame.json`` (``package_version``)."""
    try:
        return metadata.version("toftwin")
    except metadata.PackageNotFoundError:  # running from a source tree without install
        return "0+unknown"


def grey_full_scale(amplitude: np.ndarray, valid: np.ndarray, adc_bits: int | None) -> float:
    """The amplitude a frame shows as grey 255 (the rule of docs/frame-format.md).

    A frame read out by a sensor (measured, or simulated with a non-ideal sensor) has its
    amplitude in DN: its full scale is fixed by the ADC, ``2 ** (adc_bits - 1)`` DN, so grey
    levels of frames from the same sensor are comparable whatever the scene, pose or mask.
    An ideal-sensor frame (``adc_bits`` None) has radiance units and no natural scale: the
    99.5th percentile of its valid, finite amplitude (0 when there is none: an all-black image).
    """
    if adc_bits is not None:
        return float(2 ** (int(adc_bits) - 1))
    value = np.asarray(amplitude)
    sel = value[np.asarray(valid, dtype=bool) & np.isfinite(value)]
    return float(np.percentile(sel, GREY_FULL_SCALE_PERCENTILE)) if sel.size else 0.0


def sensor_adc_bits(raw: RawFrame | None) -> int | None:
    """ADC bits of the sensor behind ``raw`` (None: no raw frame, an ideal sensor).

    From the raw frame's ``meta["sensor"]`` where the source records it (the simulator does),
    else the default sensor's (:class:`~sim_core.sensor.SensorParams`).
    """
    if raw is None:
        return None
    sensor = raw.meta.get("sensor") or {}
    return int(sensor.get("adc_bits", SensorParams().adc_bits))


def grey_preview_8bit(value: np.ndarray, valid: np.ndarray, full_scale: float | None = None):
    """8-bit grey image ``round(value / full_scale * 255)`` clipped to [0, 255], 0 where not
    finite; full scale None: the percentile rule of :func:`grey_full_scale` (no ADC).

    Returns the image and the full scale used (an all-black image and 0 for a full scale <= 0).
    """
    if full_scale is None:
        full_scale = grey_full_scale(value, valid, None)
    if not full_scale > 0.0:
        return np.zeros(value.shape, dtype=np.uint8), 0.0
    g = np.where(np.isfinite(value), value, 0.0) / full_scale * 255.0
    return np.clip(np.round(g), 0, 255).astype(np.uint8), full_scale


def depth_preview_mm(range_m: np.ndarray) -> np.ndarray:
    """16-bit depth image in millimetres, 0 where invalid (the camera tools' convention)."""
    mm = np.where(np.isfinite(range_m), np.round(range_m * 1000.0), 0.0)
    return np.clip(mm, 0, 65535).astype(np.uint16)


def image_arrays(image: ToFImage, full_scale: float) -> dict[str, np.ndarray]:
    """The :data:`IMAGE_ARRAYS` of ``frame.npz`` for a reconstruction."""
    grey, _ = grey_preview_8bit(image.amplitude, image.valid, full_scale)
    return {
        "grey_8bit": grey,
        "depth_mm": depth_preview_mm(image.range_m),
        "range_m": image.range_m,
        "depth_z_m": image.depth_z_m,
        "amplitude": image.amplitude,
        "intensity": image.intensity,
        "phase_rad": image.phase_rad[0],
        "phase_all_rad": image.phase_rad,
        "valid": image.valid,
        "frequencies_hz": image.frequencies_hz,
    }


def image_from_arrays(arrays: dict[str, np.ndarray]) -> ToFImage:
    """A :class:`ToFImage` from the arrays of a ``frame.npz``."""
    phase = arrays.get("phase_all_rad", arrays["phase_rad"][None])
    return ToFImage(
        range_m=arrays["range_m"],
        depth_z_m=arrays["depth_z_m"],
        amplitude=arrays["amplitude"],
        intensity=arrays["intensity"],
        phase_rad=phase,
        valid=arrays["valid"].astype(bool),
        frequencies_hz=arrays["frequencies_hz"],
    )


# -- intrinsics in frame.json ----------------------------------------------------------------
def intrinsics_dict(intr: Intrinsics) -> dict[str, Any]:
    """``frame.json`` ``intrinsics`` of a measured frame."""
    return {
        "width_px": intr.width_px, "height_px": intr.height_px, "fx_px": intr.fx_px,
        "fy_px": intr.fy_px, "cx_px": intr.cx_px, "cy_px": intr.cy_px,
        "distortion": list(intr.distortion),
    }


def intrinsics_from_meta(meta: dict, shape: tuple[int, int]) -> Intrinsics:
    """The intrinsics a frame was reconstructed (measured) or rendered (simulated) with.

    Without ``intrinsics`` in ``frame.json`` (a measured frame of an old version, a simulated
    frame written before they were recorded): the pico flexx preset's focal lengths with the
    principal point at the image centre (:func:`intrinsics_known` says which). Keys that are
    there are checked as :class:`sim_core.frame_meta.FrameIntrinsics` states them.

    Raises
    ------
    InvalidInputError
        ``frame.json``: intrinsics with a missing key or a value out of its range.
    """
    if "intrinsics" in meta:
        from pydantic import ValidationError

        from sim_core.frame_meta import FrameIntrinsics

        try:
            i = FrameIntrinsics.model_validate(meta["intrinsics"])
        except ValidationError as exc:
            e = exc.errors()[0]
            where = ".".join(str(p) for p in e["loc"])
            raise InvalidInputError("frame.json", f"intrinsics.{where}: {e['msg']}") from None
        return Intrinsics(i.width_px, i.height_px, i.fx_px, i.fy_px, i.cx_px, i.cy_px,
                          tuple(i.distortion))
    p = CAMERA_PRESETS["pmd-camboard-pico-flexx"]
    h, w = shape
    return Intrinsics(w, h, p["fx_px"], p["fy_px"], (w - 1) / 2.0, (h - 1) / 2.0)


def intrinsics_known(meta: dict) -> bool:
    """Whether ``frame.json`` records the frame's intrinsics (else :func:`intrinsics_from_meta`
    falls back to the preset's)."""
    return "intrinsics" in meta


def image_intrinsics(meta: dict, shape: tuple[int, int]) -> Intrinsics:
    """:func:`intrinsics_from_meta` of a frame whose image is ``shape`` (H, W): its size must be
    the image's (else an input error naming ``frame.json``)."""
    intr = intrinsics_from_meta(meta, shape)
    if intr.shape != tuple(shape):
        raise InvalidInputError("frame.json", f"intrinsics of a {intr.width_px} x "
                                f"{intr.height_px} image, but the frame is {shape[1]} x "
                                f"{shape[0]}")
    return intr


#: how far a pose's rotation may be from orthonormal (rounding of a written matrix)
POSE_TOLERANCE = 1e-6


def pose_from_meta(meta: dict) -> np.ndarray | None:
    """``world_from_camera`` (4 x 4) of a frame.json: the rigid transform from the camera frame
    to the scene's world; None where the frame does not record it (its pose is not known).

    Raises
    ------
    InvalidInputError
        ``frame.json``: a ``world_from_camera`` that is not a finite rigid 4 x 4 transform
        (rotation orthonormal within :data:`POSE_TOLERANCE`, last row 0 0 0 1).
    """
    m = meta.get("world_from_camera")
    if m is None:
        return None
    try:
        a = np.asarray(m, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.zeros(0)
    ok = a.shape == (4, 4) and bool(np.all(np.isfinite(a)))
    if ok:
        r = a[:3, :3]
        with np.errstate(over="ignore", invalid="ignore"):  # a huge entry: inf, not rigid
            gram = r.T @ r
        ok = (np.allclose(gram, np.eye(3), rtol=0, atol=POSE_TOLERANCE)
              and np.allclose(a[3], [0.0, 0.0, 0.0, 1.0], rtol=0, atol=POSE_TOLERANCE))
    if not ok:
        raise InvalidInputError("frame.json", "world_from_camera is not a finite rigid 4 x 4 "
                                "transform (orthonormal rotation, last row 0 0 0 1)")
    return a


# -- atomic files ----------------------------------------------------------------------------
def _atomic_write(path: Path, write) -> None:
    atomic_write(path, write)


#: zlib level of the frame files' compression (``.npz`` and PNG). Level 1 writes a frame's
#: arrays 2-6 times faster than the default 6 (numpy's ``savez_compressed``, PIL's PNG) and
#: makes the files 3-14 % larger (a 224 x 171 frame.npz: 66 against 119 ms, 2.50 against
#: 2.44 MB; raw.npz: 29 against 163 ms, 0.68 against 0.60 MB; the 16-bit depth PNG: 3 against
#: 32 ms, 55 against 53 kB): in a campaign the files were the larger part of a pose after the
#: renders. Readers are unaffected (any level inflates alike).
COMPRESS_LEVEL = 1


#: bytes of an array's middle :func:`_deflates` compresses to decide whether its member is worth
#: deflating (8 KiB: about 0.3 ms at level 1, against 13-26 ms for a whole noisy float image)
COMPRESS_SAMPLE_BYTES = 8192
#: a member is stored, not deflated, when its sample keeps more than this share of its size:
#: a rendered frame's ``phasor`` and ``dc_active`` (Monte Carlo noise in every mantissa) keep
#: 0.94-0.95 and took 39 of a frame.npz's 63 ms to compress
STORE_ABOVE_RATIO = 0.9


def _deflates(a: np.ndarray) -> bool:
    """Whether deflating ``a`` pays: its middle :data:`COMPRESS_SAMPLE_BYTES` compress to at
    most :data:`STORE_ABOVE_RATIO` of their size (small arrays always deflate)."""
    if a.nbytes <= 2 * COMPRESS_SAMPLE_BYTES:
        return True
    data = np.ascontiguousarray(a).reshape(-1).view(np.uint8)
    start = (data.size - COMPRESS_SAMPLE_BYTES) // 2
    sample = data[start:start + COMPRESS_SAMPLE_BYTES].tobytes()
    return len(zlib.compress(sample, COMPRESS_LEVEL)) <= STORE_ABOVE_RATIO * len(sample)


def _savez(fh, arrays: dict[str, np.ndarray]) -> None:
    """``np.savez_compressed`` at :data:`COMPRESS_LEVEL`: one ``NAME.npy`` member per array, as
    ``np.load`` reads it; a member that would not shrink (:func:`_deflates`) is stored."""
    with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_DEFLATED,
                         compresslevel=COMPRESS_LEVEL) as zf:
        for name, value in arrays.items():
            a = np.asanyarray(value)
            # ZipFile.open(name, "w") takes the member's method from the archive's
            zf.compression = (zipfile.ZIP_DEFLATED if a.dtype.hasobject or _deflates(a)
                              else zipfile.ZIP_STORED)
            with zf.open(f"{name}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, a, allow_pickle=False)


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write arrays (compressed, :data:`COMPRESS_LEVEL`, where it pays: :func:`_savez`)
    atomically."""
    _atomic_write(Path(path), lambda fh: _savez(fh, arrays))


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write strict JSON atomically (sorted keys, 2-space indent; :func:`json_safe`)."""
    text = json.dumps(json_safe(data), indent=2, sort_keys=True, allow_nan=False).encode()
    _atomic_write(Path(path), lambda fh: fh.write(text))


def write_png(path: Path, image: np.ndarray) -> None:
    """Write a uint8 (8-bit grey) or uint16 (16-bit grey) image as PNG atomically."""
    if image.dtype not in (np.uint8, np.uint16):
        raise TypeError(f"PNG previews must be uint8 or uint16, got {image.dtype}")
    img = Image.fromarray(np.ascontiguousarray(image))
    _atomic_write(Path(path), lambda fh: img.save(fh, format="PNG",
                                                  compress_level=COMPRESS_LEVEL))


# -- raw.npz ---------------------------------------------------------------------------------
def write_raw(path: str | Path, raw: RawFrame) -> None:
    """Write ``raw.npz``: :data:`RAW_ARRAYS` and the metadata as JSON (``meta_json``)."""
    arrays = {
        "phase_images": raw.phase_images,
        "intensity": raw.intensity,
        "frequencies_hz": raw.frequencies_hz,
        "saturated": raw.saturated,
        "sbi_limit": raw.sbi_limit,
        "meta_json": _meta_json(raw),
    }
    if raw.taps is not None:
        arrays["taps"] = raw.taps
    write_npz(Path(path), arrays)


def read_raw(path: str | Path) -> RawFrame:
    """Read a ``raw.npz`` written by :func:`write_raw`."""
    with np.load(path) as z:
        return RawFrame(
            phase_images=z["phase_images"], intensity=z["intensity"],
            frequencies_hz=z["frequencies_hz"], saturated=z["saturated"],
            sbi_limit=z["sbi_limit"], taps=z["taps"] if "taps" in z.files else None,
            **_frame_fields(z["meta_json"]))


def _meta_json(frame: RawFrame | ProcessedDepthFrame) -> np.ndarray:
    """A measured frame's exposure, timestamp, temperature and metadata as one JSON string
    (``meta_json`` of ``raw.npz`` and ``depth_points.npz``)."""
    return np.array(json.dumps(json_safe(
        {"exposure_s": frame.exposure_s, "timestamp_s": frame.timestamp_s, **frame.meta,
         **_temperature_meta(frame)}), allow_nan=False))


def _frame_fields(meta_json: np.ndarray) -> dict[str, Any]:
    """The frame fields :func:`_meta_json` wrote (``exposure_s``, ``timestamp_s``, ``meta``,
    ``illumination_temperature_c``)."""
    meta = json.loads(str(meta_json))
    temperature = meta.pop(TEMPERATURE_KEY, None)
    return {"exposure_s": float(meta.pop("exposure_s")),
            "timestamp_s": float(meta.pop("timestamp_s")), "meta": meta,
            "illumination_temperature_c": None if temperature is None else float(temperature)}


#: the metadata key of a frame's reported illumination temperature [degC] (raw.npz, frame.json)
TEMPERATURE_KEY = "illumination_temperature_c"


#: the per-pixel arrays of ``depth_points.npz`` (a :class:`ProcessedDepthFrame`'s)
DEPTH_POINT_ARRAYS = ("x_m", "y_m", "z_m", "noise_m", "grey", "confidence")


def write_depth_points(path: str | Path, frame: ProcessedDepthFrame) -> None:
    """Write ``depth_points.npz``: royale's processed depth as the camera gave it
    (:data:`DEPTH_POINT_ARRAYS`, ``frequencies_hz``, the metadata as JSON)."""
    arrays = {name: getattr(frame, name) for name in DEPTH_POINT_ARRAYS}
    arrays["frequencies_hz"] = frame.frequencies_hz
    arrays["meta_json"] = _meta_json(frame)
    write_npz(Path(path), arrays)


def read_depth_points(path: str | Path) -> ProcessedDepthFrame:
    """Read a ``depth_points.npz`` written by :func:`write_depth_points`."""
    with np.load(path) as z:
        return ProcessedDepthFrame(
            *(z[name] for name in DEPTH_POINT_ARRAYS), frequencies_hz=z["frequencies_hz"],
            **_frame_fields(z["meta_json"]))


def _temperature_meta(raw: RawFrame | ProcessedDepthFrame) -> dict[str, float]:
    """``{TEMPERATURE_KEY: T}`` when the frame reports its illumination temperature, else {}."""
    t = raw.illumination_temperature_c
    return {} if t is None else {TEMPERATURE_KEY: float(t)}


# -- writing frame folders -------------------------------------------------------------------
def _write_image_files(out: Path, arrays: dict[str, np.ndarray], meta: dict) -> None:
    write_npz(out / FRAME_NPZ, arrays)
    write_png(out / DEPTH_PNG, arrays["depth_mm"])
    write_png(out / GREY_PNG, arrays["grey_8bit"])
    write_json(out / FRAME_JSON, meta)


def write_simulated(out_dir: str | Path, frame: Any, scene_name: str = "") -> Path:
    """Write a simulated frame folder: ``frame.npz``, ``frame.json``, the PNGs and, with a
    non-ideal sensor, ``raw.npz``.

    ``frame`` is a :class:`sim_core.pipeline.SimulatedFrame` (not imported: the pipeline
    imports this module).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    im, lf = frame.image, frame.light_field
    full_scale = frame.grey_full_scale
    if full_scale is None:
        full_scale = grey_full_scale(im.amplitude, im.valid, sensor_adc_bits(frame.raw))
    arrays = {
        **image_arrays(im, full_scale),
        "phasor": lf.phasor,
        "dc_active": lf.dc_active,
        "dc_ambient": lf.dc_ambient,
        "truth_range_m": lf.truth_range_m,
        "truth_depth_z_m": lf.truth_depth_z_m,
        "object_id": lf.object_id,
        "hit": lf.hit,
    }
    # the image arrays' frequencies are the light field's (the same values)
    arrays["frequencies_hz"] = lf.frequencies_hz
    if frame.raw is not None:
        write_raw(out / RAW_NPZ, frame.raw)
    s = frame.settings
    meta = {
        "scene_name": scene_name,
        "scene_hash": frame.scene_hash,
        "calibration_hash": getattr(frame, "calibration_hash", None),
        "package_version": package_version(),
        "ideal_sensor": frame.ideal,
        "settings": {
            "integrator": s.integrator,
            "spp": s.spp,
            "max_bounces": s.max_bounces,
            "effective_bounces": s.effective_bounces,
            "seed": s.seed,
            "russian_roulette_from_bounce": s.russian_roulette_from_bounce,
            "threads": s.threads,
        },
        "timings_s": frame.timings_s,
        "rays_traced": frame.rays_traced,
        "embree_share": frame.embree_share,
        "render_thread_seconds": frame.render_thread_seconds,
        "shape": list(im.range_m.shape),
        "frequencies_hz": lf.frequencies_hz.tolist(),
        "grey_preview_full_scale": full_scale if full_scale > 0.0 else 0.0,
        "arrays": ARRAY_UNITS,
        "effect_plan": frame.plan.to_dict(),
        **_adaptive_meta(frame),
        "sensor": None if frame.raw is None else frame.raw.meta.get("sensor"),
        **_camera_meta(frame),
        **frame.extra,
    }
    _write_image_files(out, arrays, meta)
    return out


def _camera_meta(frame: Any) -> dict:
    """``intrinsics`` and ``world_from_camera`` (4 x 4 nested lists, camera frame to the
    scene's world, metres) of a simulated frame, where it carries them."""
    out: dict[str, Any] = {}
    if getattr(frame, "intrinsics", None) is not None:
        out["intrinsics"] = intrinsics_dict(frame.intrinsics)
    if getattr(frame, "world_from_camera", None) is not None:
        out["world_from_camera"] = np.asarray(frame.world_from_camera, dtype=float).tolist()
    return out


def _adaptive_meta(frame: Any) -> dict:
    report = frame.adaptive
    if report is None:
        return {}
    return {
        "adaptive": report.to_dict(),
        "achieved_range_error_mm": report.achieved_range_error_mm,
        "seconds": report.seconds,
    }


def write_measured(
    out_dir: str | Path, raw: RawFrame | ProcessedDepthFrame, camera: Camera,
    extra: dict[str, Any],
) -> tuple[ToFImage, float]:
    """Reconstruct ``raw`` with ``camera``'s intrinsics and write a measured frame folder.

    royale's processed depth (a :class:`~sim_core.processed_depth.ProcessedDepthFrame`) is kept
    as ``depth_points.npz`` instead of ``raw.npz``, its image is its own (royale's z, its grey
    scaled by its 99.5th percentile: no ADC scale is known), and ``frame.json`` says
    ``camera_data``.

    ``raw.npz`` as the camera delivered it, ``frame.npz``/``frame.json``/PNGs of its
    reconstruction (:func:`~sim_core.raw.reconstruct_raw`); ``extra`` goes into ``frame.json``.
    Returns the reconstruction and its grey full scale.
    """
    frame = measured_frame(raw, camera, extra)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if isinstance(raw, ProcessedDepthFrame):
        write_depth_points(out / DEPTH_POINTS_NPZ, raw)
    else:
        write_raw(out / RAW_NPZ, raw)
    _write_image_files(out, frame.arrays, frame.meta)
    return frame.image, frame.grey_full_scale


def measured_frame(
    raw: RawFrame | ProcessedDepthFrame, camera: Camera, extra: dict[str, Any],
) -> Frame:
    """A measured frame as :func:`write_measured` writes it and :func:`read_measured` reads it
    back, without a folder: ``raw`` reconstructed with ``camera``'s intrinsics, the arrays of
    ``frame.npz`` and the ``frame.json`` (``extra`` merged in)."""
    from sim_core.camera import z_over_range

    if raw.shape != camera.intrinsics.shape:
        raise ValueError(
            f"measured frame is {raw.shape}, the camera model {camera.intrinsics.shape}"
        )
    image = measured_image(raw, z_over_range(camera.intrinsics))
    depth = isinstance(raw, ProcessedDepthFrame)  # royale's own grey: no ADC scale known
    full_scale = grey_full_scale(image.amplitude, image.valid,
                                 None if depth else sensor_adc_bits(raw))
    arrays = image_arrays(image, full_scale)
    meta = {
        "kind": "measured",
        "camera_data": camera_data(raw),
        "package_version": package_version(),
        "shape": list(image.range_m.shape),
        "frequencies_hz": image.frequencies_hz.tolist(),
        "exposure_s": raw.exposure_s,
        "timestamp_s": raw.timestamp_s,
        "grey_preview_full_scale": full_scale,
        "intrinsics": intrinsics_dict(camera.intrinsics),
        "validity": ("royale's depth confidence > 0" if depth else
                     ValidityThresholds().to_dict()),
        "camera_meta": raw.meta,
        **_temperature_meta(raw),
        "arrays": {k: ARRAY_UNITS[k] for k in arrays},
        **extra,
    }
    return Frame("measured", image, arrays, json.loads(json.dumps(json_safe(meta))),
                 full_scale, None if depth else raw)


# -- reading frame folders -------------------------------------------------------------------
@dataclass(frozen=True)
class Frame:
    """A frame folder read back (:func:`read_frame`).

    Attributes
    ----------
    kind : "measured" or "simulated"
    image : ToFImage
        The reconstruction (a measured frame's is recomputed from ``raw.npz``).
    arrays : dict
        ``frame.npz`` (empty for a measured folder holding only ``raw.npz``).
    meta : dict
        ``frame.json`` (empty when the folder has none).
    grey_full_scale : float
        Amplitude shown as grey 255 (``grey_preview_full_scale``, else :func:`grey_full_scale`).
    raw : RawFrame or None
        ``raw.npz`` where the folder has one.
    """

    kind: FrameKind
    image: ToFImage
    arrays: dict[str, np.ndarray]
    meta: dict[str, Any]
    grey_full_scale: float
    raw: RawFrame | None = None

    def grey_8bit(self) -> np.ndarray:
        """The frame's grey image (``grey.png``), at its grey full scale."""
        img, _ = grey_preview_8bit(self.image.amplitude, self.image.valid, self.grey_full_scale)
        return img


def _read_meta(d: Path) -> dict:
    p = d / FRAME_JSON
    if not p.is_file():
        return {}
    try:
        meta = load_structured(p, json_only=True)
    except StructuredFileError as exc:
        raise InvalidInputError("frame.json", str(exc)) from None
    if not isinstance(meta, dict):
        raise InvalidInputError("frame.json", f"{p} holds no JSON object")
    return meta


def _read_arrays(d: Path) -> dict[str, np.ndarray]:
    with np.load(d / FRAME_NPZ) as z:
        return {k: z[k] for k in z.files}


def _recorded_full_scale(meta: dict) -> float | None:
    fs = meta.get("grey_preview_full_scale")
    return float(fs) if isinstance(fs, int | float) and np.isfinite(fs) else None


def read_measured(directory: str | Path) -> Frame:
    """A measured frame folder: ``raw.npz`` reconstructed with ``frame.json``'s intrinsics."""
    from sim_core.camera import z_over_range

    d = Path(directory)
    if not (d / RAW_NPZ).is_file() and (d / DEPTH_POINTS_NPZ).is_file():
        return _read_measured_depth(d)
    if not (d / RAW_NPZ).is_file():
        raise InvalidInputError("measured_dir", f"'{d}' holds no raw.npz (a measured frame)")
    raw = read_raw(d / RAW_NPZ)
    meta = _read_meta(d)
    intr = intrinsics_from_meta(meta, raw.shape)
    if intr.shape != raw.shape:
        raise InvalidInputError(
            "measured_dir", f"raw frame is {raw.shape} but frame.json intrinsics {intr.shape}"
        )
    image = reconstruct_raw(raw, z_over_range(intr))
    fs = _recorded_full_scale(meta)
    if fs is None:
        fs = grey_full_scale(image.amplitude, image.valid, sensor_adc_bits(raw))
    arrays = _read_arrays(d) if (d / FRAME_NPZ).is_file() else {}
    return Frame("measured", image, arrays, meta, fs, raw)


def _read_measured_depth(d: Path) -> Frame:
    """A measured folder of royale's processed depth (``depth_points.npz``)."""
    frame = read_depth_points(d / DEPTH_POINTS_NPZ)
    image = frame.image()
    meta = _read_meta(d)
    fs = _recorded_full_scale(meta)
    if fs is None:
        fs = grey_full_scale(image.amplitude, image.valid, None)
    arrays = _read_arrays(d) if (d / FRAME_NPZ).is_file() else {}
    return Frame("measured", image, arrays, meta, fs, None)


def read_simulated(directory: str | Path) -> Frame:
    """A simulated frame folder (:func:`write_simulated` layout)."""
    d = Path(directory)
    if not (d / FRAME_NPZ).is_file():
        raise InvalidInputError("simulated_dir", f"'{d}' holds no frame.npz (a saved frame)")
    arrays = _read_arrays(d)
    meta = _read_meta(d)
    image = image_from_arrays(arrays)
    raw = read_raw(d / RAW_NPZ) if (d / RAW_NPZ).is_file() else None
    fs = _recorded_full_scale(meta)
    if fs is None:
        fs = grey_full_scale(image.amplitude, image.valid, sensor_adc_bits(raw))
    return Frame("simulated", image, arrays, meta, fs, raw)


def read_frame(directory: str | Path) -> Frame:
    """A frame folder, measured (``frame.json`` kind "measured", or only ``raw.npz``) or
    simulated."""
    d = Path(directory)
    if not d.is_dir():
        raise FileNotFoundError(f"no frame folder {d}")
    meta = _read_meta(d)
    if meta.get("kind") not in (None, *FRAME_KINDS):
        raise InvalidInputError("frame.json", f"kind {meta.get('kind')!r}; allowed: "
                                f"{', '.join(FRAME_KINDS)}")
    measured = meta.get("kind") == "measured" or (
        not (d / FRAME_NPZ).is_file() and (d / RAW_NPZ).is_file()
    )
    return read_measured(d) if measured else read_simulated(d)
