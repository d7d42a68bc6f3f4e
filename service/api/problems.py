"""RFC 9457 problem details: the one shape of every error the service answers.

Every error response, whatever raised it (a route, request validation, the bearer token, the
router for an unknown path or method, the body limit, an unexpected exception), is
``application/problem+json``::

    {"type": "urn:toftwin:problem:invalid-input", "title": "Invalid input", "status": 422,
     "detail": "poses[1].turntable_deg: got 500 deg; allowed: -360 to 360 deg",
     "errors": [{"field": "poses[1].turntable_deg",
                 "message": "got 500 deg; allowed: -360 to 360 deg"}]}

``type`` is a stable URN per kind of error (:data:`PROBLEM_TYPES`; ``about:blank`` for an HTTP
status with no kind of its own, its ``title`` then the status' reason phrase), ``title`` the
kind's short name, ``status`` the HTTP status, ``detail`` a sentence saying what went wrong in
this request. Invalid input (422) adds ``errors``, one ``{field, message}`` per field, the field
named as a path (``camera.fx_px``, ``poses[3].turntable_deg``; ``body`` for the body as a
whole); a device fault (503) adds ``fault``, the driver's error class (``DeviceTimeoutError``),
and for a device read back off its target ``device``, ``target`` and ``read_back``.
A server error (500) says only that it happened: its traceback goes to the service's log. A
file or database error that says the disk is full, wherever it comes from, is the 507 problem
naming the request whose data could not be written.

:func:`install` registers the handlers on an app and declares the schemas in its OpenAPI
document (:func:`document`): every operation's error responses, a ``default`` one for the
statuses any route may answer (404 and 405 of the router, 413, 500).
"""

from __future__ import annotations

import http
import logging
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Literal

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field
from pydantic.json_schema import models_json_schema
from sqlalchemy.exc import SQLAlchemyError
from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from drivers.errors import DeviceError
from service.api.security_headers import security_headers
from service.errors import ServiceError
from service.store.disk_space import disk_full_detail, is_disk_full
from sim_core.errors import InvalidInputError
from sim_core.json_safe import json_safe

PROBLEM_JSON = "application/problem+json"
TYPE_PREFIX = "urn:toftwin:problem:"
#: the problem type of an HTTP status that has no kind of its own (RFC 9457 section 4.2.1)
ABOUT_BLANK = "about:blank"
_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ProblemType:
    """A kind of error: its URN's last part, HTTP status, title and when it is answered."""

    name: str
    status: int
    title: str
    when: str

    @property
    def uri(self) -> str:
        return TYPE_PREFIX + self.name


#: every kind of error the service answers, by ``name`` (``type`` is ``TYPE_PREFIX + name``)
PROBLEM_TYPES: dict[str, ProblemType] = {t.name: t for t in (
    ProblemType("invalid-input", 422, "Invalid input",
                "a body, parameter or value of the wrong form or outside its allowed range; "
                "`errors` names each field; nothing was changed"),
    ProblemType("unauthorized", 401, "Unauthorized",
                "a call that moves hardware or changes data came without the bearer token, "
                "or with a wrong one"),
    ProblemType("not-found", 404, "Not found",
                "no such campaign, frame, pose, calibration job or file; or no such route"),
    ProblemType("method-not-allowed", 405, "Method not allowed",
                "the route exists but not with this method (`Allow` lists those it takes)"),
    ProblemType("conflict", 409, "Conflict",
                "a campaign or calibration job holds the rig, or the resource is in a state "
                "that does not allow the call"),
    ProblemType("gone", 410, "Gone",
                "the resource is known but its files are gone from the data directory"),
    ProblemType("damaged-file", 410, "Damaged file",
                "the resource is known but a file of it cannot be read (truncated or corrupt): "
                "`detail` names the frame and the file inside the data directory"),
    ProblemType("content-too-large", 413, "Content too large",
                "the request body is larger than `TOFTWIN_MAX_BODY_BYTES`"),
    ProblemType("device-fault", 503, "Device fault",
                "a device did not do what it was asked or reported a fault: `detail` is the "
                "driver's message, `fault` its error class"),
    ProblemType("unavailable", 503, "Service unavailable",
                "a device or the executor is not available, or too many event streams are "
                "open"),
    ProblemType("insufficient-storage", 507, "Insufficient storage",
                "too little free space on the data directory's disk"),
    ProblemType("internal-error", 500, "Internal server error",
                "an unexpected error (a bug); the service's log has its traceback"),
)}
_BY_STATUS = {401: "unauthorized", 404: "not-found", 405: "method-not-allowed",
              413: "content-too-large"}


# -- the schemas -------------------------------------------------------------------------------
class FieldError(BaseModel):
    """What is wrong with one field of the request."""

    field: str = Field(description="The field as a path into the request: `camera.fx_px`, "
                       "`poses[3].turntable_deg`, a query or path parameter's name; `body` "
                       "for the body as a whole.", examples=["poses[1].turntable_deg"])
    message: str = Field(description="What is wrong, with the allowed range and unit.",
                         examples=["got 500 deg; allowed: -360 to 360 deg"])


