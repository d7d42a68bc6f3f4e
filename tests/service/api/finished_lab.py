"""A service with one of everything finished, for the tests that walk every route: a campaign
of one pose (completed), a manual pose, a captured frame and a ``done`` calibration job
(activated).

The campaign, the pose and the frame are made through the API on the simulated rig. The
calibration job's row is stored with the store's own queries and its output folder written
as a done job leaves it (``calibration.yaml`` by :func:`sim_core.twin_file.write_calibration`,
``verdicts.json`` by :func:`calibration.verdicts.write_verdicts`, a ``report.json`` and a
``report.html``): running the real sequence to ``done`` takes about
half a minute (tests/service/api/test_calibration.py runs it, marked slow), and what these
tests look at is how the service serves a done job, not how the job computes.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient

from calibration.camera_forms import OPENCV_FILE, write_camera_form
from calibration.verdicts import VERDICTS_FILE, Verdict, Verdicts, write_verdicts
from service.export.panels import PANEL_NAMES
from service.export.plots import PLOTS
from service.store import queries
from sim_core.twin_file import parse_calibration, write_calibration
from tests.service.api.conftest import AUTH, start_campaign, wait_campaign

JOB_ID = "d" * 32
CALIBRATION = {"camera": {"fx_px": 236.0}, "provenance": {"rig": "test bench"}}
JOB_FILES = ("calibration.yaml", "verdicts.json", "report.json", "report.html",
             "opencv_intrinsics.yml")
#: the done job's verdicts: one determined, one not (its reason text with markup characters, as
#: a reason may hold any text: the page must show it as text)
VERDICTS = Verdicts({
    "camera.fx_px": Verdict("determined", 0.05),
    "turntable.axis_point_m": Verdict("not determined", [0.003, 0.0001, 0.0],
                                      "standard deviation 0.003 m above the limit 0.002 m "
                                      "<b>bold</b>"),
})


@dataclass(frozen=True)
class Finished:
    """The ids of what :func:`finished_lab` made."""

    campaign_id: str
    pose_id: int
    frame_id: str
    job_id: str
    job_dir: Path
    #: the answers of the calls that made them (simulate, capture, pose, activate)
    answers: tuple[Any, ...]


def done_calibration_job(app: Any, job_id: str = JOB_ID) -> Path:
    """A ``done`` calibration job with its four files on ``app`` (started); returns its
    folder."""
    jobs = app.state.lab.calibrations
    out = jobs.out_dir(job_id)
    out.mkdir(parents=True)
    write_calibration(out / "calibration.yaml", parse_calibration(CALIBRATION))
    write_verdicts(out / VERDICTS_FILE, VERDICTS)
    write_camera_form(out / OPENCV_FILE, parse_calibration(CALIBRATION), "opencv")
    (out / "report.json").write_text(json.dumps({"calibration": CALIBRATION}))
    (out / "report.html").write_text("<!doctype html><title>report</title><style>p{}</style>"
                                     "<p>calibration report</p>")
    with app.state.lab.session() as s:
        queries.create_calibration_job(s, job_id=job_id, plan={"fixtures": []}, activate=False,
                                       out_dir=str(out), steps_total=1)
        queries.update_calibration_job(s, job_id, state="done", steps_done=1, message="done",
                                       calibration_hash="0" * 16)
    return out


def finished_lab(client: TestClient) -> Finished:
    """Make one of everything on ``client``'s service (see the module's docstring)."""
    answers = [client.post("/api/v1/simulate", headers=AUTH, json={"solar_suns": 0.0}),
               client.post("/api/v1/devices/camera/capture", headers=AUTH)]
    cid = start_campaign(client, [{"turntable_deg": 10.0}], record=True)  # its recording too
    wait_campaign(client, cid, lambda s: s["state"] == "completed")
    answers.append(client.post("/api/v1/poses", headers=AUTH,
                               json={"turntable_deg": 20.0, "solar_suns": 1.0}))
    job_dir = done_calibration_job(client.app)
    answers.append(client.post(f"/api/v1/calibrations/{JOB_ID}/activate", headers=AUTH))
    for res in answers:
        assert res.status_code in (200, 201), res.text
    pose = answers[2].json()
    return Finished(campaign_id=cid, pose_id=pose["id"], frame_id=pose["measured_frame_id"],
                    job_id=JOB_ID, job_dir=job_dir, answers=tuple(answers))


def api_routes(app: Any) -> list[Any]:
    """Every route of ``app`` with a path and methods: the routes of included routers too
    (FastAPI >= 0.16x keeps them behind an included-router object)."""
    out = []
    for route in app.routes:
        if hasattr(route, "effective_route_contexts"):
            out += list(route.effective_route_contexts())
        else:
            out.append(route)
    return [r for r in out if getattr(r, "path", None) and getattr(r, "methods", None)]


def get_urls(app: Any, lab: Finished) -> dict[str, str]:
    """Every GET route of ``app`` (by its name) as a URL of something that exists in ``lab``:
    its path parameters filled with the ids of what :func:`finished_lab` made."""
    per_route = {"get_pose_panel": {"name": PANEL_NAMES[0]},
                 "get_pose_panel_colour_bar": {"name": PANEL_NAMES[0]},
                 "get_campaign_plot": {"name": next(iter(PLOTS))},
                 "get_calibration_job_file": {"name": "report.html"},
                 "get_frame_preview": {"kind": "grey"}}
    ids = {"campaign_id": lab.campaign_id, "pose_id": lab.pose_id, "frame_id": lab.frame_id,
           "job_id": lab.job_id}
    urls = {}
    for route in api_routes(app):
        if "GET" not in route.methods:
            continue
        name = getattr(route, "name", route.path)
        params = ids | per_route.get(name, {})
        urls[name] = route.path.format(**params)
    return urls
