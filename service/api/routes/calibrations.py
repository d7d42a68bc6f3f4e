"""``/api/v1/calibrations``: the calibration sequence on the rig as background jobs."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import aclosing
from functools import partial
from typing import Annotated

from fastapi import APIRouter, Depends, Path
from fastapi.responses import FileResponse
from fastapi.sse import EventSourceResponse, ServerSentEvent

from service.api.deps import (
    CalibrationsDep,
    PageDep,
    SessionDep,
    SessionsDep,
    SettingsDep,
    StreamSlotsDep,
    TokenDep,
    errors,
)
from service.api.events import status_events
from service.api.schemas import CalibrationJobPublic, CalibrationPublic
from service.api.security_headers import self_contained_document
from service.lab.calibration_jobs import job_file, job_public, job_status
from service.lab.requests import CalibrationCreate
from service.store import queries

router = APIRouter(prefix="/calibrations", tags=["calibration"])
JobId = Annotated[str, Path(pattern=r"^[0-9a-f]{32}$", description="A calibration job id.")]
FileName = Annotated[str, Path(pattern=r"^[A-Za-z0-9_-]{1,64}\.(yaml|yml|json|html|png)$",
                               description="calibration.yaml, verdicts.json, report.json, "
                               "report.html, opencv_intrinsics.yml or a plot of the report.")]
COMMAND = errors(401, 404, 409)
_MEDIA = {"yaml": "application/yaml", "yml": "application/yaml", "json": "application/json",
          "html": "text/html", "png": "image/png"}

@router.post("", response_model=CalibrationJobPublic, status_code=201,
             responses=errors(401, 409, 503, 507))
def create_calibration_job(
    body: CalibrationCreate, calibrations: CalibrationsDep, sessions: SessionsDep, _: TokenDep
) -> dict:
    """Run the calibration sequence (``toftwin calibrate rig``) on the rig in the background.

    Claims the rig: 409 while a campaign or another job holds it, and campaigns, manual device
    calls and ``POST /poses`` get 409 while it runs. Follow it with ``GET /calibrations/{id}``
    or its events."""
    job_id = calibrations.create(body)
    return job_status(sessions, calibrations, job_id)

@router.get("", response_model=list[CalibrationJobPublic])
def list_calibration_jobs(
    session: SessionDep, calibrations: CalibrationsDep, page: PageDep
) -> list[dict]:
    """Calibration jobs, newest first."""
    return [job_public(row, calibrations.live(row.id))
            for row in queries.list_calibration_jobs(session, page.limit, page.offset)]

@router.get("/{job_id}", response_model=CalibrationJobPublic, responses=errors(404))
def get_calibration_job(
    job_id: JobId, sessions: SessionsDep, calibrations: CalibrationsDep,
) -> dict:
    """State, progress, what the sequence is doing, the error and what to do, the files."""
    return job_status(sessions, calibrations, job_id)

@router.post("/{job_id}/cancel", response_model=CalibrationJobPublic, responses=COMMAND)
def cancel_calibration_job(
    job_id: JobId, sessions: SessionsDep, calibrations: CalibrationsDep, _: TokenDep
) -> dict:
    """Stop a running job before its next capture (it cannot be resumed)."""
    calibrations.cancel(job_id)
    return job_status(sessions, calibrations, job_id)

@router.post("/{job_id}/continue", response_model=CalibrationJobPublic, responses=COMMAND)
def continue_calibration_job(
    job_id: JobId, sessions: SessionsDep, calibrations: CalibrationsDep, _: TokenDep
) -> dict:
    """The operator has done what ``operator_instruction`` asked (real rig): go on."""
    calibrations.confirm_mounted(job_id)
    return job_status(sessions, calibrations, job_id)

@router.post("/{job_id}/activate", response_model=CalibrationPublic,
             responses=errors(401, 404, 409, 410))
def activate_calibration_job(job_id: JobId, calibrations: CalibrationsDep, _: TokenDep) -> dict:
    """Make a ``done`` job's calibration the service's active calibration."""
    return calibrations.activate(job_id)

@router.get("/{job_id}/files/{name}", response_class=FileResponse,
            responses=errors(404, 409, 410), dependencies=[Depends(self_contained_document)])
def get_calibration_job_file(job_id: JobId, name: FileName, sessions: SessionsDep) -> FileResponse:
    """An output file of a ``done`` job: ``calibration.yaml``, ``verdicts.json``,
    ``report.json``, ``report.html`` (its plots load from beside it), and the camera in
    OpenCV's form, ``opencv_intrinsics.yml`` (docs/export.md)."""
    path = job_file(sessions, job_id, name)
    return FileResponse(path, media_type=_MEDIA[path.suffix.lstrip(".")])

def _key(sessions, job_id: str) -> tuple:
    with sessions() as s:
        row = queries.require_calibration_job(s, job_id)
    return (row.state, row.updated_at)

def _stream_slot(job_id: JobId, sessions: SessionsDep, slots: StreamSlotsDep) -> None:
    """404 for an unknown job, 503 when too many streams are open (before streaming)."""
    _key(sessions, job_id)
    slots.take()

@router.get("/{job_id}/events", response_class=EventSourceResponse, responses=errors(404, 503))
async def get_calibration_job_events(
    job_id: JobId, sessions: SessionsDep, calibrations: CalibrationsDep, settings: SettingsDep,
    slots: StreamSlotsDep, _: Annotated[None, Depends(_stream_slot)],
) -> AsyncIterator[ServerSentEvent]:
    """Server-sent events: the job's status (as ``GET``) whenever it changes (every step of the
    sequence), until it is done, failed or cancelled. Bounded like the campaigns' streams."""
    events = status_events(partial(_key, sessions, job_id),
                           partial(job_status, sessions, calibrations, job_id),
                           terminal=queries.CALIBRATION_TERMINAL, settings=settings,
                           slots=slots)
    async with aclosing(events):
        async for event in events:
            yield event
