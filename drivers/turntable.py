"""Turntable: a rotation stage on a Newport SMC100CC (or SMC100PP) controller over RS-232.

Protocol (see ``docs/devices.md``, "Turntable", for every command with its source)
-------------------------------------------------------------------------------
57600 baud, 8N1, XON/XOFF; every command is ``<address><CMD><value>`` terminated by CR LF, the
address being the controller's RS-485 address 1..31. Set commands and motion commands have no
reply; errors are read afterwards with ``TE`` (one letter, ``@`` = no error). Queries are answered
``<address><CMD><value>`` CR LF, e.g. ``1TP`` -> ``1TP45.0000`` or ``1TS`` -> ``1TS000033``
(4 hex digits of positioner error bits, then the 2-digit controller state).

This module holds the protocol tables and the pure encode/parse functions (tested byte for
byte), :class:`TurntableProtocol` - the small interface the rest of the code depends on - and
:class:`Turntable`, the real driver over :class:`drivers.transport.SerialTransport`.

Units: angles in degrees (the stage's native unit), velocities in deg/s, accelerations in
deg/s^2, times in seconds.
"""

from __future__ import annotations

import contextlib
import logging
import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TypeVar, runtime_checkable

import serial

from drivers.errors import (
    DeviceError,
    DeviceInputError,
    LimitError,
    ProtocolError,
    TurntableError,
)
from drivers.transport import SerialSettings, SerialTransport

__all__ = [
    "ADDRESS_RANGE",
    "DISABLE_STATES",
    "HOMING_STATES",
    "MOVING_STATES",
    "NOT_REFERENCED_STATES",
    "POSITIONER_ERROR_BITS",
    "READY_STATES",
    "SMC100_SETTINGS",
    "STATE_NAMES",
    "TE_ERRORS",
    "ControllerStatus",
    "Turntable",
    "TurntableProtocol",
    "describe_positioner_errors",
    "encode_command",
    "format_number",
    "parse_number",
    "parse_reply",
    "parse_te",
    "parse_ts",
    "validate_address",
]

_log = logging.getLogger(__name__)

T = TypeVar("T")

#: RS-485 addresses an SMC100 accepts (``SA`` command range; 1 is the factory default).
ADDRESS_RANGE = (1, 31)

#: Serial settings of the SMC100 RS-232 port (user's manual, "RS-232-C communication").
SMC100_SETTINGS = SerialSettings(
    baudrate=57600,
    bytesize=serial.EIGHTBITS,
    parity=serial.PARITY_NONE,
    stopbits=serial.STOPBITS_ONE,
    xonxoff=True,
    write_terminator=b"\r\n",
    timeout_s=0.5,
    retries=2,
    reconnect_timeout_s=5.0,
)

#: Controller states, the last two characters of the ``TS`` reply.
STATE_NAMES: dict[str, str] = {
    "0A": "NOT REFERENCED from RESET",
    "0B": "NOT REFERENCED from HOMING",
    "0C": "NOT REFERENCED from CONFIGURATION",
    "0D": "NOT REFERENCED from DISABLE",
    "0E": "NOT REFERENCED from READY",
    "0F": "NOT REFERENCED from MOVING",
    "10": "NOT REFERENCED ESP stage error",
    "11": "NOT REFERENCED from JOGGING",
    "14": "CONFIGURATION",
    "1E": "HOMING commanded from RS-232-C",
    "1F": "HOMING commanded by SMC-RC",
    "28": "MOVING",
    "32": "READY from HOMING",
    "33": "READY from MOVING",
    "34": "READY from DISABLE",
    "35": "READY from JOGGING",
    "3C": "DISABLE from READY",
    "3D": "DISABLE from MOVING",
    "3E": "DISABLE from JOGGING",
    "46": "JOGGING from READY",
    "47": "JOGGING from DISABLE",
}
NOT_REFERENCED_STATES = frozenset({"0A", "0B", "0C", "0D", "0E", "0F", "10", "11"})
CONFIGURATION_STATE = "14"
HOMING_STATES = frozenset({"1E", "1F"})
MOVING_STATES = frozenset({"28"})
READY_STATES = frozenset({"32", "33", "34", "35"})
DISABLE_STATES = frozenset({"3C", "3D", "3E"})

