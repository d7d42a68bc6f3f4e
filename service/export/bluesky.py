"""A campaign as Bluesky event-model documents: run start, one descriptor, one event per pose
and repeat, and (once the campaign is over) run stop.

Built with :func:`event_model.compose_run`, which validates every document against the
``event-model`` JSON schemas as it composes it. Uids are derived from the campaign id (UUID5),
so the same campaign gives the same documents every time they are asked for. Frames are
referenced by id (``measured_frame_id``, ``simulated_frame_id``); their arrays are at
``/api/v1/frames/{id}/arrays``. Non-finite metrics (PSNR of identical images) are ``None``, and
so are the depth-difference figures of a result stored before they were computed.
"""

from __future__ import annotations

import json
import math
import uuid
from collections.abc import Iterable, Iterator
from typing import Any

import event_model
from sqlalchemy.orm import sessionmaker

from service.export.results_table import CHANNEL_FIELDS, TOF_FIELDS
from service.store import queries
from sim_core.frame_io import package_version

_NAMESPACE = uuid.UUID("6c1f6c3e-3a55-4b8e-9a8e-0f7a1d9b2c11")
_EXIT_STATUS = {"completed": "success", "cancelled": "abort", "failed": "fail"}


def _uid(*parts: object) -> str:
    return str(uuid.uuid5(_NAMESPACE, "/".join(str(p) for p in parts)))


def _num(value: Any) -> float | None:
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    return None


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


def campaign_documents(sessions: sessionmaker, campaign_id: str) -> list[dict[str, Any]]:
    """``[{"name": "start", "doc": {...}}, ...]`` in emission order."""
    return list(iter_campaign_documents(sessions, campaign_id))


def iter_campaign_documents(sessions: sessionmaker, campaign_id: str) -> Iterator[dict[str, Any]]:
    """The documents one by one, reading the results in batches (404 before the first)."""
    with sessions() as s:
        row = queries.require_campaign(s, campaign_id)
    return _documents(row, queries.iter_campaign_results(sessions, campaign_id))


def _documents(row, results: Iterable) -> Iterator[dict[str, Any]]:
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
    desc = bundle.compose_descriptor(
        name="primary", data_keys=_data_keys(), time=t_start, uid=_uid(campaign_id, "primary"),
        hints={"camera": {"fields": ["measured_frame_id"]},
               "simulator": {"fields": ["grey_ssim", "depth_ssim"]}},
        object_keys={"turntable": ["turntable_deg", "turntable_readback_deg"],
                     "solar_simulator": ["solar_suns"],
                     "camera": ["measured_frame_id"],
                     "simulator": ["simulated_frame_id"]},
    )
    yield {"name": "descriptor", "doc": desc.descriptor_doc}
    keys = desc.descriptor_doc["data_keys"]
    for seq, r in enumerate(results, start=1):
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
