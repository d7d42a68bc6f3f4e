"""The rig: turntable, solar simulator and ToF camera behind one lock.

:class:`Rig` composes the three device protocols. One ``threading.Lock`` guards the whole rig:
``with rig.hold(): ...`` makes a sequence (move, illuminate, capture) atomic with respect to other
threads (the service's pose loop, a status poll). Rig methods take the lock themselves unless the
calling thread already holds it, so they work both inside and outside ``hold()``.

:meth:`Rig.open` connects the real devices on their ports (and the camera on USB). The
simulated rig - the same real drivers connected to the three simulators - is assembled beside
the simulators (:func:`drivers.sim.rig.simulated_rig`): this module imports no simulator.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from drivers.camera import CameraProtocol, UsbCamera
from drivers.errors import (
    DeviceError,
    DeviceInputError,
    DeviceTimeoutError,
    InterlockError,
    LampFaultError,
    ProtocolError,
    SolarSimulatorError,
    TurntableError,
)
from drivers.solar_simulator import SolarSimulator, SolarSimulatorProtocol
from drivers.turntable import Turntable, TurntableProtocol
from sim_core.raw import RawFrame

__all__ = ["Rig", "RigState"]

_log = logging.getLogger(__name__)

#: angle a stage without its own ``tolerance_deg`` may miss its target by [deg]
ANGLE_TOLERANCE_DEG = 0.01
#: level the solar simulator may read back off the one set [sun] (its power regulation and
#: calibration: a few W of ~400 W)
SUNS_TOLERANCE = 0.02


@dataclass(frozen=True)
class RigState:
    """What the rig is doing, as far as the images are concerned.

    Attributes
    ----------
    turntable_angle_deg : float
        Turntable position in degrees.
    solar_suns : float
        Level of the solar simulator in suns implied by the lamp power (0 with the lamp off).
    shutter_open : bool
        Whether the solar simulator's shutter lets the light through.
    """

    turntable_angle_deg: float
    solar_suns: float
    shutter_open: bool

    def __post_init__(self) -> None:
        if not math.isfinite(self.turntable_angle_deg):
            raise DeviceInputError(
                "turntable_angle_deg", f"got {self.turntable_angle_deg!r}; a finite angle"
            )
        if not (math.isfinite(self.solar_suns) and self.solar_suns >= 0):
            raise DeviceInputError(
                "solar_suns", f"got {self.solar_suns!r}; 0 (lamp off) or a level in suns"
            )

    @property
    def irradiance_suns(self) -> float:
        """Level reaching the scene: ``solar_suns`` with the shutter open, else 0."""
        return self.solar_suns if self.shutter_open else 0.0

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


class Rig:
    """Turntable, solar simulator and camera behind one ``threading.Lock``.

    Parameters
    ----------
    turntable : TurntableProtocol
    solar : SolarSimulatorProtocol
    camera : CameraProtocol
    on_close : iterable of callables
        Called (in order) by :meth:`close` after the devices are closed, e.g. to stop simulators.
    sleep : callable
        How :meth:`wait` lets time pass: ``time.sleep`` on a real rig; the simulated lab's clock
        (:meth:`drivers.sim.lab_clock.LabClock.wait`) on a simulated one.

    Examples
    --------
    >>> from drivers.sim.rig import simulated_rig
    >>> rig = simulated_rig(seed=1)
    >>> with rig.hold():
    ...     state = rig.apply(RigState(30.0, 1.0, True))
    ...     frames = rig.capture(2)
    >>> frames[0].meta["rig"]["turntable_angle_deg"]
    30.0
    >>> rig.close()
    """

    def __init__(
        self,
        turntable: TurntableProtocol,
        solar: SolarSimulatorProtocol,
        camera: CameraProtocol,
        *,
        on_close: Iterable[Callable[[], None]] = (),
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.turntable = turntable
        self.solar = solar
        self.camera = camera
        self.lock = threading.Lock()
        self._owner: int | None = None
        self._held_since = 0.0
        self._on_close = list(on_close)
        self._sleep = sleep
        self._closed = False
        #: the lamp should be burning: a pose or the operator lit it and nobody put it out since
        #: (a lamp found out while this holds went out by itself: it is not relit by a pose)
        self._lamp_wanted = False
        #: captures that failed in a row, and the last one's error (:meth:`camera_health`)
        self._capture_failures = 0
        self._capture_error: str | None = None
        #: the simulators behind a simulated rig (:func:`drivers.sim.rig.simulated_rig`; empty
        #: for a real rig)
        self.sims: dict[str, Any] = {}

    # -- locking ------------------------------------------------------------------------------
    @contextlib.contextmanager
    def hold(self, timeout_s: float | None = None) -> Iterator[Rig]:
        """Hold the rig's lock for a block; yields the rig.

        Nested ``hold()`` in the thread that holds the lock passes straight through. Raises
        :class:`DeviceTimeoutError` (naming the holder) if the lock is not free within
        ``timeout_s`` (None: wait as long as it takes).
        """
        me = threading.get_ident()
        if self._owner == me:
            yield self
            return
        ok = self.lock.acquire() if timeout_s is None else self.lock.acquire(timeout=timeout_s)
        if not ok:
            held = time.monotonic() - self._held_since
            raise DeviceTimeoutError(
                f"rig busy: its lock is held by thread {self._owner} for {held:.1f} s; not "
                f"free within {timeout_s:g} s"
            )
        self._owner, self._held_since = me, time.monotonic()
        try:
            yield self
        finally:
            self._owner = None
            self.lock.release()

    @property
    def is_held(self) -> bool:
        """True while some thread holds the rig."""
        return self.lock.locked()

    # -- state --------------------------------------------------------------------------------
    def state(self) -> RigState:
        """Read the state back from the devices.

        A read-back is a device's word, not the caller's input: a non-finite value is a
        :class:`ProtocolError` (503), never an input error (422). A level a little below zero
        (the lamp calibration extrapolated below its table with the lamp nearly out) reads as 0.
        """
        with self.hold():
            angle = self.turntable.position_deg()
            suns = self.solar.read_suns()
            shutter = self.solar.shutter_is_open()
        for name, value in (("turntable position", angle), ("solar level", suns)):
            if not math.isfinite(value):
                raise ProtocolError(f"{name} read back as {value!r}")
        return RigState(turntable_angle_deg=angle, solar_suns=max(0.0, suns),
                        shutter_open=shutter)

    def apply(self, target: RigState, *, wait_stable_s: float | None = None) -> RigState:
        """Drive the rig to ``target``, check what it reached, and return the state read back.

        Moves the turntable (homing first if needed), lights the lamp and sets the level
        (``solar_suns`` > 0, within 0.8..1.2 suns) or puts the lamp out (0), and opens or closes
        the shutter. With ``wait_stable_s`` the solar simulator's output is waited for
        (:meth:`SolarSimulatorProtocol.wait_until_stable`) before returning.

        A lamp that went out by itself since a pose (or the operator) lit it, or whose supply
        reports a fault or its interlock, is *not* relit: that raises :class:`LampFaultError`
        (:class:`InterlockError`) telling the operator to relight it (:meth:`switch_lamp`,
        ``POST /api/v1/devices/solar/lamp``) once the cause is fixed.

        Then the state is read back and compared with ``target`` (:meth:`verify`): a stage off
        its target, a lamp that went out or reports a fault, a level or a shutter that is not
        what was asked for raise a :class:`DeviceError` naming the device, the target and what
        was read back, so that nothing is captured and stored as if the rig were where it was
        asked to be.
        """
        with self.hold():
            self.turntable.move_to(target.turntable_angle_deg)
            if target.solar_suns > 0:
                if not self.solar.is_lamp_on():
                    self._refuse_to_relight(target)
                    self.solar.lamp_on()
                self._lamp_wanted = True
                self.solar.set_suns(target.solar_suns)
                if wait_stable_s is not None:
                    self.solar.wait_until_stable(wait_stable_s)
            else:
                self._lamp_wanted = False
                if self.solar.is_lamp_on():
                    self.solar.lamp_off()
            if target.shutter_open:
                self.solar.open_shutter()
            else:
                self.solar.close_shutter()
            state = self.state()
            self.verify(target, state, when="after setting it")
            return state

    def _refuse_to_relight(self, target: RigState) -> None:
        """Raise if the lamp, found out, went out by itself or its supply reports why."""
        status = self.solar.status()
        if not (self._lamp_wanted or status.fault or status.interlock):
            return  # out because it was put out (or never lit): a pose may light it
        what = ("went out by itself since it was lit" if self._lamp_wanted
                and not (status.fault or status.interlock) else
                "went out since it was lit" if self._lamp_wanted else "is out")
        why = (": its interlock is open or tripped" if status.interlock else
               ": the supply reports a lamp fault" if status.fault else "")
        error = InterlockError if status.interlock else LampFaultError
        raise error(
            f"solar simulator lamp: {what}{why} ({status.describe()}); "
            f"a pose at {target.solar_suns:g} sun does not relight it: "
            f"{'close the interlock, ' if status.interlock else ''}relight the lamp "
            "(POST /api/v1/devices/solar/lamp) and resume")

    def switch_lamp(self, on: bool) -> None:
        """The operator's lamp switch: light the lamp (or put it out) on purpose.

        Lighting it is how a lamp that went out is relit (poses do not relight it: see
        :meth:`apply`); putting it out records that it is out on purpose, so the next lit pose
        lights it again.
        """
        with self.hold():
            if on:
                self.solar.lamp_on()
                self._lamp_wanted = True
            else:
                self._lamp_wanted = False
                self.solar.lamp_off()

    def verify(self, target: RigState, state: RigState, *, when: str = "after setting it") -> None:
        """Raise a :class:`DeviceError` if ``state`` (read back ``when``) is not ``target``.

        Tolerances: the turntable's own ``tolerance_deg`` (else :data:`ANGLE_TOLERANCE_DEG`),
        :data:`SUNS_TOLERANCE` for the level; the lamp must burn without a fault bit exactly
        when a level above 0 is asked for, and the shutter must be as asked. The message names
        the device, the target and what was read back; the error carries them as ``device``,
        ``target`` and ``read_back``.
        """
        tol_deg = float(getattr(self.turntable, "tolerance_deg", ANGLE_TOLERANCE_DEG))
        error_deg = abs(state.turntable_angle_deg - target.turntable_angle_deg)
        if not error_deg <= tol_deg:
            raise _mismatch(
                TurntableError(
                    f"turntable read back {state.turntable_angle_deg:.4f} deg {when}: target "
                    f"{target.turntable_angle_deg:.4f} deg (tolerance {tol_deg:g} deg)"),
                "turntable", f"{target.turntable_angle_deg:.4f} deg",
                f"{state.turntable_angle_deg:.4f} deg")
        if target.solar_suns > 0:
            status = self.solar.status()
            if status.fault or status.interlock or not status.lamp_on:
                cause = ("interlock tripped" if status.interlock else
                         "lamp fault" if status.fault else "lamp out")
                error = InterlockError if status.interlock else LampFaultError
                read = state.solar_suns if status.lamp_on else 0.0  # out by now, if not before
                raise _mismatch(
                    error(
                        f"solar simulator lamp: {cause} {when}: target {target.solar_suns:g} "
                        f"sun, read back {read:.3f} sun ({status.describe()}); "
                        f"{'close the interlock, ' if status.interlock else ''}relight the lamp "
                        "(POST /api/v1/devices/solar/lamp) and resume"),
                    "solar simulator lamp", f"{target.solar_suns:g} sun", f"{read:.3f} sun")
            if not abs(state.solar_suns - target.solar_suns) <= SUNS_TOLERANCE:
                raise _mismatch(
                    SolarSimulatorError(
                        f"solar level read back {state.solar_suns:.3f} sun {when}: target "
                        f"{target.solar_suns:g} sun (tolerance {SUNS_TOLERANCE:g} sun)"),
                    "solar simulator lamp", f"{target.solar_suns:g} sun",
                    f"{state.solar_suns:.3f} sun")
        elif state.solar_suns > 0:
            raise _mismatch(
                SolarSimulatorError(
                    f"lamp still burning at {state.solar_suns:.3f} sun {when}: target 0 sun "
                    "(lamp out)"),
                "solar simulator lamp", "0 sun", f"{state.solar_suns:.3f} sun")
        if state.shutter_open != target.shutter_open:
            want, got = (("open", "closed") if target.shutter_open else ("closed", "open"))
            raise _mismatch(
                SolarSimulatorError(
                    f"solar simulator shutter: shutter not {want} {when}: target {want}, read "
                    f"back {got}"),
                "solar simulator shutter", want, got)

    def wait(self, seconds: float) -> None:
        """Let ``seconds`` pass with nothing captured and nothing moved (a warm-up sequence's
        pause between captures), holding the rig so that nobody moves it meanwhile.

        Raises
        ------
        ValueError
            ``seconds`` is not a finite time >= 0.
        """
        if not (math.isfinite(seconds) and seconds >= 0.0):
            raise ValueError(f"seconds: got {seconds!r}; allowed: a finite time >= 0 s")
        with self.hold():
            self._sleep(float(seconds))

    def capture(self, n: int = 1, *, target: RigState | None = None) -> list[RawFrame]:
        """Capture ``n`` frames; each frame's ``meta["rig"]`` holds the rig state at capture.

        The state is read back before and after the exposure (``meta["rig"]`` and
        ``meta["rig_after"]``). With ``target`` both are checked against it (:meth:`verify`),
        and so is the rig state a camera reports in a frame's own metadata (``meta["rig"]`` as
        the camera delivered it, where it does): a device that was not in its target state at
        either end of the exposure raises a :class:`DeviceError` naming it, and no frame is
        returned - a frame is good only if every device was where it was asked to be for the
        whole exposure.
        """
        with self.hold():
            before = self.state()
            if target is not None:
                self.verify(target, before, when="before the exposure")
            frames = self._capture_frames(n)
            after = self.state()
            if target is not None:
                self.verify(target, after, when="after the exposure")
                for frame in frames:
                    own = _reported_state(frame.meta.get("rig"))
                    if own is not None:
                        self.verify(target, own, when="in the camera's frame metadata")
        meta = {"rig": before.to_dict(), "rig_after": after.to_dict()}
        return [dataclasses.replace(f, meta={**f.meta, **meta}) for f in frames]

    def _capture_frames(self, n: int) -> list[RawFrame]:
        """The camera's capture, its outcome recorded for :meth:`camera_health`."""
        try:
            frames = self.camera.capture(n)
        except DeviceError as exc:
            self._capture_failures += 1
            self._capture_error = f"{type(exc).__name__}: {exc}"
            raise
        self._capture_failures, self._capture_error = 0, None
        return frames

    def camera_health(self) -> dict[str, Any]:
        """How the camera's captures went: ``{"failures_in_row", "last_error"}``.

        ``failures_in_row`` counts the captures that failed since the last one that delivered
        its frames (0: the last capture worked, or none was tried); ``last_error`` is the last
        failure's error (class and message), None when ``failures_in_row`` is 0.
        """
        return {"failures_in_row": self._capture_failures, "last_error": self._capture_error}

    # -- life cycle ---------------------------------------------------------------------------
    def close(self) -> None:
        """Close the camera and both serial drivers, then run ``on_close``; safe to call twice.

        Does not wait for the lock: closing must work even if a holder is stuck.
        """
        if self._closed:
            return
        self._closed = True
        for device in (self.camera, self.solar, self.turntable):
            try:
                device.close()
            except Exception as exc:  # close everything even if one device fails
                _log.warning("rig close: %s: %s", type(device).__name__, exc)
        for hook in self._on_close:
            try:
                hook()
            except Exception as exc:
                _log.warning("rig close hook failed: %s", exc)

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the real rig -------------------------------------------------------------------------
    @classmethod
    def open(
        cls,
        turntable_port: str,
        lamp_port: str,
        shutter_port: str,
        *,
        turntable_address: int = 1,
        camera_serial: str | None = None,
        usb_backend: Any = None,
        camera: str = "usb",
        camera_mode: str = "raw",
    ) -> Rig:
        """Open and connect the three devices of the real rig and return it.

        Connects, in this order, the :class:`Turntable` (SMC100 on ``turntable_port`` at RS-485
        address ``turntable_address``), the :class:`SolarSimulator` (lamp supply on
        ``lamp_port``, exposure controller on ``shutter_port``) and the :class:`UsbCamera`
        (``camera_serial``, the first pico flexx when None), each with its default settings. If
        one fails, the devices opened so far (and the one that failed) are closed and the error
        propagates (:class:`~drivers.errors.DeviceDisconnectedError` for a port that cannot be
        opened, :class:`drivers.camera.CameraNotFoundError`, ...).

        Parameters
        ----------
        turntable_port, lamp_port, shutter_port : str
            Device paths or pyserial URLs.
        turntable_address : int
            The SMC100's RS-485 address.
        camera_serial : str or None
            USB serial number of the camera.
        usb_backend : pyusb backend or None
            libusb when None; a :class:`drivers.sim.usb_camera.UsbCameraSim` for the simulator.
        camera : str
            ``"usb"`` (:class:`UsbCamera`), ``"royale"`` (:class:`drivers.camera.RoyaleCamera`,
            PMD's roypy in this process) or ``"tcp://HOST:PORT"``
            (:class:`drivers.camera.bridge_client.BridgeCamera`, a camera bridge);
            ``camera_serial`` is the camera's id for the latter two.
        camera_mode : str
            ``"raw"`` (royale's raw data) or ``"depth"`` (royale's processed depth, for a camera
            without raw access: the latter two only).
        """
        opened: list[Any] = []
        try:
            turntable = Turntable(turntable_port, address=turntable_address)
            opened.append(turntable)
            turntable.connect()
            solar = SolarSimulator(lamp_port, shutter_port)
            opened.append(solar)
            solar.connect()
            camera = _camera(camera, camera_serial, usb_backend, camera_mode)
            opened.append(camera)
            camera.connect()
        except BaseException:
            for device in reversed(opened):
                with contextlib.suppress(Exception):
                    device.close()
            raise
        return cls(turntable, solar, camera)


