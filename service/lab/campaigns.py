"""Creating campaigns and reading where they stand.

A campaign is validated completely before anything is stored: the scene, every pose's angle
against the stage's software limits and its solar level, the repeats, the number of poses and
the samples per pixel. A bad campaign is a 422 naming the field (``poses[3].turntable_deg``)
and leaves nothing behind.

A campaign pins the calibration active when it is created (its values and hash are stored with
it): every pose it runs, on any start or resume, applies that one, whatever is activated
later, so all its results are comparable. To use another calibration, create a new campaign.
"""

from __future__ import annotations

import json
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sqlalchemy.orm import sessionmaker

from drivers.rig import Rig
from service.errors import ConflictError, InsufficientStorageError, NotFoundError
from service.export.frame_forms import delete_campaign_frames_file
from service.lab.calibration import Twin, active_twin, effective_twin
from service.lab.poses import check_angle, check_spp
from service.lab.requests import CampaignCreate, MaskSpec
from service.lab.runner import CampaignRunner
from service.lab.scenes import (
    SceneSource,
    bundled_scenes,
    check_mask,
    image_shape,
    require_mounted,
    resolve_scene,
    scene_from_request,
)
from service.settings import Settings
from service.store import queries
from service.store.disk_space import free_bytes, is_disk_full, low_space_message
from service.store.frame_files import FrameStore
from service.store.recording import (
    RECORDINGS_DIR,
    RecordedCampaign,
    Recording,
    recorded_poses,
    resolve_stored_path,
    stored_path,
)
from sim_core.errors import InvalidInputError


def create_campaign(
    req: CampaignCreate, *, sessions: sessionmaker, settings: Settings, rig: Rig | None,
    mounted: SceneSource,
) -> str:
    """Validate and store ``req``; returns the new campaign's id.

    Its scene must be the one ``mounted`` on the rig's turntable (409 otherwise:
    :func:`service.lab.scenes.require_mounted`).

    ``rig`` gives the stage's software limits the angles are checked against (None: the rig is
    not available, the angles are checked when the campaign runs).
    """
    if req.source == "recording":
        return _create_replay(req, sessions=sessions, settings=settings)
    scene = scene_from_request(settings, req.scene)
    spp = check_spp(req.spp, settings)
    check_mask(req.mask, scene, image_shape(scene, rig.camera.use_case if rig else None))
    if len(req.poses) > settings.max_poses:
        raise InvalidInputError(
            "poses", f"{len(req.poses)} poses; allowed: 1 to {settings.max_poses} (max_poses)")
    for i, pose in enumerate(req.poses):
        if pose.repeats > settings.max_repeats:
            raise InvalidInputError(
                f"poses[{i}].repeats",
                f"got {pose.repeats}; allowed: 1 to {settings.max_repeats} (max_repeats)")
        if rig is not None:
            check_angle(rig, pose.turntable_deg, f"poses[{i}].turntable_deg")
    fit = req.object_fit_settings()
    if fit is not None and not scene.turntable_object_ids:
        raise InvalidInputError(
            "object_fit", f"scene {scene.name!r} has no object on the turntable to fit")
    require_mounted(scene, mounted, inline=isinstance(req.scene, dict))
    twin = effective_twin(active_twin(sessions), scene)
    pinned = twin.to_json()
    campaign_id = uuid.uuid4().hex
    with sessions() as s:
        queries.create_campaign(
            s, campaign_id=campaign_id, name=req.name, scene_name=scene.name,
            scene_json=scene.to_json(), scene_base_dir=str(scene.base_dir),
            mask=req.mask.model_dump(mode="json"), seed=req.seed, spp=spp,
            poses=[(p.turntable_deg, p.solar_suns, p.repeats) for p in req.poses],
            calibration_json=None if pinned is None else json.dumps(pinned, sort_keys=True),
            calibration_hash=twin.hash,
            object_fit=None if fit is None else fit.model_dump(mode="json"),
            turning_deg_s=req.turning_deg_s,
            record_path=(stored_path(settings.data_dir,
                                     recordings_dir(settings) / f"{campaign_id}.h5")
                         if req.record else None),
        )
    return campaign_id