class _ProblemFields(BaseModel):
    model_config = ConfigDict(extra="allow")  # RFC 9457 allows extension members

    type: Literal[tuple([t.uri for t in PROBLEM_TYPES.values()] + [ABOUT_BLANK])] = Field(  # type: ignore[valid-type]
        description="The kind of error, stable for clients to branch on (docs/service.md lists "
        "them); `about:blank` for an HTTP status with no kind of its own.")
    title: str = Field(description="The kind's short name (the same for every error of it).")
    status: int = Field(ge=400, le=599, description="The HTTP status code.")
    detail: str = Field(description="What went wrong in this request, for people.")


class Problem(_ProblemFields):
    """An error (RFC 9457 problem details, `application/problem+json`)."""

    fault: str | None = Field(None, description="Device faults (503): the driver's error class, "
                              "e.g. `DeviceTimeoutError`.")
    device: str | None = Field(None, description="Device faults (503) of a device read back off "
                               "its target: the device, e.g. `solar simulator lamp`.")
    target: str | None = Field(None, description="With `device`: the state asked for, e.g. "
                               "`1 sun`.")
    read_back: str | None = Field(None, description="With `device`: the state read back, e.g. "
                                  "`0.000 sun`.")


class ValidationProblem(_ProblemFields):
    """Invalid input (422): the problem with one `{field, message}` per offending field."""

    type: Literal["urn:toftwin:problem:invalid-input"]  # type: ignore[assignment]
    status: Literal[422]  # type: ignore[assignment]
    errors: list[FieldError] = Field(min_length=1)


def problem_response(
    kind: ProblemType | None, status: int, detail: str, *,
    headers: dict[str, str] | None = None, **members: Any,
) -> JSONResponse:
    """The ``application/problem+json`` response of ``kind`` (``None``: ``about:blank``)."""
    body = {"type": kind.uri if kind else ABOUT_BLANK,
            "title": kind.title if kind else _reason(status),
            "status": status, "detail": detail,
            **{k: v for k, v in members.items() if v is not None}}
    # strict JSON: a message may echo the input (a lone surrogate, a non-finite number)
    return JSONResponse(json_safe(body), status_code=status, headers=headers,
                        media_type=PROBLEM_JSON)


def _reason(status: int) -> str:
    try:
        return http.HTTPStatus(status).phrase
    except ValueError:
        return "Error"


# -- the handlers ------------------------------------------------------------------------------
def field_path(loc: Iterable[Any]) -> str:
    """A pydantic error location as a field path: ``("body", "poses", 3, "turntable_deg")``
    -> ``poses[3].turntable_deg``; ``body`` for the body itself.

    >>> field_path(("body", "camera", "fx_px")), field_path(("query", "limit")), field_path([])
    ('camera.fx_px', 'limit', 'body')
    """
    out = ""
    for part in loc:
        if part in ("body", "query", "path", "header") and not out:
            continue
        out += f"[{part}]" if isinstance(part, int) else ("." if out else "") + str(part)
    return out or "body"


def _field_error(error: dict[str, Any]) -> dict[str, str]:
    if error.get("type") == "json_invalid":  # loc: ("body", character offset)
        loc = list(error.get("loc", ()))
        where = f" at character {loc[-1]}" if loc and isinstance(loc[-1], int) else ""
        why = (error.get("ctx") or {}).get("error", "")
        return {"field": "body", "message": f"not valid JSON{where}: {why}".rstrip(": ")}
    message = str(error.get("msg", "")).removeprefix("Value error, ")
    return {"field": field_path(error.get("loc", ())), "message": message}


def invalid_input(errors: list[dict[str, str]]) -> JSONResponse:
    """The 422 problem for ``errors`` (``{field, message}`` each)."""
    detail = "; ".join(f"{e['field']}: {e['message']}" for e in errors)
    return problem_response(PROBLEM_TYPES["invalid-input"], 422, detail, errors=errors)


async def _validation_error(_: Request, exc: RequestValidationError) -> JSONResponse:
    return invalid_input([_field_error(e) for e in exc.errors()] or
                         [{"field": "body", "message": "invalid request"}])


async def _invalid_input(_: Request, exc: InvalidInputError) -> JSONResponse:
    return invalid_input([{"field": exc.field, "message": exc.message}])


async def _device_error(_: Request, exc: DeviceError) -> JSONResponse:
    return problem_response(PROBLEM_TYPES["device-fault"], 503, str(exc),
                            fault=type(exc).__name__, device=exc.device,
                            target=exc.target, read_back=exc.read_back)


async def _service_error(_: Request, exc: ServiceError) -> JSONResponse:
    kind = PROBLEM_TYPES[exc.problem]
    return problem_response(kind, kind.status, exc.detail)


