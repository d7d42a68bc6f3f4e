"""``/api/v1/campaigns``: create, start / pause / resume / cancel, follow, export."""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from contextlib import aclosing
from functools import partial
from typing import Annotated, Literal

from fastapi import APIRouter, Depends, Path, Query, Response
from fastapi.responses import FileResponse, HTMLResponse, StreamingResponse
from fastapi.sse import EventSourceResponse, ServerSentEvent

from service.api.deps import (
    LeaseDep,
    Offset,
    PageDep,
    RunnerDep,
    SceneDep,
    SessionDep,
    SessionsDep,
    SettingsDep,
    StoreDep,
    StreamSlotsDep,
    TokenDep,
    errors,
)
from service.api.events import status_events
from service.api.schemas import CampaignCreated, CampaignPublic, ResultPublic
from service.api.security_headers import self_contained_document
from service.errors import ConflictError, NotFoundError
from service.export.bluesky import CampaignFrames, iter_campaign_documents
from service.export.frame_forms import campaign_frames_file, campaign_frames_path
from service.export.plots import PLOTS, plot_svg
from service.export.report import campaign_report
from service.export.results_table import result_dict, result_rows, results_csv
from service.lab import campaigns as lab_campaigns
from service.lab.campaigns import campaign_status, status_key
from service.lab.requests import CampaignCreate
from service.store import queries
from service.store.disk_space import require_free, writing
from sim_core.json_safe import json_safe

router = APIRouter(prefix="/campaigns", tags=["campaigns"])
CampaignId = Annotated[str, Path(pattern=r"^[0-9a-f]{32}$", description="A campaign id.")]
COMMAND = errors(401, 404, 409, 503)


@router.post("", response_model=CampaignCreated, status_code=201, responses=errors(401, 409))
def create_campaign(
    body: CampaignCreate, sessions: SessionsDep, settings: SettingsDep, lease: LeaseDep,
    mounted: SceneDep, _: TokenDep,
) -> dict:
    """Store a campaign (state ``created``); ``start`` runs it."""
    cid = lab_campaigns.create_campaign(body, sessions=sessions, settings=settings,
                                        rig=lease.rig, mounted=mounted)
    return {"id": cid, "state": "created", "links": {"self": f"/api/v1/campaigns/{cid}"}}


@router.get("", response_model=list[CampaignPublic])
def list_campaigns(
    sessions: SessionsDep, runner: RunnerDep, session: SessionDep, page: PageDep
) -> list[dict]:
    """Campaigns, newest first."""
    rows = queries.list_campaigns(session, page.limit, page.offset)
    return [campaign_status(sessions, runner, row.id) for row in rows]


@router.get("/{campaign_id}", response_model=CampaignPublic, responses=errors(404))
def get_campaign(campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep) -> dict:
    """State, poses done of total, the current pose and the estimated time left."""
    return campaign_status(sessions, runner, campaign_id)


@router.delete("/{campaign_id}", status_code=204, responses=errors(401, 404, 409, 507))
def delete_campaign(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, store: StoreDep,
    _: TokenDep,
) -> Response:
    """Delete a campaign that is not running, with its results and frames (reclaims space; works
    on a full disk, see docs/service.md)."""
    lab_campaigns.delete_campaign(sessions, runner, store, campaign_id)
    return Response(status_code=204)


@router.post("/{campaign_id}/start", response_model=CampaignPublic, responses=COMMAND)
def start_campaign(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, _: TokenDep
) -> dict:
    """Run a ``created`` campaign in the background (409 if another one runs)."""
    runner.start(campaign_id)
    return campaign_status(sessions, runner, campaign_id)


@router.post("/{campaign_id}/pause", response_model=CampaignPublic, responses=COMMAND)
def pause_campaign(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, _: TokenDep
) -> dict:
    """Stop after the poses in flight (they are kept); ``resume`` goes on from there."""
    runner.pause(campaign_id)
    return campaign_status(sessions, runner, campaign_id)


@router.post("/{campaign_id}/resume", response_model=CampaignPublic, responses=COMMAND)
def resume_campaign(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, _: TokenDep
) -> dict:
    """Continue a ``paused``, ``interrupted`` or ``failed`` campaign at its first missing pose."""
    runner.start(campaign_id, resume=True)
    return campaign_status(sessions, runner, campaign_id)


