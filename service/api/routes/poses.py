"""``/api/v1/poses``: move, illuminate, capture, simulate, compare - one pose."""

from __future__ import annotations

import json
from typing import Annotated, Literal

from fastapi import APIRouter, Path
from fastapi.responses import Response

from service.api.deps import (
    ExecutorDep,
    LeaseDep,
    SceneDep,
    SessionDep,
    SessionsDep,
    SettingsDep,
    StoreDep,
    TokenDep,
    errors,
)
from service.api.schemas import PosePublic
from service.errors import GoneError, NotFoundError
from service.export.panels import PANEL_NAMES, png_bytes, pose_panels
from service.lab.poses import run_single_pose
from service.lab.requests import PoseCreate
from service.store import queries
from service.store.tables import PoseResultRow
from sim_core.preview import colour_bar_png

router = APIRouter(prefix="/poses", tags=["poses"])
PoseId = Annotated[int, Path(ge=1, le=2**62, description="A pose result's id.")]
PanelName = Annotated[Literal[PANEL_NAMES], Path(description="Which image of the pose.")]  # type: ignore[valid-type]
PNG = {200: {"content": {"image/png": {}}, "description": "PNG image"}, **errors(404, 410)}


@router.post("", response_model=PosePublic, status_code=201, responses=errors(401, 409, 503, 507))
def create_pose(
    body: PoseCreate, lease: LeaseDep, sessions: SessionsDep, store: StoreDep,
    executor: ExecutorDep, settings: SettingsDep, mounted: SceneDep, _: TokenDep,
) -> dict:
    """Move, illuminate, capture, simulate and compare; the metrics and both frame ids."""
    outcome = run_single_pose(body, lease=lease, sessions=sessions, store=store,
                              executor=executor, settings=settings, mounted=mounted)
    return pose_public(outcome.row)


@router.get("/{pose_id}", response_model=PosePublic, responses=errors(404))
def get_pose(pose_id: PoseId, session: SessionDep) -> dict:
    """A stored pose comparison (ad hoc or of a campaign)."""
    return pose_public(require_pose(session, pose_id))


@router.get("/{pose_id}/panels/{name}.png", response_class=Response, responses=PNG)
def get_pose_panel(pose_id: PoseId, name: PanelName, session: SessionDep,
                store: StoreDep) -> Response:
    """One of the pose's six images (grey and depth: measured, simulated, difference) in
    colour, pixel for pixel; its colour bar is ``colour-bar.png`` beside it."""
    return Response(png_bytes(_panel(session, store, pose_id, name).rgb), media_type="image/png")


@router.get("/{pose_id}/panels/{name}/colour-bar.png", response_class=Response, responses=PNG)
def get_pose_panel_colour_bar(pose_id: PoseId, name: PanelName, session: SessionDep,
                     store: StoreDep) -> Response:
    """The colour bar of one of the pose's images: its colour map, range and unit."""
    panel = _panel(session, store, pose_id, name)
    return Response(colour_bar_png(panel.scale, panel.label), media_type="image/png")


def _panel(session, store, pose_id: int, name: str):
    row = require_pose(session, pose_id)
    try:
        panels = pose_panels(store, row.measured_frame_id, row.simulated_frame_id)
    except GoneError as exc:  # 410 naming the pose too (the detail names frame and file)
        raise type(exc)(f"pose {pose_id}: {exc.detail}") from exc
    return panels[PANEL_NAMES.index(name)]


def require_pose(session, pose_id: int) -> PoseResultRow:
    """The result row ``pose_id``, else 404."""
    row = queries.get_result(session, pose_id)
    if row is None:
        raise NotFoundError(f"no pose {pose_id}")
    return row


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
