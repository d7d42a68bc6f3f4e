"""The FastAPI application: ``create_app(settings)``.

The operator page is at ``/`` (:mod:`service.api.routes.page`, its assets under ``/static``).

Routes live under ``/api/v1`` (one router per resource in :mod:`service.api.routes`); the OpenAPI
document is at ``/api/v1/openapi.json`` and the interactive docs at ``/api/v1/docs``.
Errors map to HTTP as: invalid input (:class:`InvalidInputError`, request validation) 422 with
a message naming the field and the allowed range; device faults (:class:`DeviceError`) 503 with
the device's message; :mod:`service.errors` their own codes.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator

from fastapi import APIRouter, FastAPI, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles

from drivers.errors import DeviceError
from service.api.deps import StreamSlots
from service.api.routes import (
    calibration,
    calibrations,
    campaigns,
    devices,
    frames,
    page,
    poses,
    simulate,
)
from service.api.schemas import Health
from service.errors import ServiceError
from service.lab.lab import open_lab
from service.lab.scenes import bundled_scenes
from service.settings import Settings
from service.web import STATIC_DIR
from sim_core.errors import InvalidInputError
from sim_core.frame_io import package_version
from sim_core.json_safe import json_safe

API_PREFIX = "/api/v1"
_log = logging.getLogger(__name__)


def _field(loc: tuple | list) -> str:
    out = ""
    for part in loc:
        if part in ("body", "query", "path") and not out:
            continue
        out += f"[{part}]" if isinstance(part, int) else ("." if out else "") + str(part)
    return out or "body"


async def _validation_error(_: Request, exc: RequestValidationError) -> JSONResponse:
    # The errors echo the raw input (NaN, 1e309 read as inf, a lone surrogate): made strict JSON
    # first, so that a bad request is always a 422 and never a failure to encode one.
    errors = jsonable_encoder(json_safe(list(exc.errors())), custom_encoder={Exception: str})
    errors = json_safe(errors)
    messages = []
    for e in errors:
        msg = str(e.get("msg", "")).removeprefix("Value error, ")
        e["msg"] = msg
        e.pop("url", None)
        e["field"] = _field(e.get("loc", ()))
        messages.append(f"{e['field']}: {msg}")
    return JSONResponse(status_code=422, content={"detail": errors, "message": "; ".join(messages)})


async def _invalid_input(_: Request, exc: InvalidInputError) -> JSONResponse:
    detail = [{"loc": ["body", *exc.field.replace("[", ".").replace("]", "").split(".")],
               "msg": str(exc), "type": "invalid_input", "field": exc.field}]
    return JSONResponse(status_code=422, content={"detail": detail, "message": str(exc)})


async def _device_error(_: Request, exc: DeviceError) -> JSONResponse:
    return JSONResponse(status_code=503, content={"detail": f"{type(exc).__name__}: {exc}"})


async def _service_error(_: Request, exc: ServiceError) -> JSONResponse:
    return JSONResponse(status_code=exc.status_code, content={"detail": exc.detail})


def create_app(settings: Settings) -> FastAPI:
    """The application for ``settings``; devices, database and executor open at startup."""

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        app.state.lab = await run_in_threadpool(open_lab, settings)
        try:
            yield
        finally:
            await run_in_threadpool(app.state.lab.close)

    app = FastAPI(
        title="toftwin",
        version=package_version(),
        description="Hardware-in-the-loop twin of a PMD CamBoard pico flexx: devices, "
        "simulation, pose comparison and campaigns. Calls that move hardware or change data "
        "need `Authorization: Bearer <TOFTWIN_TOKEN>`.",
        lifespan=lifespan,
        openapi_url=f"{API_PREFIX}/openapi.json",
        docs_url=f"{API_PREFIX}/docs",
        redoc_url=None,
        max_body_size=settings.max_body_bytes,
    )
    app.state.stream_slots = StreamSlots(settings.sse_max_streams)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(InvalidInputError, _invalid_input)
    app.add_exception_handler(DeviceError, _device_error)
    app.add_exception_handler(ServiceError, _service_error)

    api = APIRouter(prefix=API_PREFIX)

    @api.get("/health", response_model=Health, tags=["service"])
    def health(request: Request) -> dict:
        """Liveness and what the service runs on."""
        lab = request.app.state.lab
        return {"status": "ok", "version": package_version(), "simulated": settings.simulated,
                "executor": lab.executor.name, "workers": lab.executor.workers,
                "scenes": bundled_scenes(settings.examples_dir),
                "mounted_scene": lab.default_scene.name,
                "mounted_objects": lab.default_scene.turntable_object_names}

    for module in (devices, simulate, poses, frames, campaigns, calibration, calibrations):
        api.include_router(module.router)
    app.include_router(api)
    # The operator page (``/``, its fragments under ``/ui``) and its assets.
    app.include_router(page.router)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    return app
