"""``POST /api/v1/simulate``: one simulated frame of a scene at a rig state, no hardware."""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import sessionmaker

from service.compute.executors import Executor
from service.compute.jobs import make_job
from service.lab.calibration import active_twin, effective_twin
from service.lab.poses import check_spp
from service.lab.requests import SimulationCreate
from service.lab.scenes import scene_from_request
from service.settings import Settings
from service.store import queries
from service.store.disk_space import require_free, writing
from service.store.frame_files import FrameStore, new_frame_id
from sim_core.json_safe import json_safe
from sim_core.render_request import request_from_spec


def simulate_frame(
    req: SimulationCreate, *, sessions: sessionmaker, store: FrameStore, executor: Executor,
    settings: Settings,
) -> dict[str, Any]:
    """Run ``req`` on the executor, store the frame, return its id.

    The simulation applies the active calibration (:mod:`service.lab.calibration`); the frame
    records its hash. Below the free space kept (or when the disk fills up while the frame is
    stored) a 507; nothing is kept then."""
    scene = scene_from_request(settings, req.scene)
    spp = check_spp(req.spp, settings)
    twin = effective_twin(active_twin(sessions), scene)
    frame_id = new_frame_id()
    request = request_from_spec(scene.spec.render, spp=spp, seed=req.seed,
                                threads=settings.threads_per_job, effects=req.effects,
                                ideal=req.ideal)
    job = make_job(
        scene.spec, scene.base_dir, turntable_deg=req.turntable_deg, solar_suns=req.solar_suns,
        request=request, scene_name=scene.name,
        extra={"frame_id": frame_id, "object_names": [o.name for o in scene.spec.objects],
               "turntable_object_ids": scene.turntable_object_ids},
        twin=twin.to_json(),
    )
    require_free(store.root, settings.min_free_bytes)  # 507 before the render
    result = executor.submit(job).result(timeout=settings.job_timeout_s)
    rig = {"turntable_deg": req.turntable_deg, "solar_suns": req.solar_suns}
    with writing("the simulated frame", store.root, settings.min_free_bytes):
        try:
            store.save_files(frame_id, result.files)
            with sessions() as s:
                queries.add_frame(s, queries.frame_row(
                    frame_id, "simulated", scene_name=scene.name, scene_hash=result.scene_hash,
                    rig=rig, summary={"valid_pixels": int(result.image.valid.sum())},
                    calibration_hash=twin.hash,
                ))
        except BaseException:
            store.delete([frame_id])  # no folder without its row
            raise
    return json_safe({
        "frame_id": frame_id, "scene_name": scene.name, "scene_hash": result.scene_hash,
        "calibration_hash": twin.hash,
        "effect_plan": result.effect_plan,
        "timings_s": result.timings_s,
        "links": {"self": f"/api/v1/frames/{frame_id}",
                  "arrays": f"/api/v1/frames/{frame_id}/arrays"},
    })
