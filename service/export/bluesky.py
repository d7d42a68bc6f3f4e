"""A campaign as Bluesky event-model documents: run start, one descriptor, one event per pose
and repeat, and (once the campaign is over) run stop.

Built with :func:`event_model.compose_run`, which validates every document against the
``event-model`` JSON schemas as it composes it. Uids are derived from the campaign id (UUID5),
so the same campaign gives the same documents every time they are asked for. Frames are
referenced by id (``measured_frame_id``, ``simulated_frame_id``); their arrays are at
``/api/v1/frames/{id}/arrays``. Non-finite metrics (PSNR of identical images) are ``None``, and
so are the depth-difference figures of a result stored before they were computed.

Given the campaign's frames as one NeXus HDF5 file (:class:`CampaignFrames`: the file
:func:`service.export.frame_forms.write_campaign_nexus` writes, which ``GET
/api/v1/campaigns/{id}/frames.h5`` serves), the documents also point into it in the form a
Bluesky detector's do (:class:`drivers.bluesky.camera.ToFCamera`): one StreamResource per
dataset (mimetype ``application/x-hdf5``, parameters ``dataset`` and ``chunk_shape``; data keys
``camera-depth`` ... for the measured frames, ``simulator-depth`` ... for the simulated ones,
``external: "STREAM:"`` in the descriptor) and, before each event, a StreamDatum per dataset
with the event's ``seq_num`` and its frames' index along the file's frame axis. A result the
file left out (its frame folders were gone) has its event but no StreamDatum.
:func:`export_campaign_run` writes both side by side: ``frames.h5`` and ``documents.jsonl``
(docs/export-bluesky.md).
"""

from __future__ import annotations

import json
import math
import uuid
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import event_model
import h5py
from sqlalchemy.orm import sessionmaker

from service.export.results_table import CHANNEL_FIELDS, TOF_FIELDS
from service.store import queries
from service.store.frame_files import FrameStore
from sim_core.frame_io import package_version
from sim_core.json_safe import json_safe
from sim_core.nexus import HDF5_MIMETYPE

_NAMESPACE = uuid.UUID("6c1f6c3e-3a55-4b8e-9a8e-0f7a1d9b2c11")
_EXIT_STATUS = {"completed": "success", "cancelled": "abort", "failed": "fail"}
#: the campaign file's entries the documents point into -> the descriptor's object (the data
#: keys are ``<object>-<group>``, as a Bluesky ToFCamera named ``camera`` writes them)
FRAME_OBJECTS = {"measured": "camera", "simulated": "simulator"}
#: the names of the two files :func:`export_campaign_run` writes
RUN_FILES = ("documents.jsonl", "frames.h5")


@dataclass(frozen=True)
class FrameDataset:
    """One dataset of a campaign's frames file: where it is and one frame's shape and dtype."""

    data_key: str
    dataset: str
    shape: tuple[int, ...]
    dtype: str
    chunk_shape: tuple[int, ...]


@dataclass(frozen=True)
class CampaignFrames:
    """Where a campaign's frames are: a NeXus file of them and, per result, its frames' index.

    Attributes
    ----------
    uri : str
        The file's URI for the StreamResource documents (``file://localhost/...`` for a file
        on this machine, which Tiled follows).
    datasets : tuple of FrameDataset
        Every image dataset of the entries in :data:`FRAME_OBJECTS`.
    index : mapping
        ``(pose_index, repeat) -> index along the frame axis`` of the results in the file.
    """

    uri: str
    datasets: tuple[FrameDataset, ...]
    index: Mapping[tuple[int, int], int] = field(default_factory=dict)

    @classmethod
    def from_file(cls, path: str | Path, uri: str | None = None) -> CampaignFrames:
        """Read what the documents need from a campaign's frames file (its datasets, and the
        pose index and repeat of each of its frames, ``/<entry>/metrics``); ``uri`` defaults
        to the file's own ``file://localhost`` URI."""
        path = Path(path).resolve()
        datasets: list[FrameDataset] = []
        with h5py.File(path, "r") as f:
            entries = [e for e in FRAME_OBJECTS if e in f]
            if not entries:
                raise ValueError(f"{path}: no entry {' or '.join(FRAME_OBJECTS)}: not a "
                                 "campaign's frames file")
            metrics = f[entries[0]].get("metrics")
            index: dict[tuple[int, int], int] = {}
            if metrics is not None and "pose_index" in metrics and "repeat" in metrics:
                for i, (p, r) in enumerate(zip(metrics["pose_index"][()],
                                               metrics["repeat"][()], strict=True)):
                    index[(int(p), int(r))] = i
            for entry in entries:
                group = f[entry]
                for name in sorted(group):
                    item = group[name]
                    if item.attrs.get("NX_class") != "NXdata" or "data" not in item:
                        continue
                    data = item["data"]
                    datasets.append(FrameDataset(
                        f"{FRAME_OBJECTS[entry]}-{name}", data.name, tuple(data.shape[1:]),
                        data.dtype.str, tuple(data.chunks or (1, *data.shape[1:]))))
        return cls(uri or file_uri(path), tuple(datasets), index)


