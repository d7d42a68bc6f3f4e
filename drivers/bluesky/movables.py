"""The turntable and the solar simulator's level as ophyd-async movables over our drivers.

:class:`TurntableMotor` wraps a :class:`~drivers.turntable.TurntableProtocol` (the SMC100
driver, :class:`~drivers.turntable.Turntable`): ``set(angle_deg)`` is the driver's
:meth:`~drivers.turntable.Turntable.move_to` (homing first where the controller is not
referenced; it returns once the stage is at rest and its position verified), the readback its
``position_deg()``, the limits its ``limits_deg`` (the controller's SL/SR with any of the
driver's own). A target outside them is refused before anything is sent, by the device
(:meth:`~ophyd_async.core.StandardMovable.check_value`, which Bluesky's ``check_limits`` calls
for a whole plan) and by ``set``, with :class:`~drivers.errors.LimitError` naming the device,
the value and the range with its unit.

:class:`SolarLevel` wraps a :class:`~drivers.solar_simulator.SolarSimulatorProtocol`: its
value is the level at the sample in suns, ``set(suns)`` lights the lamp where it is out and
sets the level (0.8 to 1.2 sun, through the driver's calibration table), ``set(0)`` puts the
lamp out; the shutter (:attr:`SolarLevel.shutter`) and the lamp switch
(:attr:`SolarLevel.lamp`) are signals of their own. As on :class:`drivers.rig.Rig`, a lamp
that went out by itself since it was lit is not relit by a ``set``: that raises
:class:`~drivers.errors.LampFaultError`, and the operator relights it (``lamp.set(True)``).

Every driver call runs in a worker thread under a lock (:class:`drivers.bluesky.calls.
DriverCalls`; a rig's devices share the rig's). The units are the drivers' own: degrees and
suns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property, partial

from ophyd_async.core import (
    MovableLogic,
    StandardMovable,
    StandardReadable,
    TimeoutCalculator,
    soft_signal_r_and_setter,
    soft_signal_rw,
)
from ophyd_async.core import StandardReadableFormat as Format

from drivers.bluesky.calls import DriverCalls, Hold
from drivers.errors import LampFaultError, LimitError, SolarSimulatorError
from drivers.rig import SUNS_TOLERANCE
from drivers.solar_simulator import SUNS_RANGE, SolarSimulatorProtocol
from drivers.turntable import TurntableProtocol

__all__ = ["SolarLevel", "TurntableMotor"]


def _limits(driver: TurntableProtocol) -> tuple[float, float]:
    """The driver's allowed range in degrees (its ``limits_deg``, a property or a method)."""
    limits = driver.limits_deg
    low, high = limits() if callable(limits) else limits
    return float(low), float(high)


# -- the turntable ---------------------------------------------------------------------------
@dataclass
class _TurntableMove(MovableLogic[float]):
    device: TurntableMotor

    async def check_move(self, new_position: float) -> None:
        self.device.check_target(new_position)

    async def move(self, new_position: float, timeout: TimeoutCalculator) -> None:
        # the driver times its own move and homing (move_timeout_s, home_timeout_s) and stops
        # the stage when one runs out: no second clock here
        target = float(new_position)
        await self.setpoint.set(target)
        await self.device.calls(self.device.driver.move_to, target)
        await self.readback.get_value(cached=False)  # read anew: to every watcher too

    async def stop(self) -> None:
        await self.device.calls.unlocked(self.device.driver.stop)


class TurntableMotor(StandardReadable, StandardMovable[float]):
    """The SMC100 turntable as an ophyd-async movable in degrees.

    Parameters
    ----------
    driver : TurntableProtocol
        A connected turntable driver (:class:`~drivers.turntable.Turntable`).
    hold : callable or None
        Held around every driver call (:class:`~drivers.bluesky.calls.DriverCalls`); the
        rig's :meth:`~drivers.rig.Rig.hold` for the devices of one rig.
    name : str
        The device's name; its readback's data key in an event is this name.

    Readings: the position (hinted; its name is the device's) and ``-setpoint`` (the
    controller's own target where the driver reports it, ``setpoint_deg()``, else the last
    target set here); configuration: ``-low_limit``, ``-high_limit`` [deg].
    """

    def __init__(self, driver: TurntableProtocol, *, hold: Hold | None = None,
                 name: str = "") -> None:
        self.driver = driver
        self.calls = DriverCalls(hold)
        with self.add_children_as_readables(Format.HINTED_UNCACHED_SIGNAL):
            self.readback, _ = soft_signal_r_and_setter(
                float, units="deg", precision=4, getter=partial(self.calls, driver.position_deg))
        setpoint_deg = getattr(driver, "setpoint_deg", None)
        with self.add_children_as_readables(Format.UNCACHED_SIGNAL):
            self.setpoint = soft_signal_rw(
                float, units="deg", precision=4,
                getter=None if setpoint_deg is None else partial(self.calls, setpoint_deg))
        with self.add_children_as_readables(Format.CONFIG_SIGNAL):
            self.low_limit, _ = soft_signal_r_and_setter(
                float, units="deg", getter=lambda: _limits(driver)[0])
            self.high_limit, _ = soft_signal_r_and_setter(
                float, units="deg", getter=lambda: _limits(driver)[1])
        super().__init__(name=name)

    @cached_property
    def movable_logic(self) -> _TurntableMove:
        return _TurntableMove(setpoint=self.setpoint, readback=self.readback, device=self)

    def check_target(self, angle_deg: float) -> None:
        """Raise :class:`~drivers.errors.LimitError` (a ``ValueError``) for a target outside
        the driver's limits or not a finite number, naming this device."""
        low, high = _limits(self.driver)
        angle = float(angle_deg)
        if not (math.isfinite(angle) and low <= angle <= high):
            raise LimitError(self.name or "turntable", angle, low, high, "deg",
                             "the turntable's software limits SL/SR")


