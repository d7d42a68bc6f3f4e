"""Manual device operations behind ``/api/v1/devices``.

Commands hold the rig (:meth:`RigLease.manual`: 409 while a campaign runs). Status
reads do not take the rig lock - each serial exchange is atomic in its transport, so a read
between a campaign's commands is safe - and the camera, which is not thread-safe, reports only
what its driver has cached. The emergency stop takes no lock at all: it must never wait.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import sessionmaker

from drivers.errors import DeviceError, DeviceTimeoutError
from drivers.rig import Rig
from service.lab.background import BackgroundRunner
from service.lab.poses import check_angle
from service.lab.rig_lease import RigLease
from service.lab.scenes import SceneSource, camera_of, for_use_case
from service.store import queries
from service.store.disk_space import require_free, writing
from service.store.frame_files import FrameStore


def _read(name: str, read) -> dict[str, Any]:
    try:
        return {"name": name, "ok": True, "details": read()}
    except DeviceError as exc:
        return {"name": name, "ok": False, "error": f"{type(exc).__name__}: {exc}"}


def _solar(lease: RigLease) -> dict[str, Any]:
    """The solar simulator's entry: not ok while its supply reports a fault or its interlock
    (the lamp is then out, and no pose relights it: the operator does, once the cause is
    fixed)."""
    rig = lease.require()

    def read() -> dict[str, Any]:
        status = rig.solar.status()
        return {**solar_state(lease), "status": status.describe(),
                "fault": status.fault, "interlock": status.interlock}

    entry = _read("solar_simulator", read)
    details = entry.get("details", {})
    if entry["ok"] and (details["fault"] or details["interlock"]):
        cause = ("its interlock is open" if details["interlock"]
                 else "the lamp supply reports a fault")
        entry.update(ok=False, error=(
            f"LampFault: {cause} ({details['status']}); fix the cause, then relight the lamp "
            "(POST /api/v1/devices/solar/lamp)"))
    return entry


def status(lease: RigLease, simulated: bool) -> dict[str, Any]:
    """Every device with what it reports, or its error."""
    rig = lease.rig
    if rig is None:
        devices = [{"name": n, "ok": False, "error": lease.error or "not configured"}
                   for n in ("turntable", "solar_simulator", "camera")]
    else:
        devices = [
            _read("turntable", lambda: {**turntable_position(lease),
                                        "status": rig.turntable.status().describe()}),
            _solar(lease),
            _camera(rig),
        ]
    return {"simulated": simulated, "campaign_id": lease.campaign_id,
            "calibration_id": lease.calibration_id, "devices": devices}


def _camera(rig: Rig) -> dict[str, Any]:
    """The camera's entry: what its driver has cached, and not ok while its captures fail.

    Its identity is cached at connection, so it alone would show a camera that delivers no
    frame as ok; the rig's record of the last captures (:meth:`Rig.camera_health`) says
    whether it delivers (``details.captures``): after a failed capture the entry is not ok and
    ``error`` names how many captures failed in a row and the last one's error (a
    ``DeviceTimeoutError``: no frame within the read timeout). The next capture that delivers
    its frames makes it ok again.
    """
    entry = _read("camera", lambda: {**rig.camera.identity().to_dict(),
                                     "use_case": rig.camera.use_case.name})
    health = rig.camera_health()
    failures = health["failures_in_row"]
    if entry["ok"]:
        entry["details"]["captures"] = health
        if failures:
            entry.update(ok=False, error=(
                f"CameraFailing: {failures} capture{'s' if failures > 1 else ''} in a row "
                f"failed; the last: {health['last_error']}"))
    return entry


def turntable_position(lease: RigLease) -> dict[str, Any]:
    rig = lease.require()
    low, high = rig.turntable.limits_deg
    return {"angle_deg": rig.turntable.position_deg(), "limits_deg": (low, high)}


def home(lease: RigLease) -> dict[str, Any]:
    with lease.manual() as rig:
        rig.turntable.home()
    return turntable_position(lease)


def move(lease: RigLease, angle_deg: float) -> dict[str, Any]:
    rig = lease.require()
    check_angle(rig, angle_deg, "angle_deg")  # 422 before the rig is even asked for
    with lease.manual() as rig:
        rig.turntable.move_to(angle_deg)
    return turntable_position(lease)


def enable_turntable(lease: RigLease) -> dict[str, Any]:
    """Leave the disabled state a stall or a following error left the controller in."""
    with lease.manual() as rig:
        rig.turntable.enable()
    return turntable_position(lease)


def reset_turntable(lease: RigLease) -> dict[str, Any]:
    """Reboot the controller (it comes back not referenced: the next move homes first)."""
    with lease.manual() as rig:
        rig.turntable.reset()
    return turntable_position(lease)


def solar_state(lease: RigLease) -> dict[str, Any]:
    solar = lease.require().solar
    return {"lamp_on": solar.is_lamp_on(), "suns": solar.read_suns(),
            "shutter_open": solar.shutter_is_open()}


def set_lamp(lease: RigLease, on: bool) -> dict[str, Any]:
    """The operator's lamp switch; lighting it is how a lamp that went out is relit (a pose
    does not relight it: :meth:`drivers.rig.Rig.apply`)."""
    with lease.manual() as rig:
        rig.switch_lamp(on)
    return solar_state(lease)


def set_level(lease: RigLease, suns: float) -> dict[str, Any]:
    with lease.manual() as rig:
        rig.solar.set_suns(suns)
    return solar_state(lease)


def set_shutter(lease: RigLease, open_: bool) -> dict[str, Any]:
    with lease.manual() as rig:
        if open_:
            rig.solar.open_shutter()
        else:
            rig.solar.close_shutter()
    return solar_state(lease)


def capture(
    lease: RigLease, *, store: FrameStore, sessions: sessionmaker, scene: SceneSource,
    min_free_bytes: int = 0,
) -> dict[str, Any]:
    """Capture one frame, reconstruct it with ``scene``'s camera (the default), store it.

    Below ``min_free_bytes`` free a 507 before the capture; a disk that fills up while the
    frame is stored a 507 too, and nothing is kept."""
    require_free(store.root, min_free_bytes)
    with lease.manual() as rig:
        state = rig.state()
        raw = rig.capture(1)[0]
        use_case = rig.camera.use_case
    camera = camera_of(for_use_case(scene.spec, use_case))
    extra = {"rig": state.to_dict(), "use_case": use_case.name, "scene_name": ""}
    with writing("the captured frame", store.root, min_free_bytes):
        frame_id, image, _ = store.save_measured(raw, camera, extra)
        try:
            with sessions() as s:
                queries.add_frame(s, queries.frame_row(
                    frame_id, "measured", rig=state.to_dict(),
                    summary={"valid_pixels": int(image.valid.sum())}))
        except BaseException:
            store.delete([frame_id])  # no folder without its row
            raise
    return {"frame_id": frame_id, "rig": state.to_dict(),
            "links": {"self": f"/api/v1/frames/{frame_id}"}}


def emergency_stop(lease: RigLease, background: BackgroundRunner) -> dict[str, Any]:
    """Halt the turntable and close the shutter now; stop the running job through the one
    background runner: pause a running campaign, cancel a running calibration job (before its
    next capture).

    The commands go out at once, without the rig lock. A campaign (or a manual call) may be in
    the middle of a rig stage and would open the shutter again, so once that stage has ended -
    the campaign, told to pause, starts no other - both commands are sent again with the rig
    held: when this returns, the stage is halted and the shutter closed.
    """
    rig = lease.require()
    kind, job_id = background.emergency_stop() or (None, None)
    errors: dict[str, str] = {}

    def halt() -> list[str]:
        done = []
        for name, action in (("turntable", rig.turntable.stop),
                             ("shutter", rig.solar.close_shutter)):
            try:
                action()
                done.append(name)
            except DeviceError as exc:
                errors[name] = f"{type(exc).__name__}: {exc}"
        return done

    stopped = halt()
    try:
        with rig.hold(timeout_s=lease.wait_s):
            errors.clear()
            stopped = halt()
    except DeviceTimeoutError as exc:
        errors["rig"] = f"commands sent once; the rig stayed busy: {exc}"
    return {"stopped": stopped, "errors": errors,
            "campaign_paused": job_id if kind == "campaign" else None,
            "calibration_cancelled": job_id if kind == "calibration job" else None}
