"""``toftwin bench turning``: a campaign that captures while turning, on the simulated lab.

Opens a service context (database, frame store, simulated rig whose turntable moves at its
speed, executor) in a temporary folder with a reality (by default one whose table rings:
``turntable.settling``), activates a calibration with the same settling (as a measured one
would have it), runs a campaign at ``speed_deg_s`` through ``poses`` angles ``step_deg`` apart
(:mod:`service.lab.turning`) and prints: poses per minute of the sweep against stop and go on
the stage's motion profile (the simulated lab's wall time is its renderer's, not the rig's),
the wall time, and per pose the depth error (measured - twin) at depth edges and away from them
(:mod:`sim_core.edges`), the twin simulating each frame with its sub-frames at their times.
"""

from __future__ import annotations

import json
import secrets
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

#: the reality of the run when none is given: a table that rings a little after every move
DEFAULT_SETTLING = {"amplitude_deg": 0.05, "frequency_hz": 3.0, "damping_ratio": 0.08}


def _median(values: list[float | None]) -> float | None:
    v = [x for x in values if x is not None]
    return float(np.median(v)) if v else None


def _twin_at_rest(lab: Any, rows: list[Any], per_pose: list[dict[str, Any]], calibration: Any,
                  seed: int, spp: int, use_case: Any) -> None:
    """Each pose's measured frame against the twin with its sub-frames (the campaign's) and
    against the same twin rendered at rest at the frame's start angle (same seed), on the same
    pixels: the edge error the sub-frame timing explains."""
    from service.compute.jobs import make_job, run_job
    from service.lab.poses import unit_seed
    from service.lab.scenes import for_use_case
    from sim_core.edges import edge_depth_error, edge_mask
    from sim_core.render_request import request_from_spec

    scene = lab.default_scene
    spec = for_use_case(scene.spec, use_case)
    for row, pose in zip(rows, per_pose, strict=True):
        measured = lab.store.read(row.measured_frame_id).image
        moving = lab.store.read(row.simulated_frame_id).image
        request = request_from_spec(scene.spec.render, spp=spp, threads=None,
                                    seed=unit_seed(seed, row.pose_index, row.repeat))
        rest = run_job(make_job(spec, scene.base_dir, turntable_deg=pose["frame_start_deg"],
                                solar_suns=0.0, request=request,
                                twin=calibration.model_dump(mode="json"))).image
        mask = measured.valid & moving.valid & rest.valid
        edges = edge_mask(moving.range_m, moving.valid)
        pose["edges_same_pixels"] = {
            "with_subframes": edge_depth_error(measured.range_m, moving.range_m, mask,
                                               moving.valid, edges=edges).to_dict(),
            "at_rest": edge_depth_error(measured.range_m, rest.range_m, mask, moving.valid,
                                        edges=edges).to_dict(),
        }