@router.post("/{campaign_id}/cancel", response_model=CampaignPublic, responses=COMMAND)
def cancel_campaign(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, _: TokenDep
) -> dict:
    """Stop for good (results so far are kept)."""
    runner.cancel(campaign_id)
    return campaign_status(sessions, runner, campaign_id)


def _poses_done(status: dict, sent: int) -> str:
    """A campaign's event id: the poses done when it was sent."""
    return str(status["poses_done"])


def _stream_slot(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, slots: StreamSlotsDep
) -> None:
    """404 for an unknown campaign, 503 when too many streams are open (before streaming)."""
    status_key(sessions, runner, campaign_id)
    slots.take()


@router.get("/{campaign_id}/events", response_class=EventSourceResponse,
            responses=errors(404, 503))
async def get_campaign_events(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, settings: SettingsDep,
    slots: StreamSlotsDep, _: Annotated[None, Depends(_stream_slot)],
) -> AsyncIterator[ServerSentEvent]:
    """Server-sent events: the campaign's status (as ``GET``) whenever it changes.

    The status is sent when the stream opens and after every change (a result, a state, the
    pose being worked on), never again unchanged; in between the stream asks the database one
    small question per interval. The stream ends after a final state (completed, cancelled,
    failed); a browser follows it with ``new EventSource(url)``. At most ``sse_max_streams``
    streams are open at once (503 beyond).
    """
    events = status_events(partial(status_key, sessions, runner, campaign_id),
                           partial(campaign_status, sessions, runner, campaign_id),
                           terminal=queries.TERMINAL, settings=settings, slots=slots,
                           event_id=_poses_done)
    async with aclosing(events):
        async for event in events:
            yield event


#: results a page of ``GET /campaigns/{id}/results`` holds unless ``limit`` says otherwise
RESULTS_PAGE = 1000


@router.get("/{campaign_id}/results", response_model=list[ResultPublic], responses={
    200: {"content": {"text/csv": {}},
          "description": "A page of results; `X-Total-Count` holds how many there are, a `Link` "
                         "header with `rel=\"next\"` the next page while there is one."},
    **errors(404)})
def list_campaign_results(
    campaign_id: CampaignId,
    sessions: SessionsDep,
    response: Response,
    format: Annotated[Literal["json", "csv"], Query()] = "json",
    limit: Annotated[int, Query(ge=1, le=10000)] = RESULTS_PAGE,
    offset: Offset = 0,
):
    """One row per pose and repeat: metrics and both frame ids, a page at a time (``limit``
    rows from ``offset``, 1000 by default). ``?format=csv``: every row as CSV, streamed."""
    if format == "csv":
        with sessions() as s:
            queries.require_campaign(s, campaign_id)  # 404 before the stream starts
        rows = (result_dict(r) for r in queries.iter_campaign_results(sessions, campaign_id))
        return StreamingResponse(results_csv(rows), media_type="text/csv")
    rows = result_rows(sessions, campaign_id, limit=limit, offset=offset)
    with sessions() as s:
        total = queries.count_results(s, campaign_id)
    response.headers["X-Total-Count"] = str(total)
    if offset + len(rows) < total:
        nxt = f"/api/v1/campaigns/{campaign_id}/results?limit={limit}&offset={offset + limit}"
        response.headers["Link"] = f'<{nxt}>; rel="next"'
    return rows


@router.get("/{campaign_id}/report", response_class=HTMLResponse, responses=errors(404),
            dependencies=[Depends(self_contained_document)])
def get_campaign_report(
    campaign_id: CampaignId, sessions: SessionsDep, store: StoreDep,
) -> HTMLResponse:
    """An HTML page: metrics over the poses, image panels measured / simulated / difference."""
    return HTMLResponse(campaign_report(sessions, store, campaign_id))


@router.get("/{campaign_id}/recording", response_class=FileResponse, responses={
    200: {"content": {"application/x-hdf5": {}},
          "description": "The campaign's recording (HDF5, docs/recordings.md)"},
    **errors(404, 409)})
