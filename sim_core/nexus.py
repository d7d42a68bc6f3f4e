"""Frames as HDF5 files in NeXus form (docs/export-hdf5.md): one file per frame, or one per
campaign, recording or scan with the frames stacked along a leading ``frame`` axis.

Layout (``frame`` is present only in a stack)::

    /                       NXroot   default = "entry", creator
    /entry                  NXentry  default = "depth", program_name
      depth range grey amplitude intensity valid
                            NXdata   data (frame, y, x) with units and long_name; y, x [pixel]
      phase                 NXdata   data (frame, frequency, y, x) [rad]; frequency [Hz]
      raw                   NXdata   the four phase images C_i (frame, frequency, phase_step,
                                     y, x) [DN], where the frame has a raw frame
      taps                  NXdata   tap charges (frame, frequency, phase_step, tap, y, x) [DN],
                                     where the source exposes them (the simulator)
      camera                NXcollection  width_px ... cy_px, distortion (k1 k2 p1 p2 k3),
                                     camera_matrix (3 x 3), world_from_camera (4 x 4, where
                                     the pose is known: the camera frame to the scene's world;
                                     else NaN), intrinsics_source
      rig                   NXcollection  the rig state's numbers (turntable angle, suns, ...)
      metadata              NXcollection  frame_json (the whole frame.json), kind, frame_id,
                                     scene_hash, calibration_hash, use_case, package_version
      metrics               NXcollection  the comparison's figures, where given

Every image is the frame folder's own array (:mod:`sim_core.frame_io`): nothing is resampled
or rescaled. Missing values are NaN (numbers) or "" (text). A single-frame file is written to a
temporary name and renamed (:func:`sim_core.files.atomic_write`); a stack grows frame by frame
(:class:`NexusFrameStack`), each append flushed, and a frame that cannot join it (another
shape or form) is refused before anything of it is written.
"""

from __future__ import annotations

import io
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from sim_core.errors import InvalidInputError
from sim_core.files import atomic_write
from sim_core.frame_io import (
    Frame,
    image_intrinsics,
    intrinsics_known,
    package_version,
    pose_from_meta,
)
from sim_core.json_safe import json_safe

#: the (H, W) NXdata groups of every frame: group -> (frame array, long name)
IMAGE_GROUPS: dict[str, tuple[str, str]] = {
    "depth": ("depth_z_m", "depth along the optical axis (NaN where not valid)"),
    "range": ("range_m", "radial range (NaN where not valid)"),
    "grey": ("grey_8bit", "grey image, 8 bit at the frame's grey full scale"),
    "amplitude": ("amplitude", "modulation amplitude (seed eq. 5)"),
    "intensity": ("intensity", "intensity, mean tap sum (seed eq. 6)"),
    "valid": ("valid", "pixel reported (1) or not (0)"),
}
#: the intrinsics' scalar keys in ``/entry/camera``
CAMERA_KEYS = ("width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px")
METADATA_KEYS = ("kind", "frame_id", "scene_name", "scene_hash", "calibration_hash",
                 "use_case", "package_version")
#: gzip level of every image dataset (h5py's and every HDF5 reader's built-in filter)
GZIP_LEVEL = 4
#: the mimetype of these files in Bluesky's StreamResource documents (Tiled's HDF5
#: consolidator takes it)
HDF5_MIMETYPE = "application/x-hdf5"


def frame_unit(frame: Frame, array: str) -> str:
    """The unit of a frame array as NeXus writes it: DN where the frame was read out by a
    sensor (measured, or simulated with a sensor: frame.json's ``ideal_sensor`` false),
    ``W m^-2 sr^-1`` for an ideal-sensor simulation (a frame.json without ``ideal_sensor``:
    by whether the folder has a raw frame)."""
    if array in ("depth_z_m", "range_m"):
        return "m"
    if array in ("amplitude", "intensity"):
        ideal = frame.meta.get("ideal_sensor")
        if frame.kind == "measured" or ideal is False or (ideal is None and frame.raw is not None):
            return "DN"
        return "W m^-2 sr^-1"
    return ""


def frame_images(frame: Frame) -> dict[str, np.ndarray]:
    """The arrays of every NXdata group of ``frame``: (H, W) images, ``phase`` (n_f, H, W),
    and ``raw`` / ``taps`` where the frame has them."""
    im = frame.image
    out: dict[str, np.ndarray] = {
        "depth": np.asarray(im.depth_z_m, dtype=np.float64),
        "range": np.asarray(im.range_m, dtype=np.float64),
        "grey": frame.grey_8bit(),
        "amplitude": np.asarray(im.amplitude, dtype=np.float64),
        "intensity": np.asarray(im.intensity, dtype=np.float64),
        "valid": np.asarray(im.valid, dtype=np.uint8),
        "phase": np.asarray(im.phase_rad, dtype=np.float64),
    }
    if frame.raw is not None:
        out["raw"] = np.asarray(frame.raw.phase_images, dtype=np.float32)
        if frame.raw.taps is not None:
            out["taps"] = np.asarray(frame.raw.taps, dtype=np.float32)
    return out


