"""``/api/v1/devices``: status of the rig and manual commands (409 while a campaign runs)."""

from __future__ import annotations

from fastapi import APIRouter

from service.api.deps import (
    BackgroundDep,
    LeaseDep,
    SceneDep,
    SessionsDep,
    SettingsDep,
    StoreDep,
    TokenDep,
    errors,
)
from service.api.schemas import (
    CaptureOut,
    DevicesPublic,
    LampIn,
    LevelIn,
    MoveIn,
    ShutterIn,
    SolarPublic,
    StopOut,
    TurntablePosition,
)
from service.lab import devices

router = APIRouter(prefix="/devices", tags=["devices"])
COMMAND = errors(401, 409, 503)


@router.get("", response_model=DevicesPublic)
def list_devices(lease: LeaseDep, settings: SettingsDep) -> dict:
    """Status of each device (a device that does not answer is listed with its error)."""
    return devices.status(lease, settings.simulated)


@router.get("/turntable/position", response_model=TurntablePosition, responses=errors(503))
def get_turntable_position(lease: LeaseDep) -> dict:
    """Turntable angle and its software limits."""
    return devices.turntable_position(lease)


@router.post("/turntable/home", response_model=TurntablePosition, responses=COMMAND)
def home_turntable(lease: LeaseDep, _: TokenDep) -> dict:
    """Reference the stage (if it is not referenced)."""
    return devices.home(lease)


@router.post("/turntable/move", response_model=TurntablePosition, responses=COMMAND)
def move_turntable(body: MoveIn, lease: LeaseDep, _: TokenDep) -> dict:
    """Move to ``angle_deg`` (within the stage's software limits, else 422)."""
    return devices.move(lease, body.angle_deg)


@router.post("/turntable/enable", response_model=TurntablePosition, responses=COMMAND)
def enable_turntable(lease: LeaseDep, _: TokenDep) -> dict:
    """Enable the controller again after a stall or a following error (SMC100 ``MM1``)."""
    return devices.enable_turntable(lease)


@router.post("/turntable/reset", response_model=TurntablePosition, responses=COMMAND)
def reset_turntable(lease: LeaseDep, _: TokenDep) -> dict:
    """Reboot the controller (SMC100 ``RS``); the next move references the stage first."""
    return devices.reset_turntable(lease)


@router.get("/solar", response_model=SolarPublic, responses=errors(503))
def get_solar_simulator(lease: LeaseDep) -> dict:
    """Lamp, level in suns and shutter of the solar simulator."""
    return devices.solar_state(lease)


@router.post("/solar/lamp", response_model=SolarPublic, responses=COMMAND)
def set_lamp(body: LampIn, lease: LeaseDep, _: TokenDep) -> dict:
    """Light or put out the lamp."""
    return devices.set_lamp(lease, body.on)


@router.post("/solar/level", response_model=SolarPublic, responses=COMMAND)
def set_solar_level(body: LevelIn, lease: LeaseDep, _: TokenDep) -> dict:
    """Set the level in suns (0.8 to 1.2)."""
    return devices.set_level(lease, body.suns)


@router.post("/solar/shutter", response_model=SolarPublic, responses=COMMAND)
def set_shutter(body: ShutterIn, lease: LeaseDep, _: TokenDep) -> dict:
    """Open or close the shutter."""
    return devices.set_shutter(lease, body.open)


@router.post("/camera/capture", response_model=CaptureOut, status_code=201,
             responses={**COMMAND, **errors(507)})
def capture_frame(
    lease: LeaseDep, store: StoreDep, sessions: SessionsDep, lab_scene: SceneDep,
    settings: SettingsDep, _: TokenDep,
) -> dict:
    """Capture one frame; returns the id of the stored (measured) frame (507 below the free
    space kept)."""
    return devices.capture(lease, store=store, sessions=sessions, scene=lab_scene,
                           min_free_bytes=settings.min_free_bytes)


@router.post("/stop", response_model=StopOut, responses=errors(401, 503))
def emergency_stop(
    lease: LeaseDep, background: BackgroundDep, _: TokenDep
) -> dict:
    """Emergency stop: halt the turntable, close the shutter, pause a running campaign, cancel
    a running calibration job."""
    return devices.emergency_stop(lease, background)
