"""Creating campaigns and reading their results back (JSON rows, CSV).

A campaign is validated completely before anything is stored: the scene, every pose's angle
against the stage's software limits and its solar level, the repeats, the number of poses and
the samples per pixel. A bad campaign is a 422 naming the field (``poses[3].turntable_deg``)
and leaves nothing behind.
"""

from __future__ import annotations

import csv
import io
import json
import uuid
from typing import TYPE_CHECKING, Any

from service import crud
from service.errors import NotFoundError
from service.poses import check_angle, check_spp
from service.scenes import scene_from_request
from sim_core.errors import InvalidInputError

if TYPE_CHECKING:
    from service.context import ServiceContext
    from service.schemas import CampaignCreate


#: metric columns of the CSV export, from ``ComparisonReport.to_dict()``
CHANNEL_FIELDS = ("mean_measured", "mean_simulated", "var_measured", "var_simulated", "mse",
                  "ssim", "psnr_db", "rel_err_mean", "rel_err_var")


def create_campaign(ctx: ServiceContext, req: CampaignCreate) -> str:
    """Validate and store ``req`` (a ``CampaignCreate``); returns the new campaign's id."""
    settings = ctx.settings
    scene = scene_from_request(settings, req.scene)
    spp = check_spp(req.spp, settings)
    if len(req.poses) > settings.max_poses:
        raise InvalidInputError(
            "poses", f"{len(req.poses)} poses; allowed: 1 to {settings.max_poses} (max_poses)")
    rig = ctx.rig
    for i, pose in enumerate(req.poses):
        if pose.repeats > settings.max_repeats:
            raise InvalidInputError(
                f"poses[{i}].repeats",
                f"got {pose.repeats}; allowed: 1 to {settings.max_repeats} (max_repeats)")
        if rig is not None:
            check_angle(rig, pose.turntable_deg, f"poses[{i}].turntable_deg")
    campaign_id = uuid.uuid4().hex
    with ctx.session() as s:
        crud.create_campaign(
            s, campaign_id=campaign_id, name=req.name, scene_name=scene.name,
            scene_json=scene.to_json(), scene_base_dir=str(scene.base_dir),
            mask=req.mask.model_dump(mode="json"), seed=req.seed, spp=spp,
            poses=[(p.turntable_deg, p.solar_suns, p.repeats) for p in req.poses],
        )
    return campaign_id


def result_rows(ctx: ServiceContext, campaign_id: str) -> list[dict[str, Any]]:
    """One row per pose and repeat, in order."""
    with ctx.session() as s:
        if crud.get_campaign(s, campaign_id) is None:
            raise NotFoundError(f"no campaign {campaign_id}")
        rows = crud.campaign_results(s, campaign_id)
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
