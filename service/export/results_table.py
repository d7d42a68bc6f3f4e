"""A campaign's results as rows (one per pose and repeat) and as CSV."""

from __future__ import annotations

import csv
import io
import json
from typing import Any

from sqlalchemy.orm import sessionmaker

from service.errors import NotFoundError
from service.store import queries

#: metric columns of the CSV export, from ``ComparisonReport.to_dict()``
CHANNEL_FIELDS = ("mean_measured", "mean_simulated", "var_measured", "var_simulated", "mse",
                  "ssim", "psnr_db", "rel_err_mean", "rel_err_var")


def result_rows(sessions: sessionmaker, campaign_id: str) -> list[dict[str, Any]]:
    """One row per pose and repeat, in order."""
    with sessions() as s:
        if queries.get_campaign(s, campaign_id) is None:
            raise NotFoundError(f"no campaign {campaign_id}")
        rows = queries.campaign_results(s, campaign_id)
    out = []
    for r in rows:
        metrics = json.loads(r.metrics_json)
        metrics.pop("table", None)
        out.append({
            "pose_index": r.pose_index, "repeat": r.repeat, "turntable_deg": r.turntable_deg,
            "solar_suns": r.solar_suns, "metrics": metrics,
            "measured_frame_id": r.measured_frame_id,
            "simulated_frame_id": r.simulated_frame_id, "created_at": r.created_at,
            "timings_s": json.loads(r.timings_json),
        })
    return out


def flat_metrics(metrics: dict[str, Any]) -> dict[str, Any]:
    """``grey_ssim``, ``depth_mse``, ... from a ``ComparisonReport.to_dict()``."""
    flat: dict[str, Any] = {}
    for ch in ("grey", "depth"):
        values = metrics.get(ch) or {}
        for f in CHANNEL_FIELDS:
            flat[f"{ch}_{f}"] = values.get(f)
    flat["grey_chi_square"] = metrics.get("grey_chi_square")
    flat["n_pixels"] = metrics.get("n_pixels")
    flat["error"] = metrics.get("error")
    return flat


def results_csv(rows: list[dict[str, Any]]) -> str:
    """The rows as CSV, metrics flattened to one column each."""
    buf = io.StringIO()
    head = ["pose_index", "repeat", "turntable_deg", "solar_suns", "measured_frame_id",
            "simulated_frame_id", "created_at"]
    metric_cols = list(flat_metrics({}).keys())
    writer = csv.writer(buf)
    writer.writerow(head + metric_cols)
    for row in rows:
        flat = flat_metrics(row["metrics"])
        writer.writerow([row[h] for h in head] + ["" if flat[c] is None else flat[c]
                                                  for c in metric_cols])
    return buf.getvalue()
