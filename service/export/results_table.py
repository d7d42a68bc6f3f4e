"""A campaign's results as rows (one per pose and repeat) and as CSV."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterable, Iterator
from typing import Any

from sqlalchemy.orm import sessionmaker

from service.store import queries
from service.store.tables import PoseResultRow

#: metric columns of the CSV export, from ``ComparisonReport.to_dict()``
CHANNEL_FIELDS = ("mean_measured", "mean_simulated", "var_measured", "var_simulated", "mse",
                  "ssim", "psnr_db", "rel_err_mean", "rel_err_var")


#: the explained difference's comparisons (campaigns with an object fit) and their columns
EXPLAINED_TWINS = ("nominal", "fitted", "ceiling")
EXPLAINED_FIELDS = ("depth_rmse_m", "grey_psnr_db")

#: the depth difference and pixel shares (``metrics["tof"]``, :class:`sim_core.metrics.ToFFigures`),
#: the first metric columns of the CSV; rows stored before them have empty cells
TOF_FIELDS = ("depth_diff_median_mm", "depth_diff_mad_mm", "depth_diff_p95_abs_mm",
              "depth_diff_n_pixels", "mask_pixels", "flying_share_measured",
              "flying_share_simulated", "invalid_share_measured", "invalid_share_simulated")
#: the explained difference's comparisons whose ToF figures get columns of their own
#: (``fitted_*``, ``ceiling_*``: the noise ceiling); the nominal twin's are the main columns
TOF_TWINS = ("fitted", "ceiling")


def result_rows(
    sessions: sessionmaker, campaign_id: str, limit: int | None = None, offset: int = 0
) -> list[dict[str, Any]]:
    """One row per pose and repeat, in order (``limit`` of them from ``offset``)."""
    with sessions() as s:
        queries.require_campaign(s, campaign_id)
        rows = queries.campaign_results(s, campaign_id, limit, offset)
    return [result_dict(r) for r in rows]


def result_dict(r: PoseResultRow) -> dict[str, Any]:
    """The public form of one result row (metrics without the Table 5 text rows)."""
    metrics = json.loads(r.metrics_json)
    metrics.pop("table", None)
    return {
        "id": r.id, "pose_index": r.pose_index, "repeat": r.repeat,
        "turntable_deg": r.turntable_deg,
        "solar_suns": r.solar_suns, "metrics": metrics,
        "measured_frame_id": r.measured_frame_id,
        "simulated_frame_id": r.simulated_frame_id, "fitted_frame_id": r.fitted_frame_id,
        "created_at": r.created_at,
        "timings_s": json.loads(r.timings_json), "calibration_hash": r.calibration_hash,
    }


def flat_metrics(metrics: dict[str, Any]) -> dict[str, Any]:
    """``depth_diff_median_mm``, ..., ``grey_ssim``, ``depth_mse``, ... from a
    ``ComparisonReport.to_dict()`` (the ToF figures first)."""
    flat: dict[str, Any] = {}
    tof = metrics.get("tof") or {}
    for f in TOF_FIELDS:
        flat[f] = tof.get(f)
    for ch in ("grey", "depth"):
        values = metrics.get(ch) or {}
        for f in CHANNEL_FIELDS:
            flat[f"{ch}_{f}"] = values.get(f)
    flat["grey_chi_square"] = metrics.get("grey_chi_square")
    flat["n_pixels"] = metrics.get("n_pixels")
    flat["error"] = metrics.get("error")
    explained = metrics.get("explained") or {}
    for twin in EXPLAINED_TWINS:
        values = explained.get(twin) or {}
        for f in EXPLAINED_FIELDS:
            flat[f"{twin}_{f}"] = values.get(f)
    for ch in ("depth", "grey"):
        flat[f"explained_{ch}"] = (explained.get("explained") or {}).get(ch)
    for ch in ("depth", "grey"):  # the channel beyond the noise ceiling: by how much and where
        flat[f"unexplained_{ch}"] = next((u.get("text") for u in explained.get("unexplained") or []
                                          if u.get("channel") == ch), None)
    for twin in TOF_TWINS:
        values = (explained.get(twin) or {}).get("tof") or {}
        for f in TOF_FIELDS:
            flat[f"{twin}_{f}"] = values.get(f)
    flat["camera_data"] = metrics.get("camera_data")  # raw, or royale's processed depth
    return flat


def results_csv(rows: Iterable[dict[str, Any]]) -> Iterator[str]:
    """The rows as CSV, metrics flattened to one column each: the header, then a line a row."""
    head = ["pose_index", "repeat", "turntable_deg", "solar_suns", "measured_frame_id",
            "simulated_frame_id", "fitted_frame_id", "created_at", "calibration_hash"]
    metric_cols = list(flat_metrics({}).keys())
    buf = io.StringIO()
    writer = csv.writer(buf)

    def line(values: list[Any]) -> str:
        buf.seek(0)
        buf.truncate()
        writer.writerow(values)
        return buf.getvalue()

    yield line(head + metric_cols)
    for row in rows:
        flat = flat_metrics(row["metrics"])
        yield line(["" if row[h] is None else row[h] for h in head]
                   + ["" if flat[c] is None else flat[c] for c in metric_cols])
