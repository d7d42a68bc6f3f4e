"""The HTML report of a campaign: metrics over the poses, and image panels per pose.

Rendered with the operator page's templates (:mod:`service.web`: ``report.html`` and the macros
of ``_pose.html``). Self-contained: plots are inline SVG (matplotlib, :mod:`service.export.plots`),
images and their colour bars inline PNG data URIs, so the page can be saved and mailed. Per pose
(its first repeat) first the depth difference and the flying and invalid pixels
(:class:`sim_core.metrics.ToFFigures`, and the noise ceiling's where a second capture exists),
then the six panels of :mod:`service.export.panels`, each with its colour bar.
"""

from __future__ import annotations

import base64
import json
from typing import Any

import numpy as np
from markupsafe import Markup
from sqlalchemy.orm import sessionmaker

from service.errors import GoneError
from service.export.panels import Panel, png_bytes, pose_panels
from service.export.plots import CAMPAIGN_PLOTS, EXPLAINED_PLOTS, explained, metric, plot_svg
from service.export.results_table import EXPLAINED_TWINS, result_rows
from service.store import queries
from service.store.frame_files import FrameStore
from service.web import environment
from sim_core.preview import colour_bar_png

#: poses with image panels (the plots show every pose)
MAX_PANEL_POSES = 60


def _data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode()


def inline_panels(panels: tuple[Panel, ...]) -> list[dict[str, Any]]:
    """The panels as the ``panels`` macro takes them, images and colour bars inline."""
    return [{"name": p.name, "caption": p.caption, "label": p.label,
             "src": _data_uri(png_bytes(p.rgb)), "bar_src": _data_uri(colour_bar_png(
                 p.scale, p.label)), "width": p.rgb.shape[1], "height": p.rgb.shape[0]}
            for p in panels]


def _median(values: list[float | None]) -> float | None:
    vals = [v for v in values if v is not None]
    return float(np.median(vals)) if vals else None


def explained_rows(first: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Per pose the difference the object twin explains (the ``explained`` macro's rows) and the
    medians: depth RMSE [m] and grey PSNR [dB] against the nominal twin, the fitted twin and the
    noise ceiling, and the share of the nominal twin's excess explained."""
    rows = []
    for r in first:
        ex = (r["metrics"].get("explained") or {}).get("explained") or {}
        rows.append({
            "pose_index": r["pose_index"], "turntable_deg": r["turntable_deg"],
            "depth_rmse_m": {t: explained(t, "depth_rmse_m")(r) for t in EXPLAINED_TWINS},
            "grey_psnr_db": {t: explained(t, "grey_psnr_db")(r) for t in EXPLAINED_TWINS},
            "explained": {ch: ex.get(ch) for ch in ("depth", "grey")},
        })
    medians = {key: {t: _median([row[key][t] for row in rows]) for t in EXPLAINED_TWINS}
               for key in ("depth_rmse_m", "grey_psnr_db")}
    return rows, medians


def explained_context(camp: Any, first: list[dict[str, Any]]) -> dict[str, Any]:
    """The explained difference of a campaign with an object fit (issue 14, section 4): the
    fitted object twin, its plots, and the difference it explains per pose with the medians."""
    if camp.object_twin_json is None:
        return {"fitted": False}
    twin = json.loads(camp.object_twin_json)
    report = json.loads(camp.object_fit_report_json or "{}")
    off = (twin.get("mount") or {}).get("pose_offset") or {}
    scales = {k: v.get("reflectance_scale") for k, v in (twin.get("objects") or {}).items()}
    rows, medians = explained_rows(first)
    return {"fitted": True, "position_m": off.get("position_m"),
            "rotation_deg": off.get("rotation_deg"), "scales": scales,
            "verdicts": report.get("verdicts") or {},
            "report": json.dumps(report, indent=1)[:20000],
            "plots": [Markup(plot_svg(p, first)) for p in EXPLAINED_PLOTS],
            "rows": rows, "medians": medians}


def ceiling_tof(metrics: dict[str, Any]) -> dict[str, Any] | None:
    """The ToF figures of the measured frame against a second capture of the same state (the
    noise ceiling of a campaign with an object fit), or None."""
    return ((metrics.get("explained") or {}).get("ceiling") or {}).get("tof")


def _pose_context(store: FrameStore, r: dict[str, Any]) -> dict[str, Any]:
    out = {"pose_index": r["pose_index"], "turntable_deg": r["turntable_deg"],
           "solar_suns": r["solar_suns"], "ssim_grey": metric("grey", "ssim")(r),
           "ssim_depth": metric("depth", "ssim")(r), "error": r["metrics"].get("error"),
           "tof": r["metrics"].get("tof"), "ceiling": ceiling_tof(r["metrics"]),
           "gap": None, "panels": []}
    try:
        out["panels"] = inline_panels(
            pose_panels(store, r["measured_frame_id"], r["simulated_frame_id"]))
    except (GoneError, OSError) as exc:  # one lost frame folder leaves a gap, not a 500
        out["gap"] = str(exc)
    return out


def campaign_report(sessions: sessionmaker, store: FrameStore, campaign_id: str) -> str:
    """The whole HTML page."""
    with sessions() as s:
        camp = queries.require_campaign(s, campaign_id)
    rows = result_rows(sessions, campaign_id)
    first = [r for r in rows if r["repeat"] == 0]
    context = {
        "camp": camp, "n_rows": len(rows), "base": f"/api/v1/campaigns/{campaign_id}",
        "plots": [Markup(plot_svg(p, first)) for p in CAMPAIGN_PLOTS],
        "explained": (explained_context(camp, first) if camp.object_fit_json is not None
                      else None),
        "truncated": len(first) > MAX_PANEL_POSES, "max_panel_poses": MAX_PANEL_POSES,
        "poses": [_pose_context(store, r) for r in first[:MAX_PANEL_POSES]],
    }
    return environment().get_template("report.html").render(context)