def file_uri(path: str | Path) -> str:
    """``file://localhost/abs/path``: the form of a local file's URI ophyd-async's detectors
    write and Tiled reads.

    >>> file_uri("/data/run/frames.h5")
    'file://localhost/data/run/frames.h5'
    """
    return "file://localhost" + Path(path).resolve().as_posix()


def _uid(*parts: object) -> str:
    return str(uuid.uuid5(_NAMESPACE, "/".join(str(p) for p in parts)))


def _num(value: Any) -> float | None:
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    return None


def _frame_keys(frames: CampaignFrames) -> dict[str, dict[str, Any]]:
    return {d.data_key: {"source": f"{frames.uri}#{d.dataset}", "dtype": "array",
                         "shape": [1, *d.shape], "dtype_numpy": d.dtype, "external": "STREAM:"}
            for d in frames.datasets}


def _data_keys() -> dict[str, dict[str, Any]]:
    keys: dict[str, dict[str, Any]] = {
        "pose_index": {"source": "toftwin:campaign", "dtype": "integer", "shape": []},
        "repeat": {"source": "toftwin:campaign", "dtype": "integer", "shape": []},
        "turntable_deg": {"source": "turntable:setpoint", "dtype": "number", "shape": [],
                          "units": "deg"},
        "turntable_readback_deg": {"source": "turntable:position", "dtype": "number",
                                   "shape": [], "units": "deg"},
        "solar_suns": {"source": "solar_simulator:setpoint", "dtype": "number", "shape": [],
                       "units": "sun"},
        "measured_frame_id": {"source": "camera", "dtype": "string", "shape": []},
        "simulated_frame_id": {"source": "simulator", "dtype": "string", "shape": []},
        "n_pixels": {"source": "toftwin:compare", "dtype": "integer", "shape": []},
        "grey_chi_square": {"source": "toftwin:compare", "dtype": "number", "shape": []},
    }
    for f in TOF_FIELDS:
        keys[f] = {"source": "toftwin:compare", "shape": [],
                   "dtype": "integer" if f.endswith("pixels") else "number"}
        if f.endswith("_mm"):
            keys[f]["units"] = "mm"
    for ch in ("grey", "depth"):
        for f in CHANNEL_FIELDS:
            keys[f"{ch}_{f}"] = {"source": "toftwin:compare", "dtype": "number", "shape": []}
    return keys


def campaign_documents(sessions: sessionmaker, campaign_id: str,
                       frames: CampaignFrames | None = None) -> list[dict[str, Any]]:
    """``[{"name": "start", "doc": {...}}, ...]`` in emission order."""
    return list(iter_campaign_documents(sessions, campaign_id, frames))


def iter_campaign_documents(sessions: sessionmaker, campaign_id: str,
                            frames: CampaignFrames | None = None) -> Iterator[dict[str, Any]]:
    """The documents one by one, reading the results in batches (404 before the first); with
    ``frames``, StreamResource and StreamDatum documents point into the frames' file."""
    with sessions() as s:
        row = queries.require_campaign(s, campaign_id)
    return _documents(row, queries.iter_campaign_results(sessions, campaign_id), frames)


def export_campaign_run(sessions: sessionmaker, store: FrameStore, campaign_id: str,
                        out_dir: str | Path) -> dict[str, Any]:
    """Write a campaign as a Bluesky run into ``out_dir``: ``frames.h5`` (the campaign's frames
    file, :func:`~service.export.frame_forms.write_campaign_nexus`) and ``documents.jsonl``
    (``{"name": ..., "doc": ...}`` a line, as Bluesky's ``JSONLinesWriter`` writes them),
    whose StreamResources point at ``frames.h5`` by its ``file://localhost`` URI. Returns
    ``{"documents": {name: count}, "skipped_results": [(pose_index, repeat), ...], "files":
    [...]}``.
    """
    from service.export.frame_forms import write_campaign_nexus

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    docs_path, frames_path = (out / name for name in RUN_FILES)
    written = write_campaign_nexus(sessions, store, campaign_id, frames_path)
    counts: dict[str, int] = {}
    tmp = docs_path.with_name(f".{docs_path.name}.tmp")
    try:
        with tmp.open("w") as fh:
            for doc in iter_campaign_documents(sessions, campaign_id,
                                               CampaignFrames.from_file(frames_path)):
                fh.write(json.dumps(json_safe(doc), allow_nan=False) + "\n")
                counts[doc["name"]] = counts.get(doc["name"], 0) + 1
        tmp.replace(docs_path)
    finally:
        tmp.unlink(missing_ok=True)
    return {"documents": counts, "skipped_results": written["skipped_results"],
            "files": [docs_path, frames_path]}


