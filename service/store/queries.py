"""Queries and writes, kept out of the routes. Every function takes a ``Session``.

Writes that must be atomic commit themselves: :func:`add_result` writes a result and the two
frame rows it names in one transaction; :func:`transition` changes a campaign's state only from
the states it names (a compare-and-set), so two requests cannot both start a campaign.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator
from typing import Any

from sqlalchemy import delete, func, select, update
from sqlalchemy.orm import Session, sessionmaker

from service.errors import NotFoundError
from service.store.tables import (
    CalibrationActivationRow,
    CalibrationJobRow,
    CampaignRow,
    FrameRow,
    PlannedPoseRow,
    PoseResultRow,
)
from sim_core.json_safe import dumps_strict

#: states from which a campaign can be (re)started by its runner
RESUMABLE = ("paused", "interrupted", "failed")
TERMINAL = ("completed", "cancelled", "failed")
#: final states of a calibration job
CALIBRATION_TERMINAL = ("done", "failed", "cancelled")


def now() -> float:
    """Seconds since the epoch."""
    return time.time()


def dumps(obj: Any) -> str:
    """Strict JSON for a text column."""
    return dumps_strict(obj, sort_keys=True)


# -- frames ----------------------------------------------------------------------------------
def frame_row(
    frame_id: str,
    kind: str,
    *,
    campaign_id: str | None = None,
    scene_name: str = "",
    scene_hash: str = "",
    rig: dict | None = None,
    summary: dict | None = None,
    calibration_hash: str | None = None,
) -> FrameRow:
    """A new (not yet added) frame row."""
    return FrameRow(
        id=frame_id, kind=kind, campaign_id=campaign_id, scene_name=scene_name,
        scene_hash=scene_hash, rig_json=dumps(rig), summary_json=dumps(summary or {}),
        created_at=now(), calibration_hash=calibration_hash,
    )


def add_frame(session: Session, row: FrameRow) -> FrameRow:
    """Commit a frame row (a frame stored on its own: a capture, a simulation)."""
    session.add(row)
    session.commit()
    return row


def get_frame(session: Session, frame_id: str) -> FrameRow | None:
    return session.get(FrameRow, frame_id)


def list_frames(session: Session, limit: int, offset: int) -> list[FrameRow]:
    q = select(FrameRow).order_by(FrameRow.created_at.desc()).limit(limit).offset(offset)
    return list(session.scalars(q))


def all_frame_ids(session: Session) -> set[str]:
    return set(session.scalars(select(FrameRow.id)))


# -- campaigns -------------------------------------------------------------------------------
def create_campaign(
    session: Session,
    *,
    campaign_id: str,
    name: str,
    scene_name: str,
    scene_json: str,
    scene_base_dir: str,
    mask: dict,
    seed: int,
    spp: int,
    poses: Iterable[tuple[float, float, int]],
    calibration_json: str | None = None,
    calibration_hash: str | None = None,
    object_fit: dict | None = None,
    turning_deg_s: float | None = None,
    record_path: str | None = None,
    replay_path: str | None = None,
    object_twin: tuple[dict, str, dict | None] | None = None,
) -> CampaignRow:
    """Store a new campaign (state ``created``) with its poses; one transaction.

    ``object_fit``: the object fit's settings (None: the campaign fits no object twin);
    ``object_twin``: its result, hash and report, already fitted (a replay of a campaign that
    fitted one). ``record_path``: the recording it writes; ``replay_path``: the one it replays.
    """
    poses = list(poses)
    t = now()
    row = CampaignRow(
        id=campaign_id, name=name, scene_name=scene_name, scene_json=scene_json,
        scene_base_dir=scene_base_dir, mask_json=dumps(mask), seed=seed, spp=spp,
        state="created", error=None, poses_total=sum(p[2] for p in poses), runs=0,
        created_at=t, started_at=None, updated_at=t, finished_at=None,
        calibration_json=calibration_json, calibration_hash=calibration_hash,
        object_fit_json=None if object_fit is None else dumps(object_fit),
        turning_deg_s=turning_deg_s, record_path=record_path, replay_path=replay_path,
        object_twin_json=None if object_twin is None else dumps(object_twin[0]),
        object_twin_hash=None if object_twin is None else object_twin[1],
        object_fit_report_json=(None if object_twin is None or object_twin[2] is None
                                else dumps(object_twin[2])),
    )
    session.add(row)
    session.flush()
    for i, (angle, suns, repeats) in enumerate(poses):
        session.add(PlannedPoseRow(
            campaign_id=campaign_id, pose_index=i, turntable_deg=angle, solar_suns=suns,
            repeats=repeats,
        ))
    session.commit()
    return row


def get_campaign(session: Session, campaign_id: str) -> CampaignRow | None:
    return session.get(CampaignRow, campaign_id)


def _require(session: Session, table, key: str, what: str):
    """The row of ``table`` with primary key ``key``, or :class:`NotFoundError` (404) naming
    ``what`` and the key."""
    row = session.get(table, key)
    if row is None:
        raise NotFoundError(f"no {what} {key}")
    return row


def require_campaign(session: Session, campaign_id: str) -> CampaignRow:
    """The campaign's row, or :class:`NotFoundError` (404) naming it."""
    return _require(session, CampaignRow, campaign_id, "campaign")


