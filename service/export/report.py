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
from sim_core.unexplained import MIN_SHARE

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
            "unexplained": [u.get("text") for u in unexplained_entries(r)],
        })
    medians = {key: {t: _median([row[key][t] for row in rows]) for t in EXPLAINED_TWINS}
               for key in ("depth_rmse_m", "grey_psnr_db")}
    return rows, medians


def unexplained_entries(row: dict[str, Any]) -> list[dict[str, Any]]:
    """A result row's unexplained residual: per channel beyond the noise ceiling, by how much
    and where (:func:`service.lab.comparison.unexplained_residual`); empty when within it."""
    return list((row["metrics"].get("explained") or {}).get("unexplained") or [])


def _shape_phrase(shape: str, where: str, values: list[float], unit: str) -> str:
    if shape == "offset":
        return f"a common offset of {_median(values):+.3g} {unit} over {where} (median)"
    if shape == "object":
        return f"an offset of {_median(values):+.3g} {unit} on {where} (median)"
    return f"excess on {where}"


def unexplained_summary(first: list[dict[str, Any]]) -> str | None:
    """The campaign's line on what its fitted twin leaves unexplained: on how many of the poses
    with an explained difference, per channel on how many, and the shape that holds the
    largest share on most of them (with the median offset over those poses), e.g.
    "unexplained residual on 4 of 5 poses: depth on 4 (a common offset of +3.2 mm over the
    compared objects (median) on 4)". None without an explained difference.
    """
    poses = [r for r in first if (r["metrics"].get("explained") or {}).get("fitted")]
    if not poses:
        return None
    hit = [r for r in poses if unexplained_entries(r)]
    if not hit:
        return f"no unexplained residual: all {len(poses)} poses within the noise ceiling"
    parts = []
    for channel in ("depth", "grey"):
        entries = [u for r in hit for u in unexplained_entries(r) if u.get("channel") == channel]
        if not entries:
            continue
        groups: dict[tuple[str, str], list[float]] = {}
        unit = ""
        spread = 0
        for u in entries:
            where = u.get("where") or {}
            named = [c for c in where.get("components") or [] if c["share"] >= MIN_SHARE]
            unit = where.get("unit", unit)
            if not named:
                spread += 1
                continue
            groups.setdefault((named[0]["shape"], named[0]["where"]), []).append(
                named[0]["mean"])
        text = f"{channel} on {len(entries)}"
        if groups:
            (shape, where), values = max(groups.items(), key=lambda kv: len(kv[1]))
            text += f" ({_shape_phrase(shape, where, values, unit)} on {len(values)})"
        elif spread:
            text += " (spread, no shape)"
        parts.append(text)
    return f"unexplained residual on {len(hit)} of {len(poses)} poses: " + "; ".join(parts)


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
            "dropped_views": report.get("dropped_views") or [],
            "report": json.dumps(report, indent=1)[:20000],
            "plots": [Markup(plot_svg(p, first)) for p in EXPLAINED_PLOTS],
            "rows": rows, "medians": medians, "summary": unexplained_summary(first)}


def ceiling_tof(metrics: dict[str, Any]) -> dict[str, Any] | None:
    """The ToF figures of the measured frame against a second capture of the same state (the
    noise ceiling of a campaign with an object fit), or None."""
    return ((metrics.get("explained") or {}).get("ceiling") or {}).get("tof")


def _pose_context(store: FrameStore, r: dict[str, Any]) -> dict[str, Any]:
    out = {"pose_index": r["pose_index"], "turntable_deg": r["turntable_deg"],
           "solar_suns": r["solar_suns"], "ssim_grey": metric("grey", "ssim")(r),
           "ssim_depth": metric("depth", "ssim")(r), "error": r["metrics"].get("error"),
           "tof": r["metrics"].get("tof"), "ceiling": ceiling_tof(r["metrics"]),
           "gap": None, "panels": [],
           "frames": [(label, r[key]) for label, key in (
               ("measured", "measured_frame_id"), ("simulated", "simulated_frame_id"),
               ("fitted", "fitted_frame_id")) if r.get(key)]}
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