def _documents(row, results: Iterable,
               frames: CampaignFrames | None = None) -> Iterator[dict[str, Any]]:
    campaign_id = row.id
    run_uid = _uid(campaign_id, "start")
    t_start = row.started_at or row.created_at
    bundle = event_model.compose_run(
        uid=run_uid,
        time=t_start,
        metadata={
            "plan_name": "toftwin_campaign",
            "campaign_id": row.id,
            "campaign_name": row.name,
            "scene_name": row.scene_name,
            "num_points": row.poses_total,
            "motors": ["turntable"],
            "detectors": ["camera", "simulator"],
            "hints": {"dimensions": [[["turntable_deg"], "primary"]]},
            "toftwin_version": package_version(),
            "seed": row.seed,
            "spp": row.spp,
        },
    )
    yield {"name": "start", "doc": bundle.start_doc}
    frame_keys = {} if frames is None else _frame_keys(frames)
    objects = {"camera": ["measured_frame_id"], "simulator": ["simulated_frame_id"]}
    for key in frame_keys:
        objects[key.split("-", 1)[0]].append(key)
    desc = bundle.compose_descriptor(
        name="primary", data_keys={**_data_keys(), **frame_keys}, time=t_start,
        uid=_uid(campaign_id, "primary"),
        hints={"camera": {"fields": ["measured_frame_id"]},
               "simulator": {"fields": ["grey_ssim", "depth_ssim"]}},
        object_keys={"turntable": ["turntable_deg", "turntable_readback_deg"],
                     "solar_simulator": ["solar_suns"], **objects},
    )
    yield {"name": "descriptor", "doc": desc.descriptor_doc}
    keys = [k for k in desc.descriptor_doc["data_keys"] if k not in frame_keys]
    streams = []
    if frames is not None:
        for d in frames.datasets:
            resource = bundle.compose_stream_resource(
                mimetype=HDF5_MIMETYPE, uri=frames.uri, data_key=d.data_key,
                parameters={"dataset": d.dataset, "chunk_shape": list(d.chunk_shape)},
                uid=_uid(campaign_id, "stream_resource", d.data_key))
            yield {"name": "stream_resource", "doc": resource.stream_resource_doc}
            streams.append(resource.compose_stream_datum)
    for seq, r in enumerate(results, start=1):
        at = None if frames is None else frames.index.get((r.pose_index, r.repeat))
        for compose_datum in streams if at is not None else ():
            datum = compose_datum(indices={"start": at, "stop": at + 1},
                                  seq_nums={"start": seq, "stop": seq + 1},
                                  descriptor=desc.descriptor_doc)
            yield {"name": "stream_datum", "doc": datum}
        metrics = json.loads(r.metrics_json)
        rig = json.loads(r.rig_json)
        data: dict[str, Any] = {k: None for k in keys}
        data.update({
            "pose_index": r.pose_index, "repeat": r.repeat, "turntable_deg": r.turntable_deg,
            "turntable_readback_deg": _num(rig.get("turntable_angle_deg")),
            "solar_suns": r.solar_suns, "measured_frame_id": r.measured_frame_id,
            "simulated_frame_id": r.simulated_frame_id, "n_pixels": metrics.get("n_pixels"),
            "grey_chi_square": _num(metrics.get("grey_chi_square")),
        })
        tof = metrics.get("tof") or {}
        for f in TOF_FIELDS:  # None in results stored before these figures
            data[f] = tof.get(f) if f.endswith("pixels") else _num(tof.get(f))
        for ch in ("grey", "depth"):
            for f in CHANNEL_FIELDS:
                data[f"{ch}_{f}"] = _num((metrics.get(ch) or {}).get(f))
        event = desc.compose_event(
            data=data, timestamps={k: r.created_at for k in keys}, seq_num=seq,
            time=r.created_at, uid=_uid(campaign_id, "event", r.pose_index, r.repeat),
        )
        yield {"name": "event", "doc": event}
    if row.state in _EXIT_STATUS:
        stop = bundle.compose_stop(
            exit_status=_EXIT_STATUS[row.state], reason=row.error or "",
            time=row.finished_at or row.updated_at, uid=_uid(campaign_id, "stop"),
        )
        yield {"name": "stop", "doc": stop}
