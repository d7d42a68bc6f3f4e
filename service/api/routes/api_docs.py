"""The API's documentation: Swagger UI at ``/api/v1/docs``, every file of it from the machine.

Swagger UI's scripts and styles come from the ``swagger-ui-bundle-v2`` package (Swagger UI's
own dist files, Apache-2.0, the version in :data:`SWAGGER_UI_VERSION`), mounted at
:data:`SWAGGER_UI_URL`; the page is our template ``api_docs.html`` and its start-up our
``static/api-docs.js`` (no inline script), which points Swagger UI at the OpenAPI document. So
the docs work on a lab PC without internet. ``/docs`` redirects here.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, RedirectResponse
from fastapi.templating import Jinja2Templates
from swagger_ui_bundle import swagger_ui_path

from service.web import environment
from sim_core.frame_io import package_version

router = APIRouter(include_in_schema=False)
templates = Jinja2Templates(env=environment())
DOCS_URL = "/api/v1/docs"
OPENAPI_URL = "/api/v1/openapi.json"
#: where Swagger UI's files are served (mounted by the app factory)
SWAGGER_UI_URL = "/static/swagger-ui"
#: the Swagger UI the package carries (its folder is ``swagger-ui-<version>``)
SWAGGER_UI_VERSION = Path(str(swagger_ui_path)).name.removeprefix("swagger-ui-")


def swagger_ui_dir() -> Path:
    """The folder of Swagger UI's dist files in the installed package."""
    return Path(str(swagger_ui_path))


@router.get(DOCS_URL, response_class=HTMLResponse)
def api_docs(request: Request) -> HTMLResponse:
    """The interactive API documentation (Swagger UI)."""
    return templates.TemplateResponse(request, "api_docs.html", {
        "assets": SWAGGER_UI_URL, "openapi_url": OPENAPI_URL, "version": package_version(),
        "swagger_ui_version": SWAGGER_UI_VERSION})


@router.get("/docs")
def docs_redirect() -> RedirectResponse:
    """``/docs`` (the address people try first) -> ``/api/v1/docs``."""
    return RedirectResponse(DOCS_URL)