# -- the solar simulator ---------------------------------------------------------------------
@dataclass
class _SolarMove(MovableLogic[float]):
    device: SolarLevel

    async def check_move(self, new_position: float) -> None:
        self.device.check_level(new_position)

    async def move(self, new_position: float, timeout: TimeoutCalculator) -> None:
        suns = float(new_position)
        await self.setpoint.set(suns)
        await self.device.calls(self.device.apply_level, suns)
        await self.readback.get_value(cached=False)


class SolarLevel(StandardReadable, StandardMovable[float]):
    """The solar simulator's level at the sample, in suns, as an ophyd-async movable.

    Parameters
    ----------
    driver : SolarSimulatorProtocol
        A connected solar simulator driver (:class:`~drivers.solar_simulator.SolarSimulator`).
    hold : callable or None
        Held around every driver call (the rig's :meth:`~drivers.rig.Rig.hold` for the
        devices of one rig).
    wait_stable_s : float or None
        After setting a level, wait up to this long for the lamp's output to be stable
        (:meth:`~drivers.solar_simulator.SolarSimulator.wait_until_stable`; an arc lamp drifts
        for about 30 minutes after ignition); None: do not wait.
    name : str

    Readings: the level read back (hinted; 0 with the lamp off), ``-setpoint`` (the last level
    set here, 0 before any), ``-lamp`` and ``-shutter`` (booleans; both writable:
    ``bps.mv(solar.shutter, True)`` opens the shutter, ``bps.mv(solar.lamp, True)`` is the
    operator's relight). Allowed levels: 0 (lamp out) or 0.8 to 1.2 sun.
    """

    def __init__(self, driver: SolarSimulatorProtocol, *, hold: Hold | None = None,
                 wait_stable_s: float | None = None, name: str = "") -> None:
        self.driver = driver
        self.calls = DriverCalls(hold)
        self.wait_stable_s = wait_stable_s
        #: a level or the lamp switch lit the lamp and nothing here put it out since: a lamp
        #: found out then went out by itself (:meth:`apply_level` does not relight it)
        self.lamp_wanted = False
        with self.add_children_as_readables(Format.HINTED_UNCACHED_SIGNAL):
            self.readback, _ = soft_signal_r_and_setter(
                float, units="sun", precision=3, getter=partial(self.calls, driver.read_suns))
        with self.add_children_as_readables(Format.UNCACHED_SIGNAL):
            self.setpoint = soft_signal_rw(float, units="sun", precision=3)
            self.lamp = soft_signal_rw(bool, getter=partial(self.calls, driver.is_lamp_on),
                                       setter=self._switch_lamp)
            self.shutter = soft_signal_rw(bool, getter=partial(self.calls, driver.shutter_is_open),
                                          setter=self._set_shutter)
        super().__init__(name=name)

    @cached_property
    def movable_logic(self) -> _SolarMove:
        return _SolarMove(setpoint=self.setpoint, readback=self.readback, device=self)

    def check_level(self, suns: float) -> None:
        """Raise :class:`~drivers.errors.LimitError` unless ``suns`` is 0 or in 0.8..1.2."""
        value = float(suns)
        low, high = SUNS_RANGE
        if not (value == 0.0 or (math.isfinite(value) and low <= value <= high)):
            raise LimitError(self.name or "solar", value, low, high, "sun",
                             "the solar simulator's level; 0 puts the lamp out")

    def apply_level(self, suns: float) -> None:
        """Set the level (blocking, in the worker thread): light the lamp where it is out and
        was not lit here, set ``suns`` and check the level read back; 0: put the lamp out."""
        driver = self.driver
        if suns == 0.0:
            self.lamp_wanted = False
            if driver.is_lamp_on():
                driver.lamp_off()
            return
        if not driver.is_lamp_on():
            if self.lamp_wanted:
                raise LampFaultError(
                    f"{self.name or 'solar'}: the solar simulator's lamp went out by itself "
                    f"since it was lit ({driver.status().describe()}); a level of {suns:g} sun "
                    f"does not relight it: relight it (bps.mv({self.name or 'solar'}.lamp, "
                    "True)) once the cause is fixed")
            driver.lamp_on()
        self.lamp_wanted = True
        driver.set_suns(suns)
        if self.wait_stable_s is not None:
            driver.wait_until_stable(self.wait_stable_s)
        read = driver.read_suns()
        if not abs(read - suns) <= SUNS_TOLERANCE:
            raise SolarSimulatorError(
                f"{self.name or 'solar'}: level read back {read:.3f} sun after setting it: "
                f"target {suns:g} sun (tolerance {SUNS_TOLERANCE:g} sun)")

    def _lamp_switch(self, on: bool) -> None:
        self.lamp_wanted = bool(on)
        if on:
            self.driver.lamp_on()
        else:
            self.driver.lamp_off()

    async def _switch_lamp(self, on: bool | None) -> None:
        await self.calls(self._lamp_switch, bool(on))

    async def _set_shutter(self, open_: bool | None) -> None:
        driver = self.driver
        await self.calls(driver.open_shutter if open_ else driver.close_shutter)

