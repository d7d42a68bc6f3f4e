"""Dependencies of the routes, as named ``Annotated`` aliases.

``TokenDep`` guards every call that moves hardware or changes data: a bearer token equal to
``TOFTWIN_TOKEN`` (compared in constant time), else 401. Read-only calls take no token.
"""

from __future__ import annotations

import secrets
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import Depends, HTTPException, Query, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session, sessionmaker

from service.api.problems import problem_content
from service.compute.executors import Executor
from service.errors import UnavailableError
from service.lab.background import BackgroundRunner
from service.lab.calibration_jobs import CalibrationJobs
from service.lab.lab import Lab
from service.lab.rig_lease import RigLease
from service.lab.runner import CampaignRunner
from service.lab.scenes import SceneSource
from service.settings import Settings
from service.store.frame_files import FrameStore

_bearer = HTTPBearer(auto_error=False, description="The service token (TOFTWIN_TOKEN).")


def get_lab(request: Request) -> Lab:
    """The running service's lab (assembled at startup)."""
    return request.app.state.lab


LabDep = Annotated[Lab, Depends(get_lab)]


def _of_lab(attribute: str) -> Callable[[Lab], Any]:
    """The dependency that answers the running lab's ``attribute``."""

    def dependency(lab: LabDep) -> Any:
        return getattr(lab, attribute)

    dependency.__name__ = f"get_{attribute}"
    return dependency


def get_session(lab: LabDep) -> Iterator[Session]:
    """A database session for one request."""
    with lab.session() as session:
        yield session


class StreamSlots:
    """A bound on the event streams open at once (each holds a connection and a poll loop)."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._open = 0
        self._lock = threading.Lock()

    def take(self) -> None:
        """One more stream, or 503 when ``limit`` are open."""
        with self._lock:
            if self._open >= self.limit:
                raise UnavailableError(
                    f"{self._open} event streams are open, the most this service serves "
                    "(TOFTWIN_SSE_MAX_STREAMS); poll GET /api/v1/campaigns/{id} or retry later")
            self._open += 1

    def give_back(self) -> None:
        with self._lock:
            self._open = max(0, self._open - 1)


def get_stream_slots(request: Request) -> StreamSlots:
    return request.app.state.stream_slots


SettingsDep = Annotated[Settings, Depends(_of_lab("settings"))]
StreamSlotsDep = Annotated[StreamSlots, Depends(get_stream_slots)]
SessionDep = Annotated[Session, Depends(get_session)]
SessionsDep = Annotated[sessionmaker, Depends(_of_lab("sessions"))]
StoreDep = Annotated[FrameStore, Depends(_of_lab("store"))]
ExecutorDep = Annotated[Executor, Depends(_of_lab("executor"))]
LeaseDep = Annotated[RigLease, Depends(_of_lab("lease"))]
RunnerDep = Annotated[CampaignRunner, Depends(_of_lab("runner"))]
SceneDep = Annotated[SceneSource, Depends(_of_lab("default_scene"))]
CalibrationsDep = Annotated[CalibrationJobs, Depends(_of_lab("calibrations"))]
BackgroundDep = Annotated[BackgroundRunner, Depends(_of_lab("background"))]
#: a page of a list: at most ``limit`` rows (100 unless the route says otherwise) ...
Limit = Annotated[int, Query(ge=1, le=1000)]
#: ... from row ``offset`` (0: the first)
Offset = Annotated[int, Query(ge=0, le=2**31)]


@dataclass(frozen=True)
class Page:
    """The page a list route answers (its ``limit`` and ``offset`` query parameters): at most
    ``limit`` rows, newest first, from row ``offset``."""

    limit: Limit = 100
    offset: Offset = 0


PageDep = Annotated[Page, Depends()]


def require_token(
    settings: SettingsDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> None:
    """401 unless the request carries ``Authorization: Bearer <TOFTWIN_TOKEN>``."""
    expected = settings.token.get_secret_value().encode()
    given = credentials.credentials.encode() if credentials is not None else b""
    if credentials is None or credentials.scheme.lower() != "bearer" or not (
        secrets.compare_digest(given, expected)
    ):
        raise HTTPException(
            status_code=status.HTTP_401_UNAUTHORIZED,
            detail="a valid bearer token is required for this call (Authorization: Bearer ...)",
            headers={"WWW-Authenticate": "Bearer"},
        )


TokenDep = Annotated[None, Depends(require_token)]

#: documented error responses, shared by the routes (each an RFC 9457 problem,
#: :mod:`service.api.problems`; 422 is declared wherever a route takes input)
ERRORS = {
    401: "Missing or wrong bearer token.",
    404: "No such resource.",
    409: "A campaign or calibration job holds the rig, or the resource is in the wrong state.",
    410: "The resource is known but its files are gone from the data directory (`gone`) or "
         "one of them cannot be read (`damaged-file`); `detail` names the frame and the file.",
    503: "A device fault (`fault`: the driver's error class; `detail`: its message), or a "
         "device, the executor or an event stream not available.",
    507: "Too little free space on the data directory's disk, or a write found it full "
         "(`detail` names what was being written; nothing of it was kept).",
}


def errors(*codes: int) -> dict[int | str, dict]:
    """The ``responses=`` entry of a route for the error statuses it can answer."""
    return {c: {"description": ERRORS[c], "content": problem_content()} for c in codes}