def recordings_dir(settings: Settings) -> Path:
    """Where the service's recordings are: ``recordings/`` in the data directory."""
    return Path(settings.data_dir) / RECORDINGS_DIR


def _create_replay(req: CampaignCreate, *, sessions: sessionmaker, settings: Settings) -> str:
    """``POST /campaigns`` with ``"source": "recording"``: the recording named in the data
    directory's ``recordings/``, replayed with the active calibration (as every campaign)."""
    assert req.recording is not None  # CampaignCreate checked it
    recording = Recording(recordings_dir(settings) / req.recording)
    recorded = recording.campaign
    # a recording may come from elsewhere: its scene, mask, spp and poses are checked as a
    # request's are (a recorded scene as an inline one: no files of this server's)
    scene = (scene_from_request(settings, req.scene) if req.scene is not None
             else recorded_scene(recorded, settings, trusted=False))
    given = req.model_fields_set
    mask = req.mask if "mask" in given else _recorded_mask(recorded.mask)
    check_mask(mask, scene, image_shape(scene, None))
    spp = check_spp(req.spp if req.spp is not None else recorded.spp, settings)
    poses = recorded_poses(recorded, recording.units())
    if len(poses) > settings.max_poses:
        raise InvalidInputError("recording", f"{len(poses)} poses; allowed: 1 to "
                                f"{settings.max_poses} (max_poses)")
    if any(p[2] > settings.max_repeats for p in poses):
        raise InvalidInputError("recording", f"more than {settings.max_repeats} repeats of a "
                                "pose (max_repeats)")
    return create_replay(
        sessions, recording, settings.data_dir, name=req.name, scene=scene,
        twin=effective_twin(active_twin(sessions), scene), mask=mask.model_dump(mode="json"),
        seed=req.seed if "seed" in given else None, spp=spp)


def _recorded_mask(data: dict[str, Any]) -> MaskSpec:
    try:
        return MaskSpec.model_validate(data)
    except ValueError as exc:
        raise InvalidInputError("recording", f"its mask is not valid: {exc}") from None


def create_replay(
    sessions: sessionmaker, recording: Recording, data_dir: str | Path, *, name: str,
    scene: SceneSource, twin: Twin,
    mask: dict[str, Any] | None = None, seed: int | None = None, spp: int | None = None,
) -> str:
    """Store a campaign that replays ``recording`` (:mod:`service.store.recording`); returns
    its id. Its poses are the recording's (each with the repeats recorded), its mask, seed and
    samples per pixel the recording's unless given, its calibration ``twin``; a recording of a
    campaign with an object fit replays with that fit's result (it is not fitted again). It
    needs neither the rig nor the mounted scene."""
    recorded = recording.campaign
    if not recording.index:
        raise InvalidInputError("recording", f"'{recording.path.name}' holds no frame")
    pinned = twin.to_json()
    campaign_id = uuid.uuid4().hex
    with sessions() as s:
        queries.create_campaign(
            s, campaign_id=campaign_id, name=name, scene_name=scene.name,
            scene_json=scene.to_json(), scene_base_dir=str(scene.base_dir),
            mask=recorded.mask if mask is None else mask,
            seed=recorded.seed if seed is None else seed,
            spp=recorded.spp if spp is None else spp,
            poses=recorded_poses(recorded, recording.units()),
            calibration_json=None if pinned is None else json.dumps(pinned, sort_keys=True),
            calibration_hash=twin.hash, object_fit=recorded.object_fit,
            object_twin=(None if recorded.object_twin is None else
                         (recorded.object_twin, recorded.object_twin_hash,
                          recorded.object_fit_report)),
            turning_deg_s=recorded.turning_deg_s,
            replay_path=stored_path(data_dir, recording.path))
    return campaign_id


