"""The simulated rig: the three simulators started, and the rig's *real* drivers connected to them.

:func:`simulated_rig` starts the SMC100 and the Oriel units on pseudo-terminals (or TCP;
:func:`drivers.sim.pty_server.start_simulator`) and the camera as a pyusb backend
(:class:`drivers.sim.usb_camera.UsbCameraSim`), and returns a :class:`drivers.rig.Rig` whose
:class:`~drivers.turntable.Turntable`, :class:`~drivers.solar_simulator.SolarSimulator` and
:class:`~drivers.camera.UsbCamera` speak the devices' bytes to them. The simulated camera's frame
source receives, with every request, the rig state read from the simulators' physical models
(``CameraRequest.rig_state``), so a renderer plugged in as ``frame_source`` renders for the
current turntable angle and illumination.

It lives beside the simulators so that :mod:`drivers.rig` (and the real drivers) import none of
them (an import-linter contract).
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from drivers.camera import UsbCamera, UsbCameraSettings
from drivers.camera.bridge_client import BridgeCamera
from drivers.errors import DeviceInputError
from drivers.rig import Rig, RigState
from drivers.sim import SimClock
from drivers.sim.bridge_source import SimulatedCameraSource
from drivers.sim.pty_server import SimHandle, start_simulator
from drivers.sim.smc100 import Smc100Sim
from drivers.sim.usb_camera import FrameSource, UsbCameraSim
from drivers.sim.world_link import WorldLinkServer
from drivers.solar_simulator import LAMP_SETTINGS, SHUTTER_SETTINGS, SolarSimulator
from drivers.turntable import SMC100_SETTINGS, Turntable
from sim_core.twin_file import TurntableSettling
from toftwin_camera_bridge import BridgeServer

__all__ = ["SimulatedRigState", "simulated_rig"]

#: longest wait for a bridged simulated frame (a path-traced frame may take a while; a bridge
#: that goes away is noticed at once, not after this)
BRIDGE_FRAME_TIMEOUT_S = 600.0


@dataclass(frozen=True)
class SimulatedRigState(RigState):
    """The rig state read from the simulators' physical models, with the table's motion ahead.

    ``turntable_angle_deg`` is the table's physical angle (its ringing included, which the
    controller does not report: :mod:`drivers.sim.smc100`); ``table_angle_after_deg(dt_s)`` is
    the table's angle ``dt_s`` simulated seconds later if no command arrives in between (a frame
    source renders each sub-frame of a frame at its time with it).
    """

    table_angle_after_deg: Callable[[float], float] | None = field(
        default=None, compare=False, repr=False)
    #: the stage rings on its own clock (a settling, and a stage that moves in time): a world
    #: that would ring an instant stage's table on the lab's clock leaves it to the stage
    stage_rings: bool = field(default=False, compare=False)


def simulated_rig(
    frame_source: FrameSource | None = None,
    *,
    seed: int = 0,
    use_case: str = "MODE_5_45FPS_500",
    instant: bool = True,
    time_scale: float = 1.0,
    turntable_instant: bool | None = None,
    transport: str = "pty",
    turntable_faults: Iterable[str] = (),
    solar_faults: Iterable[str] = (),
    camera_faults: Iterable[str] = (),
    camera_settings: UsbCameraSettings | None = None,
    turntable_settling: TurntableSettling | None = None,
    lab_wait: Callable[..., None] | None = None,
    camera_transport: str = "usb",
    camera_bridge: str | None = None,
    camera_mode: str = "raw",
) -> Rig:
    """Start the three simulators and return a rig with real drivers connected to them.

    Closing the rig closes the drivers and stops the simulators; ``rig.sims`` holds them
    (``"turntable"``, ``"solar"``: :class:`~drivers.sim.pty_server.SimHandle`; ``"camera"``:
    the :class:`~drivers.sim.usb_camera.UsbCameraSim`; ``"bridge"``: the camera bridge's
    :class:`toftwin_camera_bridge.BridgeServer` when the camera is bridged in this process, the
    :class:`~drivers.sim.world_link.WorldLinkServer` an outside bridge films).

    Parameters
    ----------
    frame_source : callable or None
        ``CameraRequest -> RawFrame`` for the simulated camera (a plane at 1 m when None);
        ``request.rig_state`` is the :class:`~drivers.rig.RigState` of the simulated devices.
    seed : int
        The camera simulator's noise seed.
    use_case : str
        Use case the camera is configured with.
    instant : bool
        Motions, warm-up and frame timing complete at once (fast tests); otherwise the
        simulators run in (scaled) real time.
    time_scale : float
        Simulated seconds per wall-clock second for the serial simulators.
    turntable_instant : bool or None
        The turntable's own ``instant`` (None: ``instant``): ``False`` with an instant rig
        gives a stage that moves at its speed (20 deg/s) while the lamp and camera stay
        instant, so that a move can be watched and stopped.
    transport : {"pty", "tcp"}
        Where the serial simulators are served.
    turntable_faults, solar_faults, camera_faults : iterable of str
        Faults armed at start (``"stall:1"``, ``"lamp-fault"``, ``"drop:1@3"``).
    camera_settings : UsbCameraSettings or None
        Driver settings for the camera.
    turntable_settling : TurntableSettling or None
        The table's ringing after every move (a reality's ``turntable.settling``); it needs a
        turntable that is not instant (an instant one has settled at once).
    lab_wait : callable or None
        How the rig's :meth:`~drivers.rig.Rig.wait` lets time pass: the simulated lab's clock
        (``world.clock.wait`` of a :class:`drivers.sim.world.SimulatedWorld`, whose warm-up
        and a table's ringing follow it); None: at once (an instant rig) or asleep in scaled
        real time. An instant stage's post-move wait passes on it too,
        ``lab_wait(seconds, turntable_angle_deg=...)`` with where the stage stopped (the move
        ends before the wait: :meth:`drivers.sim.lab_clock.LabClock.wait`).
    camera_transport : {"usb", "bridge"}
        How the rig's camera reaches the simulated one: our USB driver over the pyusb backend
        (:class:`~drivers.camera.UsbCamera`), or the camera bridge's protocol over TCP
        (:class:`~drivers.camera.bridge_client.BridgeCamera` against a
        :class:`toftwin_camera_bridge.BridgeServer` serving
        :class:`drivers.sim.bridge_source.SimulatedCameraSource` with the same frame source and
        devices; the USB camera's faults do not apply to it).
    camera_bridge : str or None
        With ``camera_transport="bridge"``: a simulated camera bridge already running there
        (``tcp://HOST:PORT``, ``toftwin camera-bridge --simulated``) instead of one in this
        process; it films this rig's world through a
        :class:`drivers.sim.world_link.WorldLinkServer` (closed with the rig).
    camera_mode : {"raw", "depth"}
        With the bridge: royale's raw data, or its processed depth
        (:class:`~sim_core.processed_depth.ProcessedDepthFrame`).

    Examples
    --------
    >>> with simulated_rig(seed=1) as rig:
    ...     rig.apply(RigState(30.0, 0.0, False)).turntable_angle_deg
    30.0
    """
    if camera_mode != "raw" and camera_transport != "bridge":
        raise DeviceInputError("camera_mode", "the simulated USB camera sends raw frames only; "
                               "royale's processed depth comes through the camera bridge")
    if camera_transport not in ("usb", "bridge"):
        raise DeviceInputError("camera_transport", f"got {camera_transport!r}; usb or bridge")
    if camera_transport == "bridge" and list(camera_faults):
        raise DeviceInputError("camera_faults", "the USB camera's faults; the bridged camera "
                                                "has none (stop the bridge to fail it)")
    started: list[Callable[[], None]] = []
    bridge: BridgeServer | WorldLinkServer | None = None
    try:
        tt_instant = instant if turntable_instant is None else turntable_instant
        lab_stage = lab_wait is not None and tt_instant  # an instant stage on the lab's clock
        serial_sims = []
        for device, faults, device_instant in (("turntable", turntable_faults, tt_instant),
                                               ("solar-simulator", solar_faults, instant)):
            sim = start_simulator(device, faults, transport=transport, instant=device_instant,
                                  time_scale=time_scale)
            started.append(sim.stop)
            serial_sims.append(sim)
        tt_sim, solar_sim = serial_sims
        tt_sim.models["turntable"].settling = turntable_settling
        cam_sim = UsbCameraSim(
            frame_source,
            seed=seed,
            instant=instant,
            faults=camera_faults,
            state_provider=_physical_state(tt_sim, solar_sim),
        )
        fast = instant or time_scale > 1
        tt_fast = tt_instant or time_scale > 1
        turntable = Turntable(
            tt_sim.ports[0],
            settle_s=0.0 if tt_fast else 0.2,
            poll_interval_s=0.005 if tt_fast else 0.05,
            stall_timeout_s=0.5 if tt_fast else 2.0,
            settings=dataclasses.replace(
                SMC100_SETTINGS, timeout_s=0.5, reconnect_timeout_s=3.0
            ),
            sleep=(_lab_sleep(lab_wait, tt_sim.models["turntable"]) if lab_stage
                   else _clock_sleep(tt_sim.models["turntable"].clock)),
        )
        turntable.connect()
        started.append(turntable.close)
        if lab_stage:
            # the lab's clock knows where the stage starts: its first move is timed from there
            lab_wait(0.0, turntable_angle_deg=tt_sim.models["turntable"].current_position())
        solar = SolarSimulator(
            *solar_sim.ports,
            warmup_s=0.0 if instant else 1800.0 / time_scale,
            poll_interval_s=0.01 if fast else 0.5,
            lamp_settings=dataclasses.replace(
                LAMP_SETTINGS, timeout_s=0.5, reconnect_timeout_s=3.0
            ),
            shutter_settings=dataclasses.replace(
                SHUTTER_SETTINGS, timeout_s=0.5, reconnect_timeout_s=3.0
            ),
        )
        solar.connect()
        started.append(solar.close)
        if camera_transport == "bridge" and camera_bridge is not None:
            bridge = WorldLinkServer(frame_source or cam_sim.frame_source,
                                     _physical_state(tt_sim, solar_sim)).start()
            started.append(bridge.close)
            camera = BridgeCamera(camera_bridge, use_case=use_case, world_url=bridge.url,
                                  frame_timeout_s=BRIDGE_FRAME_TIMEOUT_S, mode=camera_mode)
        elif camera_transport == "bridge":
            bridge = _camera_bridge(frame_source or cam_sim.frame_source,
                                    _physical_state(tt_sim, solar_sim), seed)
            started.append(bridge.close)
            camera = BridgeCamera(f"tcp://127.0.0.1:{bridge.address[1]}", use_case=use_case,
                                  frame_timeout_s=BRIDGE_FRAME_TIMEOUT_S, mode=camera_mode)
        else:
            camera = UsbCamera(backend=cam_sim, use_case=use_case, settings=camera_settings)
        camera.connect()
    except BaseException:
        for stop in reversed(started):
            with contextlib.suppress(Exception):
                stop()
        raise
    # A wait of the rig's own (a warm-up's pause, a capture's rest) on an instant stage tells
    # the lab's clock where the stage stands too: a move just made ends before it, and rings
    # during it, not after it.
    rig_sleep = (_lab_sleep(lab_wait, tt_sim.models["turntable"]) if lab_stage
                 else lab_wait or _scaled_sleep(0.0 if instant else time_scale))
    closers = [solar_sim.stop, tt_sim.stop]
    if bridge is not None:
        closers.insert(0, bridge.close)
    rig = Rig(turntable, solar, camera, on_close=closers, sleep=rig_sleep)
    rig.sims = {"turntable": tt_sim, "solar": solar_sim, "camera": cam_sim}
    if bridge is not None:
        rig.sims["bridge"] = bridge
    return rig


def _camera_bridge(frame_source: FrameSource, state: Callable[[], RigState],
                   seed: int) -> BridgeServer:
    """A camera bridge serving the simulated camera on a free loopback port."""
    return BridgeServer(lambda on_frame: SimulatedCameraSource(on_frame, frame_source, state,
                                                               seed=seed),
                        "127.0.0.1", 0).start()


def _scaled_sleep(time_scale: float) -> Callable[[float], None]:
    """Sleep ``seconds / time_scale`` of wall time; 0: return at once (an instant rig)."""

    def sleep(seconds: float) -> None:
        if time_scale > 0.0:
            time.sleep(seconds / time_scale)

    return sleep


def _physical_state(tt_sim: SimHandle, solar_sim: SimHandle) -> Callable[[], RigState]:
    """Read the rig state from the simulators' models (not through the drivers or the lock)."""
    smc = tt_sim.models["turntable"]
    solar = solar_sim.models["rig"]

    def state() -> RigState:
        lamp = solar.lamp
        suns = (
            solar.calibration.suns_for(lamp.electrical()[2], extrapolate=True)
            if lamp.lamp_on
            else 0.0
        )
        now_s = smc.clock.now()
        return SimulatedRigState(
            turntable_angle_deg=smc.table_angle_deg(now_s),
            solar_suns=max(0.0, suns),
            shutter_open=bool(solar.shutter.is_open),
            table_angle_after_deg=lambda dt_s: smc.table_angle_deg(now_s + dt_s),
            stage_rings=smc.settling is not None and not smc.clock.instant,
        )

    return state


def _lab_sleep(lab_wait: Callable[..., None], smc: Smc100Sim) -> Callable[[float], None]:
    """An instant stage's post-move wait on the simulated lab's clock: the move the stage just
    made (its motor's position) ends, then ``seconds`` pass."""

    def sleep(seconds: float) -> None:
        lab_wait(seconds, turntable_angle_deg=smc.current_position())

    return sleep


def _clock_sleep(clock: SimClock) -> Callable[[float], None]:
    """The turntable driver's post-move wait on the simulated stage's clock: ``seconds`` of
    simulated time are ``seconds / time_scale`` of wall time, none on an instant clock (whose
    table has settled at once: :class:`drivers.sim.smc100.Smc100Sim`)."""

    def sleep(seconds: float) -> None:
        wall_s = clock.duration(seconds) / clock.time_scale
        if wall_s > 0.0:
            time.sleep(wall_s)

    return sleep
