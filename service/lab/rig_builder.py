"""The one rig builder: the real rig or the simulated lab's, from the service's ``Settings``.

:func:`open_rig` is how the service (:func:`service.lab.lab.open_lab`) and every command that
drives the rig (``toftwin calibrate rig``, ``calibrate material``, ``fit-object``) get their rig,
so both honour the same settings from the same environment: for the real rig the ports
(``TOFTWIN_TURNTABLE_PORT``, ``TOFTWIN_LAMP_PORT``, ``TOFTWIN_SHUTTER_PORT``), the SMC100's
address (``TOFTWIN_TURNTABLE_ADDRESS``), the camera's serial (``TOFTWIN_CAMERA_SERIAL``) and how
it is reached (``TOFTWIN_CAMERA``: usb, royale or a camera bridge ``tcp://HOST:PORT``, which for
the simulated lab is ``toftwin camera-bridge --simulated`` filming this lab's world); for
the simulated lab the camera's render settings and noise seed, the reality, the armed faults and
the turntable's motion. The simulated rig itself is assembled beside the simulators
(:func:`drivers.sim.rig.simulated_rig`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from drivers.rig import Rig
from service.errors import UnavailableError
from service.lab.scenes import SceneSource
from service.settings import Settings

if TYPE_CHECKING:
    from drivers.sim.world import SimulatedWorld

#: the settings that name the real rig's three serial ports
PORT_FIELDS = ("turntable_port", "lamp_port", "shutter_port")
#: the devices a fault may be armed on (``DEVICE:name[:count][@skip]``)
FAULT_DEVICES = ("turntable", "solar-simulator", "camera")
#: bounces of the simulated camera's path tracer
CAMERA_MAX_BOUNCES = 2


def open_rig(settings: Settings, scene: SceneSource) -> tuple[Rig, SimulatedWorld | None]:
    """The simulated rig (rendering ``scene``) or the real one on the configured ports, and the
    simulated lab's world (:class:`drivers.sim.world.SimulatedWorld`; None for the real rig),
    which calibration asks to mount what it needs.

    Raises :class:`~service.errors.UnavailableError` naming the missing ``TOFTWIN_*`` ports of a
    real rig, and the devices' :class:`~drivers.errors.DeviceError` if one cannot be opened
    (those opened so far are closed again).
    """
    if settings.simulated:
        return _open_simulated(settings, scene)
    missing = [name for name in PORT_FIELDS if getattr(settings, name) is None]
    if missing:
        raise UnavailableError(
            f"no {', '.join('TOFTWIN_' + m.upper() for m in missing)} set (or use --simulated)"
        )
    return Rig.open(settings.turntable_port, settings.lamp_port, settings.shutter_port,
                    turntable_address=settings.turntable_address,
                    camera_serial=settings.camera_serial, camera=settings.camera,
                    camera_mode=settings.camera_mode), None


def armed_faults(settings: Settings) -> dict[str, list[str]]:
    """The faults to arm at start, by device: ``{"turntable": ["stall:1"], ...}``.

    >>> armed_faults(Settings(token="x" * 12, simulated=True,
    ...                       faults=["camera:drop:1@3", "turntable:stall"]))
    {'turntable': ['stall'], 'solar-simulator': [], 'camera': ['drop:1@3']}
    """
    armed: dict[str, list[str]] = {device: [] for device in FAULT_DEVICES}
    for text in settings.faults:  # validated by Settings: DEVICE:name[:count][@skip]
        device, _, spec = text.strip().partition(":")
        armed[device].append(spec)
    return armed


def simulated_world(settings: Settings, scene: SceneSource) -> SimulatedWorld:
    """The simulated lab's world: ``scene`` as its reality has it, rendered by the camera with
    the settings' integrator, samples per pixel and noise fraction."""
    from drivers.sim.world import SimulatedWorld
    from sim_core.render import RenderSettings
    from sim_core.render_request import AccuracyTarget, RenderRequest
    from sim_core.twin_file import load_reality

    return SimulatedWorld(
        scene.spec, scene.base_dir,
        RenderRequest(
            RenderSettings(integrator=settings.camera_integrator, spp=settings.camera_spp,
                           max_bounces=CAMERA_MAX_BOUNCES),
            AccuracyTarget(noise_fraction=settings.camera_noise_fraction), effects="all"),
        reality=None if settings.reality is None else load_reality(settings.reality),
    )


def _open_simulated(settings: Settings, scene: SceneSource) -> tuple[Rig, SimulatedWorld]:
    from drivers.sim.rig import simulated_rig
    from service.compute.jobs import RENDER_LOCK

    world = simulated_world(settings, scene)

    def frame_source(request: Any) -> Any:
        with RENDER_LOCK:  # never two renders at once in this process (see RENDER_LOCK)
            return world(request)

    armed = armed_faults(settings)
    rig = simulated_rig(frame_source=frame_source, seed=settings.camera_seed,
                        turntable_instant=settings.sim_motion == "instant",
                        turntable_faults=armed["turntable"],
                        solar_faults=armed["solar-simulator"],
                        camera_faults=armed["camera"],
                        turntable_settling=world.reality.turntable.settling,
                        lab_wait=world.clock.wait,
                        camera_transport="usb" if settings.camera == "usb" else "bridge",
                        camera_bridge=None if settings.camera == "usb" else settings.camera,
                        camera_mode=settings.camera_mode)
    return rig, world
