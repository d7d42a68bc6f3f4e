"""Recordings: what the rig captured, frame by frame, in one HDF5 file that replays as a campaign.

A recording keeps each raw frame exactly as the camera delivered it (:class:`~sim_core.raw.
RawFrame`: the phase images, grey image, validity flags, frequencies, exposure, timestamp and
illumination temperature) with the rig state read back for it and the campaign unit it belongs
to, and, once, the campaign that replays it (scene, mask, seed, samples per pixel, the pinned
calibration, the poses). ``toftwin record`` and a campaign created with ``"record": true``
write one; ``toftwin replay`` and a campaign with ``"source": "recording"`` read one back
through the pose loop's own storing step (:func:`service.lab.poses.store_measurement`), so a
replay compares exactly what a live campaign would have (docs/recordings.md).

Layout (``format`` ``"toftwin-recording"``, ``version`` 1)::

    /                       attrs: format, version, toftwin (version), created_s (epoch s),
                            campaign (JSON: :class:`RecordedCampaign`)
    /frames/NNNNNN          one group per recorded frame, in capture order
        phase_images        (n_f, 4, H, W) float32 [DN], one chunk, gzip + shuffle (or, for
                            royale's processed depth, x_m, y_m, z_m, noise_m, grey and
                            confidence, each (H, W) float32)
        intensity           (H, W) float32 [DN]
        saturated           (H, W) bool
        sbi_limit           (H, W) bool
        taps                (n_f, 4, 2, H, W) float32 [DN], where the source exposes them
        attrs               kind ("raw" or "royale processed depth"), frequencies_hz,
                            exposure_s, timestamp_s,
                            illumination_temperature_c (NaN: not reported), meta (JSON),
                            use_case, pose_index, repeat, capture (0; 1 for a unit's second
                            capture, the noise ceiling's), turntable_angle_deg, solar_suns,
                            shutter_open (the rig state read back), turning_deg_s

The file is opened, appended to and closed for every unit (:meth:`RecordingWriter.append`):
a process that dies between units leaves a readable file. A unit recorded twice (a campaign
resumed after its frame was taken but before its result was stored takes it again) reads back
as its last recording.
"""

from __future__ import annotations

import contextlib
import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from drivers.rig import RigState
from sim_core.errors import InvalidInputError
from sim_core.frame_io import DEPTH_POINT_ARRAYS
from sim_core.processed_depth import CAMERA_DATA_DEPTH, ProcessedDepthFrame, camera_data
from sim_core.raw import RawFrame

__all__ = ["FORMAT", "VERSION", "RecordedCampaign", "RecordedUnit", "Recording",
           "RecordingError", "RecordingWriter", "recorded_poses", "resolve_stored_path",
           "stored_path"]

#: the root attribute ``format`` of every recording
FORMAT = "toftwin-recording"
#: the layout's version (the module docstring)
VERSION = 1
#: the data directory's folder of recordings
RECORDINGS_DIR = "recordings"
#: gzip level of the frames' datasets (6: zlib's default; level 9 saves ~1 % more, 3x slower)
GZIP_LEVEL = 6


def stored_path(data_dir: str | Path, path: str | Path) -> str:
    """How a campaign row names a recording file: relative to the data directory when the file
    is inside it (``recordings/<id>.h5``: the folder can be moved or restored elsewhere), else
    absolute (a recording ``toftwin replay`` reads from wherever it is).

    >>> stored_path("/srv/toftwin", "/srv/toftwin/recordings/a.h5")
    'recordings/a.h5'
    >>> stored_path("/srv/toftwin", "/mnt/share/b.h5")
    '/mnt/share/b.h5'
    """
    base, file = Path(data_dir).absolute(), Path(path).absolute()
    try:
        return file.relative_to(base).as_posix()
    except ValueError:
        return str(file)