def run_turning_campaign(
    speed_deg_s: float, poses: int, step_deg: float, spp: int, camera_spp: int,
    reality: Path | None, out: Path | None, console: Console,
) -> dict[str, Any]:
    """Run the campaign; print and return its figures (JSON to ``out`` if given)."""
    from service.lab.calibration import activate
    from service.lab.campaigns import create_campaign
    from service.lab.lab import open_lab
    from service.lab.requests import CampaignCreate
    from service.lab.turning import turning_figures
    from service.settings import Settings
    from service.store import queries
    from sim_core.files import atomic_write
    from sim_core.twin_file import dump_yaml, load_reality, parse_calibration, parse_reality

    angles = [float(a) for a in (np.arange(poses) - (poses - 1) / 2.0) * step_deg]
    with tempfile.TemporaryDirectory(prefix="toftwin-turning-") as tmp:
        if reality is None:
            reality = Path(tmp) / "reality.yaml"
            atomic_write(reality, dump_yaml(parse_reality(
                {"turntable": {"zero_offset_deg": 0.0, "settling": DEFAULT_SETTLING}})))
        world = load_reality(reality)
        settings = Settings(token=secrets.token_urlsafe(24), data_dir=tmp, simulated=True,
                            sim_spp=spp, camera_spp=camera_spp, sim_motion="real",
                            reality=reality, executor="thread", workers=1)
        lab = open_lab(settings)
        try:
            settling = world.turntable.settling
            calibration = parse_calibration(
                {} if settling is None else {"turntable": {"settling": settling.model_dump()}})
            activate(lab.sessions, calibration, "bench turning")
            req = CampaignCreate(
                name=f"turning {speed_deg_s:g} deg/s", spp=spp, turning_deg_s=speed_deg_s,
                poses=[{"turntable_deg": a, "solar_suns": 0.0, "repeats": 1} for a in angles])
            cid = create_campaign(req, sessions=lab.sessions, settings=lab.settings,
                                  rig=lab.lease.rig, mounted=lab.default_scene)
            t0 = time.perf_counter()
            lab.runner.start(cid)
            lab.runner.wait()
            wall_s = time.perf_counter() - t0
            with lab.session() as s:
                camp = queries.get_campaign(s, cid)
                state, error = camp.state, camp.error
                rows = queries.campaign_results(s, cid)
                per_pose = []
                for r in rows:
                    metrics = json.loads(r.metrics_json)
                    rig = json.loads(r.rig_json) if getattr(r, "rig_json", None) else {}
                    per_pose.append({"pose_index": r.pose_index,
                                     "turntable_deg": r.turntable_deg,
                                     "frame_start_deg": rig.get("turntable_angle_deg"),
                                     "edges": metrics.get("edges"),
                                     "depth": metrics.get("depth")})
            rig = lab.lease.require()
            figures = turning_figures(angles, speed_deg_s, rig, calibration,
                                      rig.camera.use_case.frame_rate_hz)
            if state == "completed":
                _twin_at_rest(lab, rows, per_pose, calibration, camp.seed, spp,
                              rig.camera.use_case)
        finally:
            lab.close()
    if state != "completed":
        raise RuntimeError(f"turning campaign ended {state}: {error}")
    edges = [p["edges"] or {} for p in per_pose]
    same = [p.get("edges_same_pixels", {}) for p in per_pose]
    for label in ("with_subframes", "at_rest"):
        for key in ("edge_median_abs_mm", "edge_rms_mm", "interior_rms_mm"):
            figures[f"{label}.{key}"] = _median([s.get(label, {}).get(key) for s in same])
    result = {
        **figures, "use_case": "MODE_5_45FPS_500", "wall_s": wall_s,
        "edge_median_abs_mm": _median([e.get("edge_median_abs_mm") for e in edges]),
        "edge_rms_mm": _median([e.get("edge_rms_mm") for e in edges]),
        "interior_median_abs_mm": _median([e.get("interior_median_abs_mm") for e in edges]),
        "interior_rms_mm": _median([e.get("interior_rms_mm") for e in edges]),
        "poses_detail": per_pose,
    }
    console.print(
        f"capture while turning at {speed_deg_s:g} deg/s, {len(angles)} poses "
        f"{step_deg:g} deg apart ({angles[0]:g} to {angles[-1]:g} deg), {camera_spp} spp "
        f"camera, {spp} spp twin", highlight=False, soft_wrap=True)
    console.print(
        f"poses per minute (stage profile, settle wait {figures['settle_wait_s']:.2f} s): "
        f"turning {figures['turning_poses_per_min']:.1f}, stop and go "
        f"{figures['stop_and_go_poses_per_min']:.1f}; wall time {wall_s:.1f} s (renderer)",
        highlight=False, soft_wrap=True)
    console.print(
        "depth error measured - twin (median over poses): at edges median |d| "
        f"{result['edge_median_abs_mm']} mm, RMS {result['edge_rms_mm']} mm; away from edges "
        f"median |d| {result['interior_median_abs_mm']} mm, RMS {result['interior_rms_mm']} mm",
        highlight=False, soft_wrap=True)
    console.print(
        "the same frames against the twin rendered at rest (same pixels, same seed): at edges "
        f"median |d| {figures['at_rest.edge_median_abs_mm']} mm, RMS "
        f"{figures['at_rest.edge_rms_mm']} mm; with sub-frames "
        f"{figures['with_subframes.edge_median_abs_mm']} mm, RMS "
        f"{figures['with_subframes.edge_rms_mm']} mm", highlight=False, soft_wrap=True)
    if out is not None:
        out.write_text(json.dumps(result, indent=2))
        console.print(f"wrote {out}")
    return result