def camera_fields(frame: Frame) -> dict[str, Any]:
    """``/entry/camera``: the intrinsics the frame was reconstructed with, its camera matrix,
    (NaN where unknown) its pose, and where the intrinsics come from (``intrinsics_source``:
    ``frame.json``, or the preset's where frame.json records none)."""
    intr = image_intrinsics(frame.meta, frame.image.range_m.shape)
    out = {k: np.asarray(getattr(intr, k), dtype=np.int64 if k.endswith(("width_px",
           "height_px")) else np.float64) for k in CAMERA_KEYS}
    out["distortion"] = np.asarray(intr.distortion, dtype=np.float64)
    out["camera_matrix"] = np.array([[intr.fx_px, 0.0, intr.cx_px], [0.0, intr.fy_px, intr.cy_px],
                                     [0.0, 0.0, 1.0]])
    pose = pose_from_meta(frame.meta)
    out["world_from_camera"] = np.full((4, 4), np.nan) if pose is None else pose
    out["intrinsics_source"] = ("frame.json" if intrinsics_known(frame.meta) else
                                "pico flexx preset (frame.json records no intrinsics)")
    return out


def rig_fields(meta: Mapping[str, Any]) -> dict[str, float]:
    """The rig state's numbers of a frame.json (``rig``; for a measured frame also under
    ``camera_meta``), each as float."""
    rig: dict[str, Any] = {}
    for source in ((meta.get("camera_meta") or {}).get("rig"), meta.get("rig")):
        if isinstance(source, Mapping):
            rig.update(source)
    return {k: float(v) for k, v in sorted(rig.items())
            if isinstance(v, int | float) and not isinstance(v, bool)}


def metadata_fields(frame: Frame) -> dict[str, str]:
    """``/entry/metadata``: the whole frame.json as text and its identifying keys."""
    meta = frame.meta
    camera_meta = meta.get("camera_meta") or {}
    values = {"kind": frame.kind, "use_case": camera_meta.get("use_case")
              or meta.get("use_case"), **{k: meta.get(k) for k in METADATA_KEYS
                                         if k not in ("kind", "use_case")}}
    out = {k: "" if values.get(k) is None else str(values[k]) for k in METADATA_KEYS}
    out["frame_json"] = json.dumps(json_safe(dict(meta)), sort_keys=True, allow_nan=False)
    return out


def _finite_metrics(metrics: Mapping[str, Any] | None) -> dict[str, float]:
    """The numbers of ``metrics`` as floats, NaN for a missing (None) or non-finite one."""
    if not metrics:
        return {}
    return {k: float(v) if v is not None and np.isfinite(v) else float("nan")
            for k, v in sorted(metrics.items())
            if v is None or (isinstance(v, int | float) and not isinstance(v, bool))}


#: units of the collections' fields by the suffix of their names
_SUFFIX_UNITS = (("_mm", "mm"), ("_m", "m"), ("_px", "pixel"), ("_deg", "deg"), ("_s", "s"),
                 ("_hz", "Hz"), ("_c", "degC"), ("_suns", "sun"))


def _field_units(name: str) -> str | None:
    return next((u for suffix, u in _SUFFIX_UNITS if name.endswith(suffix)), None)


# -- writing -----------------------------------------------------------------------------------
def _set_class(group: h5py.Group, nx_class: str, **attrs: Any) -> h5py.Group:
    group.attrs["NX_class"] = nx_class
    for k, v in attrs.items():
        group.attrs[k] = v
    return group


def _axis_names(group: str, ndim: int) -> list[str]:
    """The NXdata axes of an image of ``ndim`` dimensions (without the frame axis)."""
    return {"phase": ["frequency", "y", "x"], "raw": ["frequency", "phase_step", "y", "x"],
            "taps": ["frequency", "phase_step", "tap", "y", "x"]}.get(group, ["y", "x"])[-ndim:]


def _long_name(group: str) -> tuple[str, str]:
    """(frame array, long name) of an NXdata group."""
    if group in IMAGE_GROUPS:
        return IMAGE_GROUPS[group]
    return {"phase": ("phase_all_rad", "phase delay per modulation frequency, in [0, 2 pi)"),
            "raw": ("phase_images", "phase images C_i = C_iA - C_iB (seed eq. 15)"),
            "taps": ("taps", "tap charges A and B")}[group]