def resolve_stored_path(data_dir: str | Path, stored: str) -> Path:
    """The file a campaign row's recording path (:func:`stored_path`) names, in ``data_dir``;
    an absolute one (rows written before paths were stored relative, or a file outside the
    data directory) as it is, unless it is gone from a ``recordings/`` folder that this data
    directory's ``recordings/`` took over (a file of its name is there, or the old folder is
    gone too): a row older than relative paths, in a data directory that was moved.

    >>> resolve_stored_path("/srv/toftwin", "recordings/a.h5").as_posix()
    '/srv/toftwin/recordings/a.h5'
    >>> resolve_stored_path("/srv/toftwin", "/mnt/share/a.h5").as_posix()
    '/mnt/share/a.h5'
    >>> resolve_stored_path("/srv/toftwin", "/gone/data/recordings/a.h5").as_posix()
    '/srv/toftwin/recordings/a.h5'
    """
    path = Path(stored)
    if not path.is_absolute():
        return Path(data_dir) / path
    # a row written before paths were stored relative names the folder's old place: the same
    # recording in this data directory's recordings/ is the one it meant
    moved = Path(data_dir) / RECORDINGS_DIR / path.name
    if (path.parent.name == RECORDINGS_DIR and not path.exists()
            and (moved.exists() or not path.parent.is_dir())):
        return moved
    return path


@dataclass(frozen=True)
class RecordedCampaign:
    """The campaign a recording replays as: what the pose loop needs besides the frames.

    ``poses`` are (turntable_deg, solar_suns, repeats) in pose-index order; ``calibration`` the
    calibration pinned when it was captured (JSON, None: nominal) and its hash;
    ``object_fit``, ``object_twin`` (and its hash) and ``object_fit_report`` the object fit's
    settings, result and report, when the campaign had one (a replay compares with that fitted
    twin, it does not fit again).
    """

    name: str
    scene_name: str
    scene: dict[str, Any]
    #: the folder the scene's files are found in; None: the bundled scenes' (a recording made by
    #: the service names no folder of the server's)
    scene_base_dir: str | None
    mask: dict[str, Any]
    seed: int
    spp: int
    poses: list[tuple[float, float, int]]
    calibration: dict[str, Any] | None = None
    calibration_hash: str | None = None
    turning_deg_s: float | None = None
    object_fit: dict[str, Any] | None = None
    object_twin: dict[str, Any] | None = None
    object_twin_hash: str | None = None
    object_fit_report: dict[str, Any] | None = None

    def to_json(self) -> str:
        return json.dumps(self.__dict__, sort_keys=True, allow_nan=False)

    @classmethod
    def of_row(cls, row: Any, poses: Sequence[Any],
               bundled_dir: str | Path | None = None) -> RecordedCampaign:
        """The recorded form of a stored campaign (:class:`~service.store.tables.CampaignRow`)
        and its planned poses; a scene of ``bundled_dir`` (the service's bundled scenes) is
        recorded without its folder."""
        def loads(text: str | None) -> Any:
            return None if text is None else json.loads(text)

        bundled = bundled_dir is not None and (
            Path(row.scene_base_dir).resolve() == Path(bundled_dir).resolve())
        return cls(
            name=row.name, scene_name=row.scene_name, scene=json.loads(row.scene_json),
            scene_base_dir=None if bundled else row.scene_base_dir,
            mask=json.loads(row.mask_json), seed=row.seed,
            spp=row.spp, poses=[(p.turntable_deg, p.solar_suns, p.repeats) for p in poses],
            calibration=loads(row.calibration_json), calibration_hash=row.calibration_hash,
            turning_deg_s=row.turning_deg_s, object_fit=loads(row.object_fit_json),
            object_twin=loads(row.object_twin_json), object_twin_hash=row.object_twin_hash,
            object_fit_report=loads(row.object_fit_report_json))

    @classmethod
    def from_json(cls, text: str) -> RecordedCampaign:
        data = json.loads(text)
        data["poses"] = [tuple(p) for p in data["poses"]]
        return cls(**data)


@dataclass
class RecordedUnit:
    """One campaign unit (pose and repeat) as recorded: its frames and the rig state."""

    pose_index: int
    repeat: int
    state: RigState
    use_case: str
    turning_deg_s: float
    raws: list[RawFrame | ProcessedDepthFrame] = field(default_factory=list)


class RecordingError(InvalidInputError):
    """A file that is not a recording, or lacks what a replay asks of it (names the file)."""