def list_campaigns(session: Session, limit: int, offset: int) -> list[CampaignRow]:
    q = select(CampaignRow).order_by(CampaignRow.created_at.desc()).limit(limit).offset(offset)
    return list(session.scalars(q))


def set_object_twin(session: Session, campaign_id: str, object_twin: dict, twin_hash: str,
                    report: dict) -> None:
    """Store a campaign's fitted object twin, its hash and the fit's report; commit."""
    session.execute(update(CampaignRow).where(CampaignRow.id == campaign_id).values(
        object_twin_json=dumps(object_twin), object_twin_hash=twin_hash,
        object_fit_report_json=dumps(report), updated_at=now()))
    session.commit()


def planned_poses(session: Session, campaign_id: str) -> list[PlannedPoseRow]:
    q = (select(PlannedPoseRow).where(PlannedPoseRow.campaign_id == campaign_id)
         .order_by(PlannedPoseRow.pose_index))
    return list(session.scalars(q))


def transition(
    session: Session,
    campaign_id: str,
    allowed_from: Iterable[str],
    to: str,
    *,
    error: str | None = None,
    started: bool = False,
    finished: bool = False,
    count_run: bool = False,
) -> bool:
    """Set the state to ``to`` if it is one of ``allowed_from``; True if it changed."""
    t = now()
    values: dict[str, Any] = {"state": to, "updated_at": t, "error": error}
    if started:
        values["started_at"] = func.coalesce(CampaignRow.started_at, t)
        values["finished_at"] = None
    if finished:
        values["finished_at"] = t
    if count_run:
        values["runs"] = CampaignRow.runs + 1
    stmt = (update(CampaignRow)
            .where(CampaignRow.id == campaign_id, CampaignRow.state.in_(list(allowed_from)))
            .values(**values))
    changed = session.execute(stmt).rowcount == 1
    session.commit()
    return changed


def mark_interrupted(session: Session) -> list[str]:
    """At startup: every campaign left ``running`` by a crash becomes ``interrupted``."""
    ids = list(session.scalars(select(CampaignRow.id).where(CampaignRow.state == "running")))
    for cid in ids:
        transition(session, cid, ("running",), "interrupted",
                   error="the service stopped while the campaign was running")
    return ids


# -- results ---------------------------------------------------------------------------------
def campaign_version(session: Session, campaign_id: str) -> tuple[str, float] | None:
    """(state, updated_at) of a campaign: one indexed row; changes with every result and state."""
    row = session.execute(select(CampaignRow.state, CampaignRow.updated_at)
                          .where(CampaignRow.id == campaign_id)).first()
    return None if row is None else (row[0], float(row[1]))


def results_per_pose(session: Session, campaign_id: str) -> dict[int, int]:
    """How many results each pose index of a campaign has (poses without any are absent)."""
    q = (select(PoseResultRow.pose_index, func.count()).where(
        PoseResultRow.campaign_id == campaign_id).group_by(PoseResultRow.pose_index))
    return {int(p): int(n) for p, n in session.execute(q)}


