"""Exceptions raised by the device drivers.

Two families:

- *bad input* (an angle outside the software limits, a level in suns outside 0.8-1.2, an RS-485
  address outside 1..31, a malformed calibration table): :class:`DeviceInputError`, a subclass of
  :class:`sim_core.errors.InvalidInputError`, so the service maps it to HTTP 422 like every other
  invalid input. The message names the field, the value received, the allowed range and the unit.
- *the device misbehaved or reported a problem*: :class:`DeviceError` and its subclasses. Every
  message names the device, the command and what came back (or did not), so that a log line is
  enough to diagnose a rig problem.

Nothing in this module imports pyserial; the errors can be caught by code that never opens a port.
"""

from __future__ import annotations

from sim_core.errors import InvalidInputError, ToftwinError

__all__ = [
    "CalibrationError",
    "DeviceDisconnectedError",
    "DeviceError",
    "DeviceInputError",
    "DeviceTimeoutError",
    "GarbledReplyError",
    "InterlockError",
    "LampFaultError",
    "LimitError",
    "ProtocolError",
    "SolarSimulatorError",
    "TurntableError",
]


class DeviceInputError(InvalidInputError):
    """A value given to a driver is outside its allowed range or of the wrong form."""


class LimitError(DeviceInputError):
    """A requested set-point lies outside the range the device allows.

    Attributes
    ----------
    value : float
        The value requested, in ``unit``.
    low, high : float
        The allowed closed range, in ``unit``.
    unit : str
        Unit of the three numbers, e.g. ``"deg"``, ``"suns"``, ``"W"``.
    """

    def __init__(
        self, field: str, value: float, low: float, high: float, unit: str, why: str = ""
    ) -> None:
        self.value = value
        self.low = low
        self.high = high
        self.unit = unit
        detail = f" ({why})" if why else ""
        super().__init__(
            field,
            f"requested {value:g} {unit} is outside the allowed range "
            f"[{low:g}, {high:g}] {unit}{detail}",
        )


class CalibrationError(DeviceInputError):
    """A calibration table (suns -> lamp power) is malformed or not monotonic."""


class DeviceError(ToftwinError):
    """A device did not do what it was asked, or reported a fault.

    Attributes
    ----------
    device, target, read_back : str or None
        Set when the error is a device read back off the state it was asked for
        (:meth:`drivers.rig.Rig.verify`): the device (``"solar simulator lamp"``), the target
        and what was read back, each with its unit (``"1 sun"``, ``"0.000 sun"``).
    """

    device: str | None = None
    target: str | None = None
    read_back: str | None = None


class DeviceTimeoutError(DeviceError, TimeoutError):
    """No complete reply arrived within the timeout (after the allowed retries)."""


class ProtocolError(DeviceError):
    """A reply arrived but does not have the form the protocol prescribes."""


class GarbledReplyError(ProtocolError):
    """A reply contains bytes that cannot be part of the protocol (noise, wrong baud rate)."""


class DeviceDisconnectedError(DeviceError, ConnectionError):
    """The port went away (cable, USB adapter, socket) and could not be reopened in time."""


class TurntableError(DeviceError):
    """The SMC100 controller reported an error or the stage did not reach its target.

    Attributes
    ----------
    te_code : str or None
        The ``TE`` error letter when the error came from ``TE`` (``"C"``, ``"H"``, ...).
    state : str or None
        The two-digit controller state from ``TS`` when known (``"3D"``, ``"0B"``, ...).
    error_bits : int
        The positioner error bits from ``TS`` (0 when none or unknown).
    """

    def __init__(
        self,
        message: str,
        *,
        te_code: str | None = None,
        state: str | None = None,
        error_bits: int = 0,
    ) -> None:
        self.te_code = te_code
        self.state = state
        self.error_bits = error_bits
        super().__init__(message)


class SolarSimulatorError(DeviceError):
    """The lamp supply or the shutter controller reported an error."""


class LampFaultError(SolarSimulatorError):
    """The lamp supply reports a lamp fault (STB bit 3) or the lamp did not ignite."""


class InterlockError(SolarSimulatorError):
    """The lamp supply reports its interlock open (STB bit 0); the lamp cannot run."""