def _camera(kind: str, camera_id: str | None, usb_backend: Any,
            mode: str = "raw") -> CameraProtocol:
    """The real rig's camera driver of ``kind`` (see :meth:`Rig.open`), not yet connected."""
    if kind == "usb":
        if mode != "raw":
            raise DeviceInputError("camera_mode", "our USB wire format carries raw frames only; "
                                   "royale's processed depth needs camera royale or a bridge")
        return UsbCamera(camera_id, backend=usb_backend)
    if kind == "royale":
        from drivers.camera.royale import RoyaleCamera

        return RoyaleCamera(camera_id, mode=mode)
    from drivers.camera.bridge_client import BridgeCamera

    return BridgeCamera(kind, camera_id, mode=mode)


def _mismatch(error: DeviceError, device: str, target: str, read_back: str) -> DeviceError:
    """``error`` with the device, its target and what it read back as attributes."""
    error.device, error.target, error.read_back = device, target, read_back
    return error


def _reported_state(meta: Any) -> RigState | None:
    """The rig state a camera put in a frame's metadata, if it did (a mapping of the three)."""
    if not isinstance(meta, dict):
        return None
    try:
        return RigState(float(meta["turntable_angle_deg"]), float(meta["solar_suns"]),
                        bool(meta["shutter_open"]))
    except (KeyError, TypeError, ValueError, DeviceInputError):
        return None