async def _http_error(request: Request, exc: HTTPException) -> JSONResponse:
    status = exc.status_code
    kind = PROBLEM_TYPES.get(_BY_STATUS.get(status, ""))
    detail = exc.detail if isinstance(exc.detail, str) else str(exc.detail)
    if detail == _reason(status):  # Starlette's own (router, static files): say it in full
        path, method = request.url.path, request.method
        if status == 404:
            detail = (f"nothing at {path}: the API is under /api/v1 (its documentation at "
                      "/api/v1/docs), the operator page at /")
        elif status == 405:
            allowed = (exc.headers or {}).get("Allow", "")
            detail = f"{path} does not take {method}" + (f"; it takes {allowed}" if allowed
                                                         else "")
        else:
            detail = f"{status} {detail} ({method} {path})"
    return problem_response(kind, status, detail, headers=exc.headers)


async def _storage_error(request: Request, exc: Exception) -> JSONResponse:
    """A file or database error: a 507 if it says the disk is full (a write path that has no
    handling of its own), else the server error it is."""
    if not is_disk_full(exc):
        raise exc
    lab = getattr(request.app.state, "lab", None)
    detail = disk_full_detail(
        f"the data of {request.method} {request.url.path}",
        lab.store.root if lab is not None else ".",
        lab.settings.min_free_bytes if lab is not None else None)
    return problem_response(PROBLEM_TYPES["insufficient-storage"], 507, detail)


async def _server_error(request: Request, exc: Exception) -> JSONResponse:
    # Never the exception's text: it may hold server paths or data. Starlette re-raises the
    # exception after this answer, so that the server logs its traceback. Answered outside the
    # app's middleware: the security headers are added here.
    return problem_response(
        PROBLEM_TYPES["internal-error"], 500,
        f"the service failed on an unexpected error while answering {request.method} "
        f"{request.url.path}; its log has the details. Nothing is known to have changed, "
        "but check before retrying a call that moves hardware.", headers=security_headers())


# -- the body limit ----------------------------------------------------------------------------
class ContentTooLarge(HTTPException):
    """A request body over the limit (raised while the body is read; answered as a 413)."""

    def __init__(self, limit: int) -> None:
        super().__init__(413, f"the request body is larger than {limit} bytes, the most this "
                         "service accepts (TOFTWIN_MAX_BODY_BYTES)")


class BodyLimit:
    """ASGI middleware: a request body over ``limit`` bytes is a 413 problem.

    A declared ``Content-Length`` over the limit is answered before the app runs; a body sent
    without one (chunked) is counted as it is read and stops with :class:`ContentTooLarge`
    when it passes the limit.
    """

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = Headers(scope=scope).get("content-length", "")
        if length.isdigit() and int(length) > self.limit:
            exc = ContentTooLarge(self.limit)
            response = problem_response(PROBLEM_TYPES["content-too-large"], 413, exc.detail,
                                        headers={"Connection": "close"})
            await response(scope, receive, send)
            return
        seen = 0

        async def counted() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    raise ContentTooLarge(self.limit)
            return message

        await self.app(scope, counted, send)


# -- the OpenAPI document ----------------------------------------------------------------------
REF = "#/components/schemas/"
#: what the ``default`` response of every operation covers
DEFAULT_DESCRIPTION = ("Any other error: an unknown path (404) or method (405), a body over "
                       "the limit (413), an unexpected server error (500).")


def problem_content(schema: str = "Problem") -> dict[str, Any]:
    """The ``content`` of an error response in the OpenAPI document."""
    return {PROBLEM_JSON: {"schema": {"$ref": REF + schema}}}


def document(doc: dict[str, Any]) -> dict[str, Any]:
    """Declare the problem schemas in an OpenAPI document (changed in place and returned).

    Every operation's error responses get the problem as their content (422: the validation
    problem, in place of FastAPI's ``HTTPValidationError``), and a ``default`` response.
    """
    for item in doc.get("paths", {}).values():
        for operation in item.values():
            responses = operation.setdefault("responses", {})
            for status, response in responses.items():
                if status == "422":
                    response["description"] = ("Invalid input: `errors` names each field, with "
                                               "the allowed range; nothing was changed.")
                    response["content"] = problem_content("ValidationProblem")
                elif status[0] in "45":
                    response["content"] = problem_content()
            responses["default"] = {"description": DEFAULT_DESCRIPTION,
                                    "content": problem_content()}
    schemas = doc.setdefault("components", {}).setdefault("schemas", {})
    for unused in ("HTTPValidationError", "ValidationError"):
        schemas.pop(unused, None)
    _, defs = models_json_schema([(m, "serialization") for m in (Problem, ValidationProblem)],
                                 ref_template=REF + "{model}")
    schemas.update(defs["$defs"])
    return doc


def install(app: FastAPI, max_body_bytes: int) -> None:
    """Answer every error of ``app`` as a problem; declare them in its OpenAPI document."""
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(InvalidInputError, _invalid_input)
    app.add_exception_handler(DeviceError, _device_error)
    app.add_exception_handler(ServiceError, _service_error)
    app.add_exception_handler(HTTPException, _http_error)
    for storage_error in (OSError, SQLAlchemyError):
        app.add_exception_handler(storage_error, _storage_error)
    app.add_exception_handler(Exception, _server_error)
    app.add_middleware(BodyLimit, limit=max_body_bytes)
    generate = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = document(generate())
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
