"""The operator page at ``/`` and the HTML fragments it loads (``/ui/...``).

The page (``page.html``, ``static/page.js``) talks to the REST API like any client; the
fragments are rendered with the same template macros as the campaign report (a pose's image
panels with colour bars, its Table 5 rows, the object fit's verdicts and the difference the object
twin explains, the active calibration), so that each is made in one place. Everything here is
read-only and needs no token.
"""

from __future__ import annotations

import json
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse
from fastapi.templating import Jinja2Templates

from calibration.verdicts import Verdicts, count_line
from service.api.deps import (
    CalibrationsDep,
    RunnerDep,
    SessionDep,
    SessionsDep,
    SettingsDep,
    StoreDep,
)
from service.api.routes.calibrations import JobId
from service.api.routes.campaigns import CampaignId
from service.api.routes.poses import PoseId, require_pose
from service.errors import GoneError, NotFoundError
from service.export.panels import pose_panels
from service.export.plots import CAMPAIGN_PLOTS, EXPLAINED_PLOTS
from service.export.report import ceiling_tof, explained_rows, unexplained_summary
from service.export.results_table import result_rows
from service.lab.calibration import active_public, calibration_residuals
from service.lab.calibration_jobs import job_status
from service.lab.campaigns import campaign_status
from service.store import queries
from service.web import environment
from sim_core.frame_io import package_version
from sim_core.metrics import TABLE_HEADER

router = APIRouter(include_in_schema=False)
templates = Jinja2Templates(env=environment())


@router.get("/", response_class=HTMLResponse)
def page(request: Request, settings: SettingsDep) -> HTMLResponse:
    """The operator page."""
    return templates.TemplateResponse(request, "page.html", {
        "simulated": settings.simulated, "version": package_version(),
        # poses and campaigns compare frames of the mounted scene: the only one offered
        "scenes": [settings.scene], "default_scene": settings.scene,
        "max_spp": settings.max_spp, "sim_spp": settings.sim_spp,
        "plots": [p.name for p in CAMPAIGN_PLOTS],
        "explained_plots": [p.name for p in EXPLAINED_PLOTS]})


def panel_links(store, row) -> list[dict[str, Any]]:
    """The pose's six panels as the ``panels`` macro takes them, served by the API
    (``/api/v1/poses/{id}/panels/...``: the grey images stretched to their percentiles, not the
    frames' stored grey.png, on which a dim scene is black)."""
    base = f"/api/v1/poses/{row.id}/panels"
    return [{"name": p.name, "caption": p.caption, "label": p.label,
             "src": f"{base}/{p.name}.png", "bar_src": f"{base}/{p.name}/colour-bar.png",
             "width": p.rgb.shape[1], "height": p.rgb.shape[0]}
            for p in pose_panels(store, row.measured_frame_id, row.simulated_frame_id)]


@router.get("/ui/poses/{pose_id}", response_class=HTMLResponse)
def pose_fragment(request: Request, pose_id: PoseId, session: SessionDep,
                  store: StoreDep) -> HTMLResponse:
    """A pose: its images with colour bars, its depth difference and pixel shares (first), its
    Table 5 rows and (object fit) the difference the object twin explains."""
    row = require_pose(session, pose_id)
    metrics = json.loads(row.metrics_json)
    try:
        panels, gap = panel_links(store, row), None
    except (GoneError, OSError) as exc:
        panels, gap = [], str(exc)
    explained = None
    if metrics.get("explained"):
        explained = explained_rows([{"pose_index": row.pose_index,
                                 "turntable_deg": row.turntable_deg, "metrics": metrics}])[0]
    return templates.TemplateResponse(request, "_pose_fragment.html", {
        "row": row, "panels": panels, "gap": gap, "header": TABLE_HEADER,
        "table": metrics.get("table", []), "error": metrics.get("error"), "explained": explained,
        "tof": metrics.get("tof"), "ceiling_tof": ceiling_tof(metrics)})


@router.get("/ui/campaigns", response_class=HTMLResponse)
def campaigns_fragment(request: Request, session: SessionDep, sessions: SessionsDep,
                       runner: RunnerDep) -> HTMLResponse:
    """The list of campaigns, newest first, with their report, CSV and documents links."""
    rows = [campaign_status(sessions, runner, row.id)
            for row in queries.list_campaigns(session, 50, 0)]
    return templates.TemplateResponse(request, "_campaigns.html", {"campaigns": rows})


@router.get("/ui/campaigns/{campaign_id}/explained", response_class=HTMLResponse)
def explained_fragment(request: Request, campaign_id: CampaignId,
                     sessions: SessionsDep) -> HTMLResponse:
    """A campaign's object fit (empty without): its verdict on each key it estimated, and the
    difference the object twin explains per pose."""
    with sessions() as s:
        report = json.loads(queries.require_campaign(s, campaign_id).object_fit_report_json
                            or "{}")
    first = [r for r in result_rows(sessions, campaign_id) if r["repeat"] == 0]
    rows, medians = explained_rows([r for r in first if r["metrics"].get("explained")])
    return templates.TemplateResponse(request, "_explained_fragment.html", {
        "rows": rows, "medians": medians if rows else None, "summary": unexplained_summary(first),
        "fit_verdicts": report.get("verdicts") or {},
        "dropped_views": report.get("dropped_views") or []})


@router.get("/ui/calibrations/{job_id}/verdicts", response_class=HTMLResponse)
def calibration_verdicts_fragment(request: Request, job_id: JobId, sessions: SessionsDep,
                                  calibrations: CalibrationsDep) -> HTMLResponse:
    """A calibration job's verdicts (empty until it is done): the count line and the table the
    calibration's own report shows."""
    verdicts = job_status(sessions, calibrations, job_id).get("verdicts") or {}
    return templates.TemplateResponse(request, "_calibration_verdicts.html", {
        "verdicts": verdicts,
        "counts": count_line(Verdicts.from_json(verdicts)) if verdicts else None})


@router.get("/ui/calibration", response_class=HTMLResponse)
def calibration_fragment(request: Request, sessions: SessionsDep) -> HTMLResponse:
    """The active calibration: its hash, date, where it came from and its residuals."""
    try:
        active = active_public(sessions)
    except NotFoundError as exc:
        active, message = None, str(exc)
    else:
        message = None
    return templates.TemplateResponse(request, "_calibration.html", {
        "active": active, "message": message,
        "residuals": calibration_residuals(active["provenance"]) if active else []})