def _unit(frame: Frame, group: str) -> str:
    if group == "phase":
        return "rad"
    if group in ("raw", "taps"):
        return "DN"
    return frame_unit(frame, IMAGE_GROUPS[group][0])


def _dataset(parent: h5py.Group, name: str, value: Any, stacked: bool,
             compress: bool = False) -> h5py.Dataset:
    """A dataset for ``value`` (text is stored as UTF-8 strings); in a stack an empty one with
    a leading, growing frame axis, one frame a chunk."""
    if isinstance(value, str):
        if not stacked:
            return parent.create_dataset(name, data=value, dtype=h5py.string_dtype())
        return parent.create_dataset(name, shape=(0,), maxshape=(None,),
                                     dtype=h5py.string_dtype(), chunks=True)
    value = np.asarray(value)
    kw: dict[str, Any] = {}
    if compress and value.ndim >= 2:
        kw = {"compression": "gzip", "compression_opts": GZIP_LEVEL, "shuffle": True}
    if not stacked:
        return parent.create_dataset(name, data=value, **kw)
    if value.dtype.kind == "f":  # a frame that lacks a value leaves NaN, not 0
        kw["fillvalue"] = np.nan
    return parent.create_dataset(name, shape=(0, *value.shape), maxshape=(None, *value.shape),
                                 dtype=value.dtype, chunks=(1, *value.shape) if value.shape
                                 else True, **kw)


def _append(ds: h5py.Dataset, index: int, value: Any, what: str) -> None:
    value = value if isinstance(value, str) else np.asarray(value)
    if np.shape(value) != ds.shape[1:]:
        raise InvalidInputError(what, f"a frame's {ds.name} is {value.shape}, the stack's "
                                f"earlier frames {ds.shape[1:]}: a stack holds frames of one "
                                "shape and form")
    ds.resize(index + 1, axis=0)
    ds[index] = value


class _Writer:
    """Writes frames into an open NeXus file, as one frame or as a growing stack."""

    def __init__(self, h5: h5py.File, stacked: bool, entry: str = "entry") -> None:
        self.h5, self.stacked, self.count = h5, stacked, 0
        h5.attrs["NX_class"] = "NXroot"
        if "default" not in h5.attrs:  # the first entry is the file's default
            h5.attrs["default"] = entry
        h5.attrs["creator"] = f"toftwin {package_version()}"
        self.entry = _set_class(h5.create_group(entry), "NXentry", default="depth")
        self.entry.create_dataset("program_name", data=f"toftwin {package_version()}")

    def _collection(self, name: str, fields: Mapping[str, Any]) -> None:
        """An NXcollection of ``fields``; in a stack a field first seen at a later frame is
        added then, with NaN (or "") for the frames before, and one a frame lacks gets NaN."""
        group = self.entry.get(name)
        if group is None:
            group = _set_class(self.entry.create_group(name), "NXcollection")
        for k, v in fields.items():
            if k in group:
                continue
            ds = _dataset(group, k, v, self.stacked)
            units = _field_units(k)
            if units is not None:
                ds.attrs["units"] = units
            if k == "world_from_camera":
                ds.attrs["description"] = ("4 x 4 rigid transform from the camera frame (x "
                                           "right, y down, z forward) to the scene's world, "
                                           "translation in m; NaN where not known")
            if self.stacked and self.count:  # the earlier frames lacked it
                ds.resize(self.count, axis=0)
        if not self.stacked:
            return
        for k in group:
            text = h5py.check_string_dtype(group[k].dtype) is not None
            _append(group[k], self.count, fields.get(k, "" if text else np.nan), "frames")

    def _image_group(self, frame: Frame, name: str, value: np.ndarray) -> None:
        group = self.entry.get(name)
        if group is None:
            axes = _axis_names(name, value.ndim)
            group = _set_class(self.entry.create_group(name), "NXdata", signal="data",
                               axes=(["frame"] if self.stacked else []) + axes)
            array, long_name = _long_name(name)
            data = _dataset(group, "data", value, self.stacked, compress=True)
            data.attrs["long_name"] = long_name
            if _unit(frame, name):
                data.attrs["units"] = _unit(frame, name)
            data.attrs["toftwin_array"] = array
            shift = 1 if self.stacked else 0
            for i, axis in enumerate(axes):
                group.attrs[f"{axis}_indices"] = i + shift
                if axis == "frequency":
                    group.create_dataset(axis, data=frame.image.frequencies_hz)
                    group[axis].attrs["units"] = "Hz"
                else:
                    group.create_dataset(axis, data=np.arange(value.shape[i]))
                    if axis in ("x", "y"):
                        group[axis].attrs["units"] = "pixel"
            if self.stacked:
                group.attrs["frame_indices"] = 0
                group.create_dataset("frame", shape=(0,), maxshape=(None,), dtype=np.int64)
        if self.stacked:
            _append(group["data"], self.count, value, "frames")
            _append(group["frame"], self.count, self.count, "frames")
        elif "data" not in group:
            raise AssertionError("unreachable: a single frame's group made without data")

    def _check_joins(self, images: Mapping[str, np.ndarray]) -> None:
        """Refuse, before anything is written, a frame of another form or shape than the
        stack's: it would leave the stack's groups of unequal length."""
        have = {k for k in self.entry if self.entry[k].attrs.get("NX_class") == "NXdata"}
        if set(images) != have:
            raise InvalidInputError(
                "frames", f"a frame with the groups {sorted(images)} cannot join a stack of "
                f"{sorted(have)}: a stack holds frames of one form (raw frames or not)")
        for name, value in images.items():
            want = self.entry[name]["data"].shape[1:]
            if value.shape != want:
                raise InvalidInputError(
                    "frames", f"a frame's {name} is {value.shape}, the stack's {want}: a stack "
                    "holds frames of one shape")

    def add(self, frame: Frame, metrics: Mapping[str, Any] | None = None) -> int:
        """Write ``frame`` (the next of a stack, or the file's one frame); returns its index."""
        if not self.stacked and self.count:
            raise InvalidInputError("frames", "a single-frame file holds one frame")
        images = frame_images(frame)
        camera = camera_fields(frame)
        if self.stacked and self.count:
            self._check_joins(images)  # the camera's fields have fixed shapes
        for name, value in images.items():
            self._image_group(frame, name, value)
        self._collection("camera", camera)
        self._collection("rig", rig_fields(frame.meta))
        self._collection("metadata", metadata_fields(frame))
        if metrics is not None or "metrics" in self.entry:
            self._collection("metrics", _finite_metrics(metrics))
        index = self.count
        self.count += 1
        self.h5.flush()
        return index