class RecordingWriter:
    """Appends units to a recording, creating it (with its campaign) on the first one.

    Parameters
    ----------
    path : Path
        The ``.h5`` file; an existing recording is appended to (a resumed campaign), anything
        else there is refused.
    campaign : RecordedCampaign
        Written when the file is created.
    """

    def __init__(self, path: str | Path, campaign: RecordedCampaign) -> None:
        self.path = Path(path)
        self.campaign = campaign
        #: the file at ``path`` was checked to be a recording (once: a long campaign appends
        #: thousands of units, and reading its index each time would grow with it)
        self._checked = False

    def append(self, unit: RecordedUnit) -> None:
        """Write ``unit``'s frames (each a group, in order) and close the file."""
        from sim_core.frame_io import package_version

        self.path.parent.mkdir(parents=True, exist_ok=True)
        new = not self.path.exists()
        if not new and not self._checked:
            Recording(self.path)  # refuses a file that is not a recording
        self._checked = True
        with h5py.File(self.path, "a") as f:
            if new:
                f.attrs.update({"format": FORMAT, "version": VERSION,
                                "toftwin": package_version(), "created_s": time.time(),
                                "campaign": self.campaign.to_json()})
            frames = f.require_group("frames")
            for capture, raw in enumerate(unit.raws):
                attrs = _frame_attrs(raw, unit, capture)  # a meta that is no JSON fails here
                name = f"{len(frames):06d}"
                try:
                    _write_frame(frames.create_group(name), raw, attrs)
                except BaseException:  # no half-written group stays (a full disk)
                    with contextlib.suppress(Exception):
                        del frames[name]
                    raise


def _frame_attrs(raw: RawFrame | ProcessedDepthFrame, unit: RecordedUnit,
                 capture: int) -> dict[str, Any]:
    temp = raw.illumination_temperature_c
    return {
        "kind": camera_data(raw),
        "frequencies_hz": np.asarray(raw.frequencies_hz, dtype=np.float64),
        "exposure_s": float(raw.exposure_s), "timestamp_s": float(raw.timestamp_s),
        "illumination_temperature_c": math.nan if temp is None else float(temp),
        "meta": json.dumps(raw.meta, sort_keys=True, default=_jsonable),
        "use_case": unit.use_case, "pose_index": unit.pose_index, "repeat": unit.repeat,
        "capture": capture, "turntable_angle_deg": unit.state.turntable_angle_deg,
        "solar_suns": unit.state.solar_suns, "shutter_open": unit.state.shutter_open,
        "turning_deg_s": float(unit.turning_deg_s),
    }


def _write_frame(g: Any, raw: RawFrame | ProcessedDepthFrame, attrs: dict[str, Any]) -> None:
    """The frame's datasets, then its attributes (a group without them is incomplete: the
    reader skips it)."""
    def data(name: str, array: np.ndarray) -> None:
        g.create_dataset(name, data=array, chunks=array.shape, compression="gzip",
                         compression_opts=GZIP_LEVEL, shuffle=True)

    if isinstance(raw, ProcessedDepthFrame):  # royale's processed depth (camera mode depth)
        for name in DEPTH_POINT_ARRAYS:
            data(name, np.asarray(getattr(raw, name), dtype=np.float32))
    else:
        data("phase_images", np.asarray(raw.phase_images, dtype=np.float32))
        data("intensity", np.asarray(raw.intensity, dtype=np.float32))
        data("saturated", np.asarray(raw.saturated, dtype=bool))
        data("sbi_limit", np.asarray(raw.sbi_limit, dtype=bool))
        if raw.taps is not None:
            data("taps", np.asarray(raw.taps, dtype=np.float32))
    g.attrs.update(attrs)