def recorded_scene(recorded: RecordedCampaign, settings: Settings,
                   trusted: bool = True) -> SceneSource:
    """The scene a recording was captured with.

    A bundled scene (no folder recorded) that this service bundles unchanged is that one.
    Otherwise a ``trusted`` caller (``toftwin replay``, the user's own files) looks for its
    files where they were, else among the bundled scenes (a recording made on another PC); the
    service (not trusted) takes it as an inline scene: checked and bounded as a request's, no
    files of the server's named.
    """
    if recorded.scene_base_dir is None and recorded.scene_name in bundled_scenes(
            Path(settings.examples_dir)):
        bundled = resolve_scene(recorded.scene_name, settings.examples_dir,
                                settings.max_scene_objects)
        if json.loads(bundled.to_json()) == recorded.scene:
            return bundled
    if not trusted:
        return resolve_scene(recorded.scene, settings.examples_dir, settings.max_scene_objects,
                             field="recording", max_pixels=settings.max_scene_pixels,
                             max_triangles=settings.max_scene_triangles)
    base_dir = Path(recorded.scene_base_dir or settings.examples_dir)
    if not base_dir.is_dir():
        base_dir = Path(settings.examples_dir)
    return SceneSource.from_json(json.dumps(recorded.scene), str(base_dir),
                                 recorded.scene_name)


def status_key(sessions: sessionmaker, runner: CampaignRunner, campaign_id: str) -> tuple:
    """What changes whenever :func:`campaign_status` would: one small query and the runner's
    current pose. A follower (the event stream) asks this every interval and the status only
    when it changed. 404 for an unknown campaign."""
    with sessions() as s:
        version = queries.campaign_version(s, campaign_id)
    if version is None:
        raise NotFoundError(f"no campaign {campaign_id}")
    live = runner.live(campaign_id)
    return (*version, None if live is None else str(live["current"]))


def campaign_status(
    sessions: sessionmaker, runner: CampaignRunner, campaign_id: str
) -> dict[str, Any]:
    """Everything ``GET /campaigns/{id}`` shows: state, progress, current pose, time left.

    Counts results per pose instead of reading every result, so that a campaign of tens of
    thousands of results answers in a few milliseconds.
    """
    # What the runner knows first, then the rows: a campaign the runner no longer runs has its
    # final state written by then (BackgroundRunner.find), so a finished campaign never reads
    # as "running" without its live figures.
    live = runner.live(campaign_id)
    with sessions() as s:
        row = queries.require_campaign(s, campaign_id)
        poses = queries.planned_poses(s, campaign_id)
        per_pose = queries.results_per_pose(s, campaign_id)
        done = sum(per_pose.values())
        current, eta = None, None
        if live is not None and row.state == "running":
            current = live["current"]
            if live["done_in_run"] > 0:
                eta = (row.poses_total - done) * live["elapsed_s"] / live["done_in_run"]
        elif row.state not in queries.TERMINAL:
            first = next((p for p in poses if per_pose.get(p.pose_index, 0) < p.repeats), None)
            if first is not None:
                have = queries.done_repeats(s, campaign_id, first.pose_index)
                # None if the pose's last repeat was committed between the two reads
                repeat = next((r for r in range(first.repeats) if r not in have), None)
                if repeat is not None:
                    current = {"pose_index": first.pose_index, "repeat": repeat,
                               "turntable_deg": first.turntable_deg,
                               "solar_suns": first.solar_suns}
    base = f"/api/v1/campaigns/{campaign_id}"
    return {
        "id": row.id, "name": row.name, "scene_name": row.scene_name, "state": row.state,
        "poses_done": done, "poses_total": row.poses_total, "pose_count": len(poses),
        "calibration_hash": row.calibration_hash,
        "object_fit": object_fit_public(row),
        "source": "recording" if row.replay_path is not None else "rig",
        "recording": _recording_name(row),
        "current_pose": current, "eta_s": eta, "error": row.error, "runs": row.runs,
        "created_at": row.created_at, "started_at": row.started_at,
        "updated_at": row.updated_at, "finished_at": row.finished_at,
        "links": {k: f"{base}/{k}" for k in ("events", "results", "report", "documents")}
        | {"self": base}
        | ({"recording": f"{base}/recording"}
           if recording_file(row, runner.settings.data_dir) is not None else {}),
    }


def _recording_name(row: Any) -> str | None:
    path = row.replay_path or row.record_path
    return None if path is None else Path(path).name