#: ``TE`` error letters (``@`` = no error).
TE_ERRORS: dict[str, str] = {
    "@": "no error",
    "A": "unknown message code or floating point controller address",
    "B": "controller address not correct",
    "C": "parameter missing or out of range",
    "D": "command not allowed",
    "E": "home sequence already started",
    "F": "ESP stage name unknown",
    "G": "displacement out of limits",
    "H": "command not allowed in NOT REFERENCED state",
    "I": "command not allowed in CONFIGURATION state",
    "J": "command not allowed in DISABLE state",
    "K": "command not allowed in READY state",
    "L": "command not allowed in HOMING state",
    "M": "command not allowed in MOVING state",
    "N": "current position out of software limit",
    "S": "communication time out",
    "U": "error during EEPROM access",
    "V": "error during command execution",
    "W": "command not allowed for PP version",
    "X": "command not allowed for CC version",
}

#: Positioner error bits, the first four hex digits of the ``TS`` reply (bit number -> meaning).
POSITIONER_ERROR_BITS: dict[int, str] = {
    9: "80 W output power exceeded",
    8: "DC voltage too low",
    7: "wrong ESP stage",
    6: "homing time out",
    5: "following error",
    4: "short circuit detection",
    3: "RMS current limit",
    2: "peak current limit",
    1: "positive end of run",
    0: "negative end of run",
}

_REPLY = re.compile(r"^(\d{1,2})([A-Z]{2})(.*)$")
_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")
_TS_VALUE = re.compile(r"^[0-9A-F]{6}$")


# -- pure protocol functions ---------------------------------------------------------------
def validate_address(address: int) -> int:
    """Return ``address`` if it is an SMC100 RS-485 address, else raise DeviceInputError.

    >>> validate_address(1)
    1
    """
    low, high = ADDRESS_RANGE
    if isinstance(address, bool) or not isinstance(address, int) or not low <= address <= high:
        raise DeviceInputError(
            "address",
            f"got {address!r}; the SMC100 RS-485 address is an integer in {low}..{high}",
        )
    return address


def format_number(value: float) -> str:
    """Format a parameter the way the controller accepts it: plain decimal, up to 6 decimals.

    >>> format_number(45), format_number(-12.5), format_number(0.1234567)
    ('45.0', '-12.5', '0.123457')
    """
    if not math.isfinite(value):
        raise DeviceInputError("value", f"got {value!r}; a finite number is required")
    text = f"{value:.6f}".rstrip("0")
    if text.endswith("."):
        text += "0"
    return "0.0" if text in ("-0.0", "+0.0") else text


def encode_command(address: int, command: str, value: float | str | None = None) -> str:
    """Build one command line (without the CR LF terminator).

    ``value`` may be a number, ``"?"`` for a query of a set/get parameter, or ``None``.

    >>> encode_command(1, "PA", 45.0), encode_command(1, "TS"), encode_command(2, "VA", "?")
    ('1PA45.0', '1TS', '2VA?')
    """
    validate_address(address)
    if not re.fullmatch(r"[A-Z]{2}", command):
        raise DeviceInputError("command", f"got {command!r}; two upper-case letters expected")
    if value is None:
        tail = ""
    elif isinstance(value, str):
        tail = value
    else:
        tail = format_number(float(value))
    return f"{address}{command}{tail}"


def parse_reply(address: int, command: str, line: str) -> str:
    """Check that ``line`` answers ``command`` from ``address``; return the value part.

    >>> parse_reply(1, "TP", "1TP45.0000")
    '45.0000'
    """
    match = _REPLY.match(line.strip())
    if match is None:
        raise ProtocolError(f"reply {line!r} is not of the form <address><command><value>")
    got_address, got_command, value = int(match.group(1)), match.group(2), match.group(3)
    if got_address != address or got_command != command:
        raise ProtocolError(
            f"reply {line!r} answers {got_address}{got_command}, expected {address}{command}"
        )
    return value.strip()


def parse_number(text: str) -> float:
    """Parse a decimal number as the controller prints it (``45.0000``, ``-0.5``, ``1.7e-05``)."""
    if not _NUMBER.match(text):
        raise ProtocolError(f"{text!r} is not a number")
    return float(text)


def parse_ts(value: str) -> tuple[int, str]:
    """Split a ``TS`` value into (positioner error bits, controller state).

    >>> parse_ts("000033")
    (0, '33')
    >>> parse_ts("00200D")
    (32, '0D')
    """
    text = value.strip().upper()
    if not _TS_VALUE.match(text):
        raise ProtocolError(f"TS value {value!r} is not 6 hex digits")
    return int(text[:4], 16), text[4:]