def done_repeats(session: Session, campaign_id: str, pose_index: int) -> set[int]:
    """The repeats of one pose that have a result."""
    q = select(PoseResultRow.repeat).where(PoseResultRow.campaign_id == campaign_id,
                                           PoseResultRow.pose_index == pose_index)
    return {int(r) for r in session.scalars(q)}


def done_units(session: Session, campaign_id: str) -> set[tuple[int, int]]:
    q = select(PoseResultRow.pose_index, PoseResultRow.repeat).where(
        PoseResultRow.campaign_id == campaign_id)
    return {(int(p), int(r)) for p, r in session.execute(q)}


def count_results(session: Session, campaign_id: str) -> int:
    """How many results a campaign has."""
    q = select(func.count()).select_from(PoseResultRow).where(
        PoseResultRow.campaign_id == campaign_id)
    return int(session.scalar(q) or 0)


def campaign_results(
    session: Session, campaign_id: str, limit: int | None = None, offset: int = 0
) -> list[PoseResultRow]:
    """A campaign's results in pose and repeat order (``limit`` of them from ``offset``)."""
    q = (select(PoseResultRow).where(PoseResultRow.campaign_id == campaign_id)
         .order_by(PoseResultRow.pose_index, PoseResultRow.repeat).offset(offset).limit(limit))
    return list(session.scalars(q))


def iter_campaign_results(
    sessions: sessionmaker, campaign_id: str, batch: int = 1000
) -> Iterator[PoseResultRow]:
    """Every result of a campaign in order, read ``batch`` rows at a time (bounded memory)."""
    offset = 0
    while True:
        with sessions() as s:
            rows = campaign_results(s, campaign_id, batch, offset)
        yield from rows
        if len(rows) < batch:
            return
        offset += batch


def get_result(session: Session, result_id: int) -> PoseResultRow | None:
    return session.get(PoseResultRow, result_id)


def add_result(
    session: Session,
    *,
    campaign_id: str | None,
    pose_index: int,
    repeat: int,
    turntable_deg: float,
    solar_suns: float,
    measured: FrameRow,
    simulated: FrameRow,
    metrics: dict,
    rig: dict,
    timings_s: dict,
    calibration_hash: str | None = None,
    fitted: FrameRow | None = None,
) -> PoseResultRow:
    """Commit a result and its frame rows (two, or three with ``fitted``, the simulation with
    the fitted object twin) in one transaction."""
    row = PoseResultRow(
        campaign_id=campaign_id, pose_index=pose_index, repeat=repeat,
        turntable_deg=turntable_deg, solar_suns=solar_suns,
        measured_frame_id=measured.id, simulated_frame_id=simulated.id,
        metrics_json=dumps(metrics), rig_json=dumps(rig), timings_json=dumps(timings_s),
        created_at=now(), calibration_hash=calibration_hash,
        fitted_frame_id=None if fitted is None else fitted.id,
    )
    session.add_all([measured, simulated] + ([] if fitted is None else [fitted]))
    session.flush()
    session.add(row)
    if campaign_id is not None:
        session.execute(update(CampaignRow).where(CampaignRow.id == campaign_id)
                        .values(updated_at=row.created_at))
    session.commit()
    return row


# -- deleting --------------------------------------------------------------------------------
def campaign_frame_ids(session: Session, campaign_id: str) -> list[str]:
    """Ids of the frames of a campaign."""
    return list(session.scalars(select(FrameRow.id).where(FrameRow.campaign_id == campaign_id)))


def delete_campaign(session: Session, campaign_id: str) -> list[str]:
    """Delete a campaign with its planned poses, results and frame rows in one transaction;
    returns the ids of the frames whose folders the caller removes next."""
    frame_ids = campaign_frame_ids(session, campaign_id)
    session.execute(delete(PoseResultRow).where(PoseResultRow.campaign_id == campaign_id))
    session.execute(delete(FrameRow).where(FrameRow.campaign_id == campaign_id))
    session.execute(delete(PlannedPoseRow).where(PlannedPoseRow.campaign_id == campaign_id))
    session.execute(delete(CampaignRow).where(CampaignRow.id == campaign_id))
    session.commit()
    return frame_ids


