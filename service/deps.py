"""Dependencies of the routes, as named ``Annotated`` aliases.

``TokenDep`` guards every call that moves hardware or changes data: a bearer token equal to
``TOFTWIN_TOKEN`` (compared in constant time), else 401. Read-only calls take no token.
"""

from __future__ import annotations

import secrets
from collections.abc import Iterator
from typing import Annotated

from fastapi import Depends, HTTPException, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session

from service.context import ServiceContext

_bearer = HTTPBearer(auto_error=False, description="The service token (TOFTWIN_TOKEN).")


def get_ctx(request: Request) -> ServiceContext:
    """The running service's state."""
    return request.app.state.ctx


CtxDep = Annotated[ServiceContext, Depends(get_ctx)]


def get_session(ctx: CtxDep) -> Iterator[Session]:
    """A database session for one request."""
    with ctx.session() as session:
        yield session


SessionDep = Annotated[Session, Depends(get_session)]


def require_token(
    ctx: CtxDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> None:
    """401 unless the request carries ``Authorization: Bearer <TOFTWIN_TOKEN>``."""
    expected = ctx.settings.token.get_secret_value().encode()
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

#: documented error responses, shared by the routes
ERRORS = {
    401: {"description": "Missing or wrong bearer token."},
    404: {"description": "No such resource."},
    409: {"description": "A campaign holds the rig, or the resource is in the wrong state."},
    422: {"description": "Invalid input; the message names the field and the allowed range."},
    503: {"description": "A device fault (the device's message) or a device not available."},
}


def errors(*codes: int) -> dict[int | str, dict]:
    """The ``responses=`` entry of a route for the given error codes."""
    from service.schemas import Message

    return {c: {**ERRORS[c], "model": Message} for c in codes if c != 422}