def parse_te(value: str) -> str:
    """Return the ``TE`` error letter (``@`` for none); reject anything else."""
    text = value.strip()
    if len(text) != 1 or not ("A" <= text <= "Z" or text == "@"):
        raise ProtocolError(f"TE value {value!r} is not one letter or '@'")
    return text


def describe_positioner_errors(bits: int) -> list[str]:
    """Names of the positioner error bits set in ``bits`` (highest bit first).

    >>> describe_positioner_errors(0x0021)
    ['following error', 'negative end of run']
    """
    names = [name for bit, name in POSITIONER_ERROR_BITS.items() if bits & (1 << bit)]
    unknown = bits & ~sum(1 << bit for bit in POSITIONER_ERROR_BITS)
    if unknown:
        names.append(f"undocumented bits 0x{unknown:04X}")
    return names


def describe_te(code: str) -> str:
    """Meaning of a ``TE`` letter (``'C'`` -> ``'parameter missing or out of range'``)."""
    return TE_ERRORS.get(code, "undocumented error letter")


@dataclass(frozen=True)
class ControllerStatus:
    """One ``TS`` reading: positioner error bits and controller state."""

    error_bits: int
    state: str

    @property
    def state_name(self) -> str:
        """Human name of the state, e.g. ``'READY from MOVING'``."""
        return STATE_NAMES.get(self.state, "undocumented state")

    @property
    def errors(self) -> list[str]:
        """Names of the positioner error bits that are set."""
        return describe_positioner_errors(self.error_bits)

    @property
    def is_ready(self) -> bool:
        return self.state in READY_STATES

    @property
    def is_referenced(self) -> bool:
        return self.state not in NOT_REFERENCED_STATES and self.state != CONFIGURATION_STATE

    def describe(self) -> str:
        """``'3D DISABLE from MOVING, positioner errors: following error'``."""
        text = f"{self.state} {self.state_name}"
        if self.error_bits:
            text += f", positioner errors 0x{self.error_bits:04X}: " + ", ".join(self.errors)
        return text


# -- the interface the rest of the code depends on ------------------------------------------
@runtime_checkable
class TurntableProtocol(Protocol):
    """What the service and the pose loop need from a turntable.

    ``move_to`` returns only after the stage is at rest, the controller is READY and the
    position read back agrees with the target within the tolerance; otherwise it raises. A
    returned angle is therefore always a verified one.
    """

    @property
    def limits_deg(self) -> tuple[float, float]:
        """Allowed target range (low, high) in degrees."""
        ...

    def home(self) -> None:
        """Reference the stage if it is not referenced; return when READY."""
        ...

    def move_to(self, angle_deg: float) -> float:
        """Move to ``angle_deg``, wait, verify, settle; return the verified angle in degrees."""
        ...

    def position_deg(self) -> float:
        """Current position in degrees (as reported by the controller)."""
        ...

    def stop(self) -> None:
        """Stop any motion now."""
        ...

    def enable(self) -> None:
        """Leave the disabled state (after a stall or a following error); return when READY."""
        ...

    def reset(self, timeout_s: float = 15.0) -> None:
        """Reboot the controller; return when it answers again (not referenced)."""
        ...

    def close(self) -> None:
        """Release the port."""
        ...


