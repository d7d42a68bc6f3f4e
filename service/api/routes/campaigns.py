"""``/api/v1/campaigns``: create, start / pause / resume / cancel, follow, export."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from typing import Annotated, Literal

from fastapi import APIRouter, Depends, Path, Query
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import HTMLResponse, PlainTextResponse
from fastapi.sse import EventSourceResponse, ServerSentEvent

from service.api.deps import (
    LeaseDep,
    RunnerDep,
    SessionDep,
    SessionsDep,
    SettingsDep,
    StoreDep,
    StreamSlotsDep,
    TokenDep,
    errors,
)
from service.api.schemas import CampaignCreated, CampaignPublic, ResultPublic
from service.export.bluesky import campaign_documents
from service.export.report import campaign_report
from service.export.results_table import result_rows, results_csv
from service.lab.campaigns import campaign_status, create_campaign, status_key
from service.lab.requests import CampaignCreate
from service.store import queries

router = APIRouter(prefix="/campaigns", tags=["campaigns"])
CampaignId = Annotated[str, Path(pattern=r"^[0-9a-f]{32}$", description="A campaign id.")]
COMMAND = errors(401, 404, 409, 503)


@router.post("", response_model=CampaignCreated, status_code=201, responses=errors(401))
def create(
    body: CampaignCreate, sessions: SessionsDep, settings: SettingsDep, lease: LeaseDep,
    _: TokenDep,
) -> dict:
    """Store a campaign (state ``created``); ``start`` runs it."""
    cid = create_campaign(body, sessions=sessions, settings=settings, rig=lease.rig)
    return {"id": cid, "state": "created", "links": {"self": f"/api/v1/campaigns/{cid}"}}


@router.get("", response_model=list[CampaignPublic])
def list_campaigns(
    sessions: SessionsDep,
    runner: RunnerDep,
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    offset: Annotated[int, Query(ge=0, le=2**31)] = 0,
) -> list[dict]:
    """Campaigns, newest first."""
    rows = queries.list_campaigns(session, limit, offset)
    return [campaign_status(sessions, runner, row.id) for row in rows]


@router.get("/{campaign_id}", response_model=CampaignPublic, responses=errors(404))
def get_campaign(campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep) -> dict:
    """State, poses done of total, the current pose and the estimated time left."""
    return campaign_status(sessions, runner, campaign_id)


@router.post("/{campaign_id}/start", response_model=CampaignPublic, responses=COMMAND)
def start(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, _: TokenDep
) -> dict:
    """Run a ``created`` campaign in the background (409 if another one runs)."""
    runner.start(campaign_id)
    return campaign_status(sessions, runner, campaign_id)


@router.post("/{campaign_id}/pause", response_model=CampaignPublic, responses=COMMAND)
def pause(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, _: TokenDep
) -> dict:
    """Stop after the poses in flight (they are kept); ``resume`` goes on from there."""
    runner.pause(campaign_id)
    return campaign_status(sessions, runner, campaign_id)


@router.post("/{campaign_id}/resume", response_model=CampaignPublic, responses=COMMAND)
def resume(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, _: TokenDep
) -> dict:
    """Continue a ``paused``, ``interrupted`` or ``failed`` campaign at its first missing pose."""
    runner.start(campaign_id, resume=True)
    return campaign_status(sessions, runner, campaign_id)


@router.post("/{campaign_id}/cancel", response_model=CampaignPublic, responses=COMMAND)
def cancel(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, _: TokenDep
) -> dict:
    """Stop for good (results so far are kept)."""
    runner.cancel(campaign_id)
    return campaign_status(sessions, runner, campaign_id)


def _stream_slot(
    campaign_id: CampaignId, sessions: SessionsDep, runner: RunnerDep, slots: StreamSlotsDep
) -> None:
    """404 for an unknown campaign, 503 when too many streams are open (before streaming)."""
    status_key(sessions, runner, campaign_id)
    slots.take()


@router.get("/{campaign_id}/events", response_class=EventSourceResponse,
            responses=errors(404, 503))
async def events(
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
    try:
        deadline = time.monotonic() + settings.sse_max_s
        last = None
        while True:
            key = await run_in_threadpool(status_key, sessions, runner, campaign_id)
            if key != last:
                last = key
                status = await run_in_threadpool(campaign_status, sessions, runner, campaign_id)
                yield ServerSentEvent(data=status, event="status", id=str(status["poses_done"]),
                                      retry=int(settings.sse_interval_s * 4000))
                if status["state"] in queries.TERMINAL:
                    return
            if time.monotonic() > deadline:
                return
            await asyncio.sleep(settings.sse_interval_s)
    finally:
        slots.give_back()


@router.get("/{campaign_id}/results", response_model=list[ResultPublic], responses={
    200: {"content": {"text/csv": {}}}, **errors(404)})
def results(
    campaign_id: CampaignId,
    sessions: SessionsDep,
    format: Annotated[Literal["json", "csv"], Query()] = "json",
):
    """One row per pose and repeat: metrics and both frame ids (``?format=csv``: CSV)."""
    rows = result_rows(sessions, campaign_id)
    if format == "csv":
        return PlainTextResponse(results_csv(rows), media_type="text/csv")
    return rows


@router.get("/{campaign_id}/report", response_class=HTMLResponse, responses=errors(404))
def report(campaign_id: CampaignId, sessions: SessionsDep, store: StoreDep) -> HTMLResponse:
    """An HTML page: metrics over the poses, image panels measured / simulated / difference."""
    return HTMLResponse(campaign_report(sessions, store, campaign_id))


@router.get("/{campaign_id}/documents", responses=errors(404))
def documents(campaign_id: CampaignId, sessions: SessionsDep) -> list[dict]:
    """The campaign as Bluesky event-model documents: ``[{"name": ..., "doc": ...}, ...]``."""
    return campaign_documents(sessions, campaign_id)