def results_naming_frame(session: Session, frame_id: str) -> list[int]:
    """Ids of the results that compare ``frame_id`` (as measured, simulated or fitted frame)."""
    q = select(PoseResultRow.id).where((PoseResultRow.measured_frame_id == frame_id)
                                       | (PoseResultRow.simulated_frame_id == frame_id)
                                       | (PoseResultRow.fitted_frame_id == frame_id))
    return [int(i) for i in session.scalars(q)]


def delete_frame(session: Session, frame_id: str) -> None:
    """Delete a frame row no result names (the caller checks) and commit."""
    session.execute(delete(FrameRow).where(FrameRow.id == frame_id))
    session.commit()


# -- the active calibration ------------------------------------------------------------------
def active_calibration(session: Session) -> CalibrationActivationRow | None:
    """The newest activation (its ``calibration_json`` None: nominal), or None if never set."""
    q = select(CalibrationActivationRow).order_by(CalibrationActivationRow.id.desc()).limit(1)
    return session.scalars(q).first()


def add_activation(
    session: Session, *, calibration_json: str | None, calibration_hash: str | None, source: str
) -> CalibrationActivationRow:
    """Make a calibration (None: nominal) the active one; commits."""
    row = CalibrationActivationRow(calibration_json=calibration_json,
                                   calibration_hash=calibration_hash, source=source,
                                   activated_at=now())
    session.add(row)
    session.commit()
    return row


# -- calibration jobs ------------------------------------------------------------------------
def create_calibration_job(
    session: Session, *, job_id: str, plan: dict, activate: bool, out_dir: str, steps_total: int
) -> CalibrationJobRow:
    """Store a new calibration job (state ``queued``)."""
    t = now()
    row = CalibrationJobRow(
        id=job_id, state="queued", plan_json=dumps(plan), activate=activate, steps_done=0,
        steps_total=steps_total, message="queued", error=None, out_dir=out_dir,
        calibration_hash=None, activated=False, created_at=t, started_at=None, updated_at=t,
        finished_at=None,
    )
    session.add(row)
    session.commit()
    return row


def get_calibration_job(session: Session, job_id: str) -> CalibrationJobRow | None:
    return session.get(CalibrationJobRow, job_id)


def require_calibration_job(session: Session, job_id: str) -> CalibrationJobRow:
    """The job's row, or :class:`NotFoundError` (404) naming it."""
    return _require(session, CalibrationJobRow, job_id, "calibration job")


def list_calibration_jobs(session: Session, limit: int, offset: int) -> list[CalibrationJobRow]:
    q = (select(CalibrationJobRow).order_by(CalibrationJobRow.created_at.desc())
         .limit(limit).offset(offset))
    return list(session.scalars(q))


def update_calibration_job(
    session: Session, job_id: str, *, allowed_from: Iterable[str] | None = None, **values: Any
) -> bool:
    """Set columns of a job (only from the states ``allowed_from``, if given); True if changed."""
    values["updated_at"] = now()
    stmt = update(CalibrationJobRow).where(CalibrationJobRow.id == job_id)
    if allowed_from is not None:
        stmt = stmt.where(CalibrationJobRow.state.in_(list(allowed_from)))
    changed = session.execute(stmt.values(**values)).rowcount == 1
    session.commit()
    return changed


def fail_unfinished_calibration_jobs(session: Session, message: str) -> list[str]:
    """At startup: every job a stopped service left ``queued`` or ``running`` becomes
    ``failed`` with ``message``."""
    ids = list(session.scalars(select(CalibrationJobRow.id).where(
        CalibrationJobRow.state.in_(("queued", "running")))))
    for job_id in ids:
        update_calibration_job(session, job_id, allowed_from=("queued", "running"),
                               state="failed", error=message, finished_at=now())
    return ids