def get_campaign_recording(campaign_id: CampaignId, sessions: SessionsDep,
                           settings: SettingsDep) -> FileResponse:
    """The recording a campaign created with ``record: true`` writes: every captured raw frame
    with its rig state, to replay (``toftwin replay``, a campaign with source 'recording') or
    to share. 404 for a campaign that records nothing or has captured nothing yet."""
    with sessions() as s:
        row = queries.require_campaign(s, campaign_id)
    if row.state == "running" and row.record_path is not None:
        raise ConflictError(f"campaign {campaign_id} is running and still writing its "
                            "recording; download it once the campaign is paused, completed or "
                            "cancelled")
    path = lab_campaigns.recording_file(row, settings.data_dir)
    if path is None:
        raise NotFoundError(f"campaign {campaign_id} has no recording"
                            + ("" if row.record_path is None else " yet"))
    return FileResponse(path, media_type="application/x-hdf5", filename=path.name)


@router.get("/{campaign_id}/frames.h5", response_class=FileResponse, responses={
    200: {"content": {"application/x-hdf5": {}},
          "description": "The campaign's frames as NeXus HDF5 (docs/export-hdf5.md)"},
    **errors(404, 507)})
def get_campaign_frames(campaign_id: CampaignId, sessions: SessionsDep, store: StoreDep,
                        settings: SettingsDep) -> FileResponse:
    """Every result's measured and simulated frames (and the fitted twin's, where each result
    has one) in one NeXus HDF5 file, result by result, with each result's metrics; a result
    whose frame folders are gone is left out (the file's ``skipped_results``). The file is
    kept in the data directory and made again only when the results have changed; the
    documents' StreamResources (``documents?frames=hdf5``) point into this same file."""
    return FileResponse(_frames_file(sessions, store, settings, campaign_id),
                        media_type="application/x-hdf5", filename=f"campaign-{campaign_id}.h5")


def _frames_file(sessions, store, settings, campaign_id: str):
    """The campaign's kept frames file (507 below the free space kept, before writing)."""
    with sessions() as s:
        queries.require_campaign(s, campaign_id)  # 404 before anything is written
    path = campaign_frames_path(store, campaign_id)
    if not path.is_file():
        require_free(store.root, settings.min_free_bytes)
    with writing("the campaign's frames file", store.root, settings.min_free_bytes):
        return campaign_frames_file(sessions, store, campaign_id)


@router.get("/{campaign_id}/plots/{name}.svg", response_class=Response, responses={
    200: {"content": {"image/svg+xml": {}}, "description": "An SVG plot"}, **errors(404)},
    dependencies=[Depends(self_contained_document)])
def get_campaign_plot(
    campaign_id: CampaignId,
    name: Annotated[Literal[tuple(PLOTS)], Path(description="Which plot.")],  # type: ignore[valid-type]
    sessions: SessionsDep,
) -> Response:
    """A metric over the poses so far (first repeats), as in the report: ``ssim``, ``psnr``,
    ``depth-mean``, ``grey-mean``; with an object fit ``explained-depth-rmse`` and
    ``explained-grey-psnr`` (nominal twin, fitted twin, noise ceiling)."""
    rows = [r for r in result_rows(sessions, campaign_id) if r["repeat"] == 0]
    return Response(plot_svg(PLOTS[name], rows), media_type="image/svg+xml",
                    headers={"Cache-Control": "no-store"})


@router.get("/{campaign_id}/documents", responses=errors(404, 507))
def get_campaign_documents(
    campaign_id: CampaignId, sessions: SessionsDep, store: StoreDep, settings: SettingsDep,
    frames: Annotated[Literal["ids", "hdf5"], Query(
        description="ids: events name their frames by id (arrays at /api/v1/frames/{id}); "
                    "hdf5: StreamResource/StreamDatum documents point into the campaign's "
                    "frames file (frames.h5, kept in the data directory) by its "
                    "file://localhost URI, as a Bluesky detector's do")] = "ids",
) -> StreamingResponse:
    """The campaign as Bluesky event-model documents: ``[{"name": ..., "doc": ...}, ...]``.

    Streamed as it is read (the results in batches), so a campaign of any size costs the
    service bounded memory.
    """
    stream = None
    if frames == "hdf5":
        stream = CampaignFrames.from_file(_frames_file(sessions, store, settings, campaign_id))
    docs = iter_campaign_documents(sessions, campaign_id, stream)  # 404 here, before the stream

    def json_array():
        yield "["
        for i, doc in enumerate(docs):
            yield ("," if i else "") + json.dumps(json_safe(doc), allow_nan=False)
        yield "]"

    return StreamingResponse(json_array(), media_type="application/json")