# -- the real driver ------------------------------------------------------------------------
class Turntable:
    """SMC100 rotation stage over pyserial.

    Parameters
    ----------
    port : str
        Serial device path or pyserial URL (``socket://host:port`` for a simulator).
    address : int
        Controller RS-485 address, 1..31.
    tolerance_deg : float
        Largest accepted difference between the target and the position read back (``TP``).
    settle_s : float
        Wait after the controller reports READY before the final position check (mechanics and
        cable wrap come to rest).
    move_timeout_s, home_timeout_s : float
        Longest wait for a move / a homing to reach READY; on expiry ``ST`` is sent and
        :class:`TurntableError` raised.
    stall_timeout_s : float or None
        While MOVING, a position that changes by less than ``1e-6`` deg for this long is a stall:
        ``ST`` is sent and :class:`TurntableError` raised. ``None`` disables the check.
    poll_interval_s : float
        Period of the ``TS`` polling while waiting.
    limits_deg : (float, float) or None
        Extra limits on top of the controller's software limits (``SL``/``SR``, read at
        :meth:`connect`); the allowed range is their intersection.
    settings : SerialSettings
        Port settings; the default is the SMC100's 57600 8N1 XON/XOFF, CR LF.
    sleep : callable
        How the post-move wait (``settle_s``) is spent: :func:`time.sleep` on a real rig; the
        simulated lab passes its clock's (an instant clock's table has settled at once).

    Examples
    --------
    Against the simulator (``python -m drivers.sim.pty_server turntable`` prints the port)::

        with Turntable("/tmp/toftwin-sim-xyz/turntable") as tt:
            tt.move_to(30.0)   # homes first when the controller is NOT REFERENCED
    """

    def __init__(
        self,
        port: str,
        *,
        address: int = 1,
        tolerance_deg: float = 0.01,
        settle_s: float = 0.2,
        move_timeout_s: float = 60.0,
        home_timeout_s: float = 120.0,
        stall_timeout_s: float | None = 2.0,
        poll_interval_s: float = 0.05,
        limits_deg: tuple[float, float] | None = None,
        settings: SerialSettings = SMC100_SETTINGS,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.address = validate_address(address)
        self.sleep = sleep
        for field, value in (
            ("tolerance_deg", tolerance_deg),
            ("move_timeout_s", move_timeout_s),
            ("home_timeout_s", home_timeout_s),
            ("poll_interval_s", poll_interval_s),
        ):
            if not (math.isfinite(value) and value > 0):
                raise DeviceInputError(field, f"got {value!r}; a finite number > 0 is required")
        if not (math.isfinite(settle_s) and settle_s >= 0):
            raise DeviceInputError(
                "settle_s", f"got {settle_s!r}; a finite number >= 0 is required"
            )
        if limits_deg is not None:
            low, high = (float(v) for v in limits_deg)
            if not (math.isfinite(low) and math.isfinite(high) and low < high):
                raise DeviceInputError(
                    "limits_deg", f"got {limits_deg!r}; (low, high) with low < high expected"
                )
        self.tolerance_deg = tolerance_deg
        self.settle_s = settle_s
        self.move_timeout_s = move_timeout_s
        self.home_timeout_s = home_timeout_s
        self.stall_timeout_s = stall_timeout_s
        self.poll_interval_s = poll_interval_s
        self._user_limits = limits_deg
        self._limits: tuple[float, float] = limits_deg if limits_deg else (-math.inf, math.inf)
        self.stage_name: str | None = None
        self.last_status: ControllerStatus | None = None
        self.transport = SerialTransport(port, settings, name=f"SMC100 turntable #{address}")

    # -- connection ---------------------------------------------------------------------------
    def connect(self) -> None:
        """Open the port, clear a stale error, read the stage name and the software limits."""
        self.transport.open()
        self._query("TE", parse_te)  # reading TE clears an error left by an earlier session
        self.last_status = self.status()  # TS also clears latched positioner errors
        if self.last_status.error_bits:
            _log.warning("%s: at connect: %s", self.transport.name, self.last_status.describe())
        self.stage_name = self._query("ID", str, "?")
        low = self._query("SL", parse_number, "?")
        high = self._query("SR", parse_number, "?")
        if self._user_limits is not None:
            low, high = max(low, self._user_limits[0]), min(high, self._user_limits[1])
        self._limits = (low, high)

    def close(self) -> None:
        """Close the port (the stage keeps its state)."""
        self.transport.close()

    def __enter__(self) -> Turntable:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def limits_deg(self) -> tuple[float, float]:
        """Allowed target range in degrees (controller SL/SR intersected with user limits)."""
        return self._limits

    # -- low level ----------------------------------------------------------------------------
    def _query(self, command: str, parse: Callable[[str], T], tail: str | None = None) -> T:
        """Send a query and parse the value of its reply (address and command are checked)."""
        line = encode_command(self.address, command, tail)

        def parse_line(reply: str) -> T:
            return parse(parse_reply(self.address, command, reply))

        return self.transport.query(line, parse_line)

    def _command(self, command: str, value: float | str | None = None) -> str:
        """Send a command without reply, then read ``TE``; raise if the controller refused it."""
        line = encode_command(self.address, command, value)
        self.transport.send(line, idempotent=command != "PR")
        code = self._query("TE", parse_te)
        if code != "@":
            raise TurntableError(
                f"TE reply {code!r} after {line!r}: {describe_te(code)}{self._state_hint()}",
                te_code=code,
            )
        return line

    def _state_hint(self) -> str:
        try:
            return f" (controller state {self.status().describe()})"
        except DeviceError:  # the hint is best effort; the TE error is what matters
            return ""

    # -- queries ------------------------------------------------------------------------------
    def status(self) -> ControllerStatus:
        """Read ``TS``: positioner error bits and controller state."""
        bits, state = self._query("TS", parse_ts)
        return ControllerStatus(bits, state)

    def position_deg(self) -> float:
        """Current position (``TP``) in degrees."""
        value = self._query("TP", parse_number)
        if not math.isfinite(value):
            raise ProtocolError(f"TP reply {value!r} is not finite")
        return value

    def setpoint_deg(self) -> float:
        """Current set-point (``TH``), the target of the running or last move, in degrees."""
        return self._query("TH", parse_number)

    def last_error(self) -> str:
        """Read and clear the last command error letter (``TE``); ``'@'`` means none."""
        return self._query("TE", parse_te)

    def velocity_deg_s(self) -> float:
        """Programmed velocity (``VA?``) in deg/s."""
        return self._query("VA", parse_number, "?")

    def acceleration_deg_s2(self) -> float:
        """Programmed acceleration (``AC?``) in deg/s^2."""
        return self._query("AC", parse_number, "?")

    # -- settings -----------------------------------------------------------------------------
    def set_velocity(self, velocity_deg_s: float) -> None:
        """Set the move velocity (``VA``) in deg/s; the controller rejects values above its max."""
        if not (math.isfinite(velocity_deg_s) and velocity_deg_s > 0):
            raise DeviceInputError(
                "velocity_deg_s", f"got {velocity_deg_s!r} deg/s; a finite value > 0 is required"
            )
        self._command("VA", velocity_deg_s)

    def set_acceleration(self, acceleration_deg_s2: float) -> None:
        """Set the acceleration (``AC``) in deg/s^2."""
        if not (math.isfinite(acceleration_deg_s2) and acceleration_deg_s2 > 0):
            raise DeviceInputError(
                "acceleration_deg_s2",
                f"got {acceleration_deg_s2!r} deg/s^2; a finite value > 0 is required",
            )
        self._command("AC", acceleration_deg_s2)

    # -- motion -------------------------------------------------------------------------------
    def stop(self) -> None:
        """Send ``ST`` (stop motion; aborts a homing too), then clear ``TE``.

        ``ST`` in NOT REFERENCED or CONFIGURATION is refused by the controller (``H``/``I``);
        reading ``TE`` here keeps that refusal from being reported against the next command.
        """
        self.transport.send(encode_command(self.address, "ST"))
        with contextlib.suppress(DeviceError):
            self._query("TE", parse_te)

    def enable(self) -> None:
        """Leave DISABLE (``MM1``), e.g. after a following error; wait for READY.

        A controller that is not disabled is left as it is (``MM1`` is refused outside
        DISABLE and READY), so enabling is safe to ask for in any state.
        """
        if self.status().state not in DISABLE_STATES:
            return
        self._command("MM", 1)
        self._wait_ready("enable", self.move_timeout_s)

    def reset(self, timeout_s: float = 15.0) -> None:
        """Reboot the controller (``RS``) and wait until it answers NOT REFERENCED again."""
        self.transport.send(encode_command(self.address, "RS"))
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                if self.status().state in NOT_REFERENCED_STATES:
                    self._query("TE", parse_te)
                    return
            except (ProtocolError, TimeoutError):
                pass  # the controller does not answer while it reboots
            if time.monotonic() > deadline:
                raise TurntableError(f"controller did not come back within {timeout_s:g} s of RS")
            time.sleep(self.poll_interval_s)

    def home(self) -> None:
        """Reference the stage (``OR``) unless it already is; return when READY."""
        status = self.status()
        if status.state in MOVING_STATES | HOMING_STATES:
            what = "homing" if status.state in HOMING_STATES else "move"
            status = self._wait_ready(what, self.home_timeout_s)
        if status.is_ready:
            return
        if status.state in DISABLE_STATES:
            raise TurntableError(
                f"cannot home: controller is {status.describe()}; call enable() (MM1) first",
                state=status.state,
                error_bits=status.error_bits,
            )
        if status.state == CONFIGURATION_STATE:
            raise TurntableError(
                "cannot home: controller is in CONFIGURATION; leave it with PW0 first",
                state=status.state,
            )
        self._command("OR")
        self._wait_ready("homing", self.home_timeout_s)

    def move_to(self, angle_deg: float) -> float:
        """Move to ``angle_deg``; return the verified position in degrees.

        Homes first when the controller is NOT REFERENCED. Raises :class:`LimitError` for a
        target outside :attr:`limits_deg` (nothing is sent), :class:`TurntableError` when the
        controller refuses the move, reports an error or disable state, stalls, times out, or
        when the position read back differs from the target by more than ``tolerance_deg``.
        """
        angle = self._checked_target(angle_deg)
        status = self.status()
        if status.state in MOVING_STATES | HOMING_STATES:
            status = self._wait_ready("previous motion", self.move_timeout_s)
        if not status.is_referenced and status.state not in DISABLE_STATES:
            self.home()
        elif status.state in DISABLE_STATES:
            raise TurntableError(
                f"cannot move: controller is {status.describe()}; call enable() (MM1) first",
                state=status.state,
                error_bits=status.error_bits,
            )
        self._command("PA", angle)
        self._wait_ready(f"move to {angle:g} deg", self.move_timeout_s, target=angle)
        self._verify(angle)
        if self.settle_s > 0:
            self.sleep(self.settle_s)
        return self._verify(angle)

    def _checked_target(self, angle_deg: float) -> float:
        """``angle_deg`` as a float, or :class:`DeviceInputError` (not finite) or
        :class:`LimitError` (outside :attr:`limits_deg`) before anything is sent."""
        angle = float(angle_deg)
        low, high = self._limits
        if not math.isfinite(angle):
            raise DeviceInputError("angle_deg", f"got {angle_deg!r}; a finite angle is required")
        if not low <= angle <= high:
            raise LimitError(
                "angle_deg", angle, low, high, "deg", "turntable software limits SL/SR"
            )
        return angle

    def start_move(self, angle_deg: float) -> None:
        """Send the move to ``angle_deg`` (``PA``) and return at once, the stage moving: for a
        capture while turning. The caller waits for READY (:meth:`move_to` to the same angle
        does) and stops the stage on any failure (:meth:`stop`). Same checks as
        :meth:`move_to` (limits, a finite angle); the stage must be READY (referenced)."""
        angle = self._checked_target(angle_deg)
        status = self.status()
        if not status.is_ready:
            raise TurntableError(f"cannot start a move: controller is {status.describe()}; "
                                 "move_to() the start first", state=status.state)
        self._command("PA", angle)

    # -- waiting and verification -----------------------------------------------------------
    def _verify(self, target: float, reads: int = 3) -> float:
        """Read ``TP`` until it agrees with ``target``; raise after ``reads`` disagreeing reads."""
        position = math.nan
        for _ in range(reads):
            position = self.position_deg()
            if abs(position - target) <= self.tolerance_deg:
                return position
        raise TurntableError(
            f"turntable position verification failed: target {target:g} deg, controller reports "
            f"{position:g} deg (tolerance {self.tolerance_deg:g} deg, {reads} reads)"
        )

    def _wait_ready(
        self, what: str, timeout_s: float, target: float | None = None
    ) -> ControllerStatus:
        """Poll ``TS`` until READY; raise on errors, DISABLE, NOT REFERENCED, stall, timeout."""
        start = time.monotonic()
        last_move_t = start
        last_position: float | None = None
        while True:
            status = self.status()
            if status.error_bits:
                self._fail(what, status, "positioner error")
            if status.is_ready:
                return status
            if status.state not in MOVING_STATES | HOMING_STATES:
                self._fail(what, status, "unexpected state")
            now = time.monotonic()
            if self.stall_timeout_s is not None and status.state in MOVING_STATES:
                position = self.position_deg()
                if last_position is None or abs(position - last_position) > 1e-6:
                    last_position, last_move_t = position, now
                elif now - last_move_t > self.stall_timeout_s:
                    self.stop()
                    raise TurntableError(
                        f"{what}: stage stalled at {position:g} deg (no progress for "
                        f"{self.stall_timeout_s:g} s while MOVING); stop (ST) sent",
                        state=status.state,
                    )
            if now - start > timeout_s:
                self.stop()
                position = self._position_or_nan()
                raise TurntableError(
                    f"{what}: not READY within {timeout_s:g} s (last state "
                    f"{status.describe()}, position {position:g} deg"
                    f"{'' if target is None else f', target {target:g} deg'}); stop (ST) sent",
                    state=status.state,
                )
            time.sleep(self.poll_interval_s)

    def _position_or_nan(self) -> float:
        try:
            return self.position_deg()
        except DeviceError:  # only used to enrich an error message
            return math.nan

    def _fail(self, what: str, status: ControllerStatus, why: str) -> None:
        position = self._position_or_nan()
        raise TurntableError(
            f"{what}: {why}: controller is {status.describe()} at {position:g} deg",
            state=status.state,
            error_bits=status.error_bits,
        )
