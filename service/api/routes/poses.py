"""``/api/v1/poses``: move, illuminate, capture, simulate, compare - one pose."""

from __future__ import annotations

import json
from typing import Annotated

from fastapi import APIRouter, Path

from service.api.deps import (
    ExecutorDep,
    LeaseDep,
    SessionDep,
    SessionsDep,
    SettingsDep,
    StoreDep,
    TokenDep,
    errors,
)
from service.api.schemas import PosePublic
from service.errors import NotFoundError
from service.lab.poses import run_single_pose
from service.lab.requests import PoseCreate
from service.store import queries
from service.store.tables import PoseResultRow

router = APIRouter(prefix="/poses", tags=["poses"])


@router.post("", response_model=PosePublic, status_code=201, responses=errors(401, 409, 503, 507))
def pose(
    body: PoseCreate, lease: LeaseDep, sessions: SessionsDep, store: StoreDep,
    executor: ExecutorDep, settings: SettingsDep, _: TokenDep,
) -> dict:
    """Move, illuminate, capture, simulate and compare; the metrics and both frame ids."""
    outcome = run_single_pose(body, lease=lease, sessions=sessions, store=store,
                              executor=executor, settings=settings)
    return pose_public(outcome.row)


@router.get("/{pose_id}", response_model=PosePublic, responses=errors(404))
def get_pose(pose_id: Annotated[int, Path(ge=1, le=2**62)], session: SessionDep) -> dict:
    """A stored pose comparison (ad hoc or of a campaign)."""
    row = queries.get_result(session, pose_id)
    if row is None:
        raise NotFoundError(f"no pose {pose_id}")
    return pose_public(row)


def pose_public(row: PoseResultRow) -> dict:
    """The public form of a result row."""
    metrics = json.loads(row.metrics_json)
    return {
        "id": row.id, "campaign_id": row.campaign_id, "pose_index": row.pose_index,
        "repeat": row.repeat, "turntable_deg": row.turntable_deg, "solar_suns": row.solar_suns,
        "measured_frame_id": row.measured_frame_id,
        "simulated_frame_id": row.simulated_frame_id,
        "metrics": {k: v for k, v in metrics.items() if k != "table"},
        "table": metrics.get("table", []), "rig": json.loads(row.rig_json),
        "timings_s": json.loads(row.timings_json), "created_at": row.created_at,
        "calibration_hash": row.calibration_hash,
    }