def write_frame_nexus(path: str | Path, frame: Frame,
                      metrics: Mapping[str, Any] | None = None) -> Path:
    """Write one frame as a NeXus HDF5 file (the module's layout, no frame axis), atomically
    (:func:`sim_core.files.atomic_write` of :func:`frame_nexus_bytes`)."""
    return atomic_write(Path(path), frame_nexus_bytes(frame, metrics))


def frame_nexus_bytes(frame: Frame, metrics: Mapping[str, Any] | None = None) -> bytes:
    """One frame as the bytes of a NeXus HDF5 file, made in memory (a frame's is a few MB)."""
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as h5:
        _Writer(h5, stacked=False).add(frame, metrics)
    return buffer.getvalue()


class NexusFrameStack:
    """A NeXus HDF5 file of frames stacked along a leading ``frame`` axis, written frame by
    frame (a campaign's, a recording's or a Bluesky scan's). Use as a context manager.

    The file is created at ``path`` (an existing file is replaced, unless ``replace`` is False:
    then it is refused, :class:`FileExistsError`). Frames go into the NXentry
    ``entry`` (the default), or into several entries of one file (a campaign's ``measured``
    and ``simulated`` frames, pose by pose); the first entry written is the file's default.
    Every :meth:`append` is flushed before it returns (a crash keeps the frames appended so
    far); HDF5 locks a file while it is written, so readers open it once the stack is closed.
    """

    def __init__(self, path: str | Path, replace: bool = True) -> None:
        self.path = Path(path)
        if not replace and self.path.exists():
            raise FileExistsError(f"{self.path} exists: a stack is not written over another "
                                  "file (give each one a name of its own)")
        # HDF5 1.14's format (h5py 3.11, the floor, reads it; 2.0's default it cannot); "x":
        # created, never truncated, where an existing file must be kept
        self._h5 = h5py.File(self.path, "w" if replace else "x",
                             libver=("earliest", "v114"))
        self._writers: dict[str, _Writer] = {}

    def append(self, frame: Frame, metrics: Mapping[str, Any] | None = None,
               entry: str = "entry") -> int:
        """Add ``frame`` (with the comparison's ``metrics``, if any) to ``entry``; returns its
        index there."""
        if entry not in self._writers:
            self._writers[entry] = _Writer(self._h5, stacked=True, entry=entry)
        return self._writers[entry].add(frame, metrics)

    @property
    def count(self) -> int:
        """Frames written so far into the entry ``entry``."""
        return self.entry_count("entry")

    def entry_count(self, entry: str) -> int:
        """Frames written so far into ``entry``."""
        writer = self._writers.get(entry)
        return 0 if writer is None else writer.count

    def set_attribute(self, name: str, value: Any) -> None:
        """Set an attribute of the file's root (what the whole stack is: a campaign id, ...)."""
        self._h5.attrs[name] = value

    def close(self) -> None:
        self._h5.close()

    def __enter__(self) -> NexusFrameStack:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