def _jsonable(value: Any) -> Any:
    """numpy scalars and arrays in a frame's ``meta`` as JSON."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} in a frame's meta is not JSON")


class Recording:
    """A recording, opened for reading: its campaign and an index of its units.

    Raises
    ------
    RecordingError
        The file does not exist, is not HDF5, or is not a recording of a known version.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        name = self.path.name  # messages name the file, never a folder of the server's
        if not self.path.is_file():
            raise RecordingError("recording", f"'{name}' does not exist")
        #: groups without their attributes (a write that failed half-way), skipped
        self.incomplete: list[str] = []
        try:
            with h5py.File(self.path, "r") as f:
                if f.attrs.get("format") != FORMAT:
                    raise RecordingError(
                        "recording", f"'{name}' is HDF5 but not a toftwin recording "
                        f"(its 'format' attribute is {f.attrs.get('format')!r})")
                version = int(f.attrs.get("version", 0))
                if version != VERSION:
                    raise RecordingError(
                        "recording", f"'{name}' is version {version}; this toftwin reads "
                        f"version {VERSION}")
                self.campaign = RecordedCampaign.from_json(str(f.attrs["campaign"]))
                #: (pose_index, repeat) -> the groups of its frames, by capture (the last
                #: recording of a unit recorded twice)
                self.index: dict[tuple[int, int], dict[int, str]] = {}
                frames = f.get("frames", {})
                for group in sorted(frames, key=lambda n: (len(n), n)):  # capture order
                    a = frames[group].attrs
                    if "capture" not in a:
                        self.incomplete.append(group)
                        continue
                    key = (int(a["pose_index"]), int(a["repeat"]))
                    captures = self.index.setdefault(key, {})
                    if int(a["capture"]) == 0:
                        captures.clear()
                    captures[int(a["capture"])] = group
        except OSError as exc:
            raise RecordingError("recording", f"'{name}' is not an HDF5 file: {exc}") from None
        except (KeyError, ValueError, TypeError) as exc:  # a damaged campaign or frame
            raise RecordingError("recording", f"'{name}' is damaged: {exc!r}") from None

    @property
    def n_frames(self) -> int:
        return sum(len(c) for c in self.index.values())

    def units(self) -> list[tuple[int, int]]:
        """The recorded units (pose_index, repeat), sorted."""
        return sorted(self.index)

    def unit(self, pose_index: int, repeat: int, captures: int = 1) -> RecordedUnit:
        """The recorded frames of one unit (its first ``captures`` of them, or all it has when
        fewer were captured while turning: a turning sweep takes one frame per unit).

        Raises
        ------
        RecordingError
            The unit, or as many captures of it, was not recorded.
        """
        names = self.index.get((pose_index, repeat), {})
        with h5py.File(self.path, "r") as f:
            first = f["frames"][names[0]].attrs if 0 in names else None
            if first is not None and float(first["turning_deg_s"]) != 0.0:
                captures = min(captures, len(names))
            if any(k not in names for k in range(captures)):
                raise RecordingError(
                    "recording", f"'{self.path.name}' holds {len(names)} frame(s) of pose "
                    f"{pose_index} repeat {repeat}; the replay needs {captures}")
            groups = [f["frames"][names[k]] for k in range(captures)]
            a = groups[0].attrs
            state = RigState(float(a["turntable_angle_deg"]), float(a["solar_suns"]),
                             bool(a["shutter_open"]))
            return RecordedUnit(pose_index, repeat, state, str(a["use_case"]),
                                float(a["turning_deg_s"]), [_read_frame(g) for g in groups])


def _read_frame(g: Any) -> RawFrame | ProcessedDepthFrame:
    a = g.attrs
    temp = float(a["illumination_temperature_c"])
    if a.get("kind") == CAMERA_DATA_DEPTH:
        return ProcessedDepthFrame(
            *(g[name][...] for name in DEPTH_POINT_ARRAYS),
            frequencies_hz=np.asarray(a["frequencies_hz"], dtype=np.float64),
            exposure_s=float(a["exposure_s"]), timestamp_s=float(a["timestamp_s"]),
            meta=json.loads(str(a["meta"])),
            illumination_temperature_c=None if math.isnan(temp) else temp)
    return RawFrame(
        phase_images=g["phase_images"][...], intensity=g["intensity"][...],
        frequencies_hz=np.asarray(a["frequencies_hz"], dtype=np.float64),
        saturated=g["saturated"][...], sbi_limit=g["sbi_limit"][...],
        exposure_s=float(a["exposure_s"]), timestamp_s=float(a["timestamp_s"]),
        taps=g["taps"][...] if "taps" in g else None, meta=json.loads(str(a["meta"])),
        illumination_temperature_c=None if math.isnan(temp) else temp,
    )


def recorded_poses(campaign: RecordedCampaign,
                   units: Sequence[tuple[int, int]]) -> list[tuple[float, float, int]]:
    """The campaign's poses, each with as many repeats as were recorded in a row from repeat 0
    (a recording stopped early replays the units it holds)."""
    out = []
    recorded = set(units)
    for i, (angle, suns, _repeats) in enumerate(campaign.poses):
        n = 0
        while (i, n) in recorded:
            n += 1
        out.append((angle, suns, n))
    return out
