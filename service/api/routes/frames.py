"""``/api/v1/frames``: metadata, arrays (npz) and PNG previews of stored frames."""

from __future__ import annotations

import json
from typing import Annotated, Literal

from fastapi import APIRouter, Path, Query
from fastapi.responses import FileResponse, Response

from service.api.deps import PageDep, SessionDep, SessionsDep, StoreDep, TokenDep, errors
from service.api.schemas import FramePublic
from service.errors import NotFoundError
from service.export.frame_forms import stored_frame_nexus, stored_frame_ply
from service.lab import campaigns as lab_campaigns
from service.store import queries
from sim_core import frame_io
from sim_core.frame_points import POINT_FRAMES
from sim_core.json_safe import json_safe

router = APIRouter(prefix="/frames", tags=["frames"])
FrameIdPath = Annotated[str, Path(pattern=r"^[0-9a-f]{32}$", description="A frame id.")]


@router.get("", response_model=list[FramePublic])
def list_frames(store: StoreDep, session: SessionDep, page: PageDep) -> list[dict]:
    """Stored frames, newest first."""
    return [frame_public(store, row, with_metadata=False)
            for row in queries.list_frames(session, page.limit, page.offset)]


@router.get("/{frame_id}", response_model=FramePublic, responses=errors(404, 410))
def get_frame(frame_id: FrameIdPath, store: StoreDep, session: SessionDep) -> dict:
    """A frame's metadata (its ``frame.json``: rig state, effect plan, timings, ...); 410 if
    that file cannot be read."""
    return frame_public(store, _row(session, frame_id))


@router.delete("/{frame_id}", status_code=204, responses=errors(401, 404, 409, 507))
def delete_frame(
    frame_id: FrameIdPath, sessions: SessionsDep, store: StoreDep, _: TokenDep
) -> Response:
    """Delete a frame that no pose result compares (a capture, a simulation) and its files."""
    lab_campaigns.delete_frame(sessions, store, frame_id)
    return Response(status_code=204)


@router.get("/{frame_id}/arrays", response_class=FileResponse, responses={
    200: {"content": {"application/octet-stream": {}}, "description": "frame.npz"},
    **errors(404, 410)})
def get_frame_arrays(frame_id: FrameIdPath, store: StoreDep, session: SessionDep) -> FileResponse:
    """``frame.npz``: range, depth, amplitude, intensity, phase, valid mask (units in metadata)."""
    _row(session, frame_id)
    return FileResponse(store.checked_file(frame_id, frame_io.FRAME_NPZ),
                        media_type="application/octet-stream", filename=f"{frame_id}.npz")


@router.get("/{frame_id}/raw", response_class=FileResponse, responses={
    200: {"content": {"application/octet-stream": {}}, "description": "raw.npz"},
    **errors(404, 410)})
def get_frame_raw(frame_id: FrameIdPath, store: StoreDep, session: SessionDep) -> FileResponse:
    """``raw.npz``: the four-phase raw frame (measured, or a simulated non-ideal sensor's)."""
    _row(session, frame_id)
    store.file(frame_id, frame_io.FRAME_JSON)  # 410 if the frame's files are gone
    path = store.path(frame_id) / frame_io.RAW_NPZ
    if not path.is_file():
        raise NotFoundError(f"frame {frame_id} has no raw frame (ideal sensor)")
    return FileResponse(store.checked_file(frame_id, frame_io.RAW_NPZ),
                        media_type="application/octet-stream", filename=f"{frame_id}-raw.npz")


@router.get("/{frame_id}/preview/{kind}.png", response_class=FileResponse, responses={
    200: {"content": {"image/png": {}}, "description": "PNG preview"}, **errors(404, 410)})
def get_frame_preview(
    frame_id: FrameIdPath, kind: Literal["grey", "depth"], store: StoreDep, session: SessionDep
) -> FileResponse:
    """8-bit grey, or 16-bit depth in millimetres (0 where invalid), as the camera tools write."""
    _row(session, frame_id)
    return FileResponse(store.checked_file(frame_id, f"{kind}.png"), media_type="image/png")


@router.get("/{frame_id}/export.h5", response_class=Response, responses={
    200: {"content": {"application/x-hdf5": {}},
          "description": "The frame as NeXus HDF5 (docs/export-hdf5.md)"}, **errors(404, 410)})
def get_frame_nexus(frame_id: FrameIdPath, store: StoreDep, session: SessionDep) -> Response:
    """The frame as one NeXus HDF5 file: depth, range, grey, amplitude, intensity, valid,
    phase (and the raw phase images and taps where it has them) as NXdata with axes and units;
    intrinsics, pose, rig state and its frame.json as NXcollections."""
    _row(session, frame_id)
    return Response(stored_frame_nexus(store, frame_id), media_type="application/x-hdf5",
                    headers=_attachment(f"{frame_id}.h5"))


@router.get("/{frame_id}/points.ply", response_class=Response, responses={
    200: {"content": {"application/octet-stream": {}},
          "description": "The valid pixels as a PLY point cloud (docs/export-ply.md)"},
    **errors(404, 410)})
def get_frame_points(
    frame_id: FrameIdPath, store: StoreDep, session: SessionDep,
    frame: Annotated[Literal[POINT_FRAMES], Query(  # type: ignore[valid-type]
        description="camera (x right, y down, z forward) or world (needs the frame's pose: "
                    "a simulated frame has it)")] = "camera",
) -> Response:
    """The frame's valid pixels as points x, y, z [m] with column, row, grey and a noise
    estimate [m] per point (binary PLY); 422 for the world frame of a frame whose pose is not
    known."""
    _row(session, frame_id)
    return Response(stored_frame_ply(store, frame_id, frame),
                    media_type="application/octet-stream",
                    headers=_attachment(f"{frame_id}-{frame}.ply"))


def _attachment(filename: str) -> dict[str, str]:
    return {"Content-Disposition": f'attachment; filename="{filename}"'}


def _row(session, frame_id: str):
    row = queries.get_frame(session, frame_id)
    if row is None:
        raise NotFoundError(f"no frame {frame_id}")
    return row


def frame_public(store, row, with_metadata: bool = True) -> dict:
    """The public form of a frame row (``metadata``: its frame.json)."""
    meta = store.metadata(row.id) if with_metadata else {}
    base = f"/api/v1/frames/{row.id}"
    return json_safe({
        "id": row.id, "kind": row.kind, "created_at": row.created_at,
        "campaign_id": row.campaign_id, "scene_name": row.scene_name,
        "scene_hash": row.scene_hash, "calibration_hash": row.calibration_hash,
        "rig": json.loads(row.rig_json),
        "summary": json.loads(row.summary_json), "metadata": meta,
        "links": {"self": base, "arrays": f"{base}/arrays", "raw": f"{base}/raw",
                  "grey": f"{base}/preview/grey.png", "depth": f"{base}/preview/depth.png",
                  "hdf5": f"{base}/export.h5", "ply": f"{base}/points.ply"},
    })
