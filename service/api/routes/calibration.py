"""``/api/v1/calibration``: the service's active calibration (read, replace, remove).

Every simulation the service runs applies it (``POST /simulate``, ``POST /poses``, campaigns
created while it is active), and records its hash. The simulated lab's reality is never shown.
"""

from __future__ import annotations

from fastapi import APIRouter, Request, Response
from fastapi.concurrency import run_in_threadpool

from service.api.deps import SessionsDep, TokenDep, errors
from service.api.schemas import CalibrationPublic
from service.lab.calibration import activate, active_public, deactivate, parse_body
from sim_core.twin_file import CalibrationFile

router = APIRouter(prefix="/calibration", tags=["calibration"])


@router.get("", response_model=CalibrationPublic, responses=errors(404))
def get_active_calibration(sessions: SessionsDep) -> dict:
    """The active calibration: its values, hash and provenance, and when it was activated.
    404 while the simulations apply the nominal twin."""
    return active_public(sessions)


@router.put("", response_model=CalibrationPublic, responses=errors(401))
async def set_active_calibration(
    body: CalibrationFile, request: Request, sessions: SessionsDep, _: TokenDep
) -> dict:
    """Make a calibration the active one: the body is a calibration file's content as JSON
    (docs/calibration.md). Validated as a file is; an unknown key or an out-of-range value is a
    422 naming the field, and the active calibration stays as it was."""
    # ``body`` (FastAPI's validation) gives the OpenAPI document its schema and the first
    # checks; the raw body once more, strictly (``true`` is not a number), is what is stored.
    del body
    cal = parse_body(await request.json())
    return await run_in_threadpool(activate, sessions, cal, "PUT /api/v1/calibration")


@router.delete("", status_code=204, responses=errors(401, 404))
def delete_active_calibration(sessions: SessionsDep, _: TokenDep) -> Response:
    """Back to the nominal twin: simulations apply no calibration (404 if none is active)."""
    deactivate(sessions)
    return Response(status_code=204)
