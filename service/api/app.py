"""The FastAPI application: ``create_app(settings)``.

The operator page is at ``/`` (:mod:`service.api.routes.page`, its assets under ``/static``).

Routes live under ``/api/v1`` (one router per resource in :mod:`service.api.routes`); the OpenAPI
document is at ``/api/v1/openapi.json`` and the interactive docs (Swagger UI, served from the
installed ``swagger-ui-bundle-v2`` package: no request leaves the machine) at ``/api/v1/docs``
(``/docs`` redirects there). Every operation's id is its function's name in camelCase
(``listCampaigns``, :func:`operation_id`).

Every error is an RFC 9457 problem (:mod:`service.api.problems`): invalid input
(:class:`InvalidInputError`, request validation) 422 with ``errors`` naming each field and the
allowed range; device faults (:class:`DeviceError`) 503 with the device's message;
:mod:`service.errors` their own codes; a request body over ``max_body_bytes`` 413; an unexpected
exception 500 without its text.

Every response carries the security headers of :mod:`service.api.security_headers`
(Content-Security-Policy, ``nosniff``, no framing, no referrer).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator

from fastapi import APIRouter, FastAPI, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.routing import APIRoute
from fastapi.staticfiles import StaticFiles

from service.api import problems
from service.api.deps import StreamSlots
from service.api.routes import (
    api_docs,
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
from service.api.security_headers import SecurityHeaders
from service.lab.lab import open_lab
from service.lab.scenes import bundled_scenes
from service.settings import Settings
from service.web import STATIC_DIR
from sim_core.frame_io import package_version

API_PREFIX = "/api/v1"
_log = logging.getLogger(__name__)


def operation_id(route: APIRoute) -> str:
    """A route's OpenAPI operation id: its name (the function's) in camelCase.

    ``list_campaigns`` -> ``listCampaigns``; the names are unique across the API (a test says
    so), so generated clients get readable method names.
    """
    first, *rest = route.name.split("_")
    return first + "".join(part[:1].upper() + part[1:] for part in rest)


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
        docs_url=None,  # our own page, its assets served from the package (api_docs)
        redoc_url=None,
        generate_unique_id_function=operation_id,
    )
    app.state.stream_slots = StreamSlots(settings.sse_max_streams)
    problems.install(app, settings.max_body_bytes)
    app.add_middleware(SecurityHeaders)  # outermost: every answer, a 413 too

    api = APIRouter(prefix=API_PREFIX)

    @api.get("/health", response_model=Health, tags=["service"])
    def get_health(request: Request) -> dict:
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
    # The operator page (``/``, its fragments under ``/ui``), the API's documentation and their
    # assets (Swagger UI's from its package, mounted before ours: the first mount that matches
    # a path serves it).
    app.include_router(page.router)
    app.include_router(api_docs.router)
    app.mount(api_docs.SWAGGER_UI_URL, StaticFiles(directory=api_docs.swagger_ui_dir()),
              name="swagger-ui")
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    return app