def recording_file(row: Any, data_dir: str | Path) -> Path | None:
    """The recording a campaign wrote (``"record": true``) in the data directory ``data_dir``,
    once it holds a frame; None otherwise (a replay's is the one it read, named in its
    ``recording``)."""
    if row.record_path is None:
        return None
    path = resolve_stored_path(data_dir, row.record_path)
    return path if path.is_file() else None


def object_fit_public(row) -> dict[str, Any] | None:
    """A campaign's object fit as ``GET /campaigns/{id}`` shows it (None: no fit).

    ``state`` is ``pending`` until the fit has run, then ``fitted`` with the object twin (the
    reality file's keys ``mount`` and ``objects``), its hash and the fit's report.
    """
    if row.object_fit_json is None:
        return None
    fitted = row.object_twin_json is not None
    return {
        "settings": json.loads(row.object_fit_json),
        "state": "fitted" if fitted else "pending",
        "object_twin_hash": row.object_twin_hash,
        "object_twin": json.loads(row.object_twin_json) if fitted else None,
        "report": json.loads(row.object_fit_report_json) if row.object_fit_report_json else None,
    }


def delete_campaign(
    sessions: sessionmaker, runner: CampaignRunner, store: FrameStore, campaign_id: str
) -> int:
    """Delete a campaign that is not running, its results and its frames; returns how many
    frames went (see :func:`_delete_rows_and_files` for the order and a full disk)."""
    with sessions() as s:
        row = queries.require_campaign(s, campaign_id)
        if row.state == "running" or runner.live(campaign_id) is not None:
            raise ConflictError(f"campaign {campaign_id} is running; pause or cancel it first")
        frame_ids = queries.campaign_frame_ids(s, campaign_id)

    def rows() -> None:
        with sessions() as s:
            queries.delete_campaign(s, campaign_id)

    _delete_rows_and_files(store, rows, frame_ids, f"deleting campaign {campaign_id}")
    delete_campaign_frames_file(store, campaign_id)
    return len(frame_ids)


def delete_frame(sessions: sessionmaker, store: FrameStore, frame_id: str) -> None:
    """Delete a frame no pose result compares (409 naming the results that do)."""
    with sessions() as s:
        if queries.get_frame(s, frame_id) is None:
            raise NotFoundError(f"no frame {frame_id}")
        results = queries.results_naming_frame(s, frame_id)
        if results:
            raise ConflictError(
                f"frame {frame_id} is compared in pose result(s) {results}; delete its "
                "campaign instead (DELETE /api/v1/campaigns/{id})")

    def rows() -> None:
        with sessions() as s:
            queries.delete_frame(s, frame_id)

    _delete_rows_and_files(store, rows, [frame_id], f"deleting frame {frame_id}")


def _delete_rows_and_files(
    store: FrameStore, delete_rows: Callable[[], None], frame_ids: list[str], what: str
) -> None:
    """Delete rows (one transaction) and then the frames' folders, also on a full disk.

    Deleting is the remedy for a full disk, but SQLite needs room to delete: every page the
    transaction changes goes into its write-ahead log first. So:

    1. the disk reserve (a file of allocated bytes the service keeps while there is room,
       :class:`service.store.disk_space.SpaceReserve`) is given back first: its room takes the
       log, and the rows go before the folders, as usual (a crash in between leaves folders
       without rows, which the next start sweeps away);
    2. if the disk is full all the same (no reserve: the service started on a full disk; or a
       delete larger than the reserve), the folders go first, their room taking the log, and
       the rows are deleted again. Should that fail too, the rows remain without their files
       (reads answer 410 naming them) and a repeated delete completes.

    The reserve is made again afterwards if the room is there. Without any room at all the
    answer is a 507 naming the deletion.
    """
    with store.room_to_delete():
        try:
            delete_rows()
        except Exception as exc:
            if not is_disk_full(exc):
                raise
            store.delete(frame_ids)
            try:
                delete_rows()
            except Exception as again:
                if not is_disk_full(again):
                    raise
                raise InsufficientStorageError(
                    f"the disk is full: {what} needs room for the database's log, and there is "
                    f"none even after its frames' files were deleted ({len(frame_ids)}); its "
                    "rows remain (their frames' reads answer 410); "
                    + low_space_message(free_bytes(store.root), None,
                                        then=", then repeat the delete")) from again
        store.delete(frame_ids)
