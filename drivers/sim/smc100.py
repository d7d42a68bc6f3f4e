"""Simulated Newport SMC100CC controller driving a rotation stage, at the level of ASCII lines.

:meth:`Smc100Sim.handle_line` takes one received command line (terminator already removed) and
returns the reply lines (without terminator); the server in :mod:`drivers.sim.pty_server` adds
framing, CR LF and the link-level faults. The model:

- States and transitions of the controller (``TS``): NOT REFERENCED (0A..11) after power-up or
  reset, CONFIGURATION (14, ``PW1``/``PW0``), HOMING (1E, ``OR``), MOVING (28, ``PA``/``PR``),
  READY (32 from homing, 33 from moving, 34 from disable), DISABLE (3C/3D, ``MM0``/``MM1``).
- Moves follow a trapezoidal velocity profile (``VA``, ``AC``) in simulated time; homing runs to
  the home position at the home search velocity ``OH``; ``ST`` decelerates at ``AC``.
- A ``PA``/``PR`` received while MOVING re-targets the running move (the manual lists no
  "not allowed in MOVING" error for them); ``ST`` decelerates at ``AC``.
- Software limits ``SL``/``SR``: a target outside them is refused with ``G``.
- Each command is accepted only in the states the manual's "Usage" table and error list allow;
  a refused command sets the ``TE`` letter: unknown command ``A``, bad address ``B``, bad or
  missing parameter ``C``, home already started ``E``, target out of limits ``G``, wrong state
  ``H``/``I``/``J``/``K``/``L``/``M``. ``TE`` (and ``TB``) return the letter and clear it; ``TS``
  returns the positioner error bits and clears them (manual, TS notes).
- Syntax per the manual's section 5.3: upper or lower case, blanks ignored anywhere (``2P A1.43
  6`` = ``2PA1.436``), characters after the command's value ignored, so ``1TS?`` = ``1TS``.
  Commands for another address 1..31 are ignored (another controller on the RS-485 bus would
  answer); ``ST`` and ``MM`` without address apply to every controller.
- While rebooting (``RS``, < 5 s) or saving the configuration (``PW0``, up to 10 s) the
  controller does not answer.
- The table rings after every move that ends (``settling``, a reality's ``turntable.settling``;
  :mod:`sim_core.settling`): its physical angle (:meth:`Smc100Sim.table_angle_deg`, what the
  simulated camera sees) oscillates about the target, in the direction it moved, while the
  controller reports the target and READY. The SMC100CC closes its loop on the encoder of the DC
  motor; the ringing is the table and its load swinging on the compliance of the drive train
  (worm gear, coupling) behind the motor, which the motor's encoder does not see. So ``TP``, the
  ``TS`` state and the following error know nothing of it, as on the real stage: only the images
  show it, and the service must wait for it to decay (issue 27). With an instant clock it has
  decayed at once, as every timed process has.

Where the manual's exact behaviour is not known to us, the choice made here is stated in
``docs/devices.md`` ("Simulator choices").
"""

from __future__ import annotations

import math
import re
import threading
from dataclasses import dataclass, field

import numpy as np

from drivers.sim import SimClock
from drivers.sim.faults import FaultInjector
from drivers.turntable import (
    ADDRESS_RANGE,
    CONFIGURATION_STATE,
    DISABLE_STATES,
    HOMING_STATES,
    MOVING_STATES,
    NOT_REFERENCED_STATES,
    READY_STATES,
    TE_ERRORS,
)
from sim_core.settling import envelope_deg, ringing_of_moves_deg
from sim_core.twin_file import TurntableSettling

__all__ = ["FOLLOWING_ERROR_BIT", "Smc100Config", "Smc100Sim"]

FOLLOWING_ERROR_BIT = 1 << 5

_LINE = re.compile(r"^(?P<address>\d+(?:\.\d*)?)?(?P<command>[A-Za-z]{2})(?P<value>.*)$")
_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?")


@dataclass
class Smc100Config:
    """Physical and firmware parameters of the simulated controller and stage.

    Defaults describe a URS100CC rotation stage (DC servo, 20 deg/s max; the stage of the manual's
    ``ID`` example) on an SMC100CC, with software limits of +-170 deg to protect the cables of
    the turntable.
    """

    address: int = 1
    stage_name: str = "URS100CC"
    firmware: str = "SMC_CC - Controller-driver version 3.0.1 (toftwin sim)"
    velocity_deg_s: float = 20.0
    max_velocity_deg_s: float = 20.0
    acceleration_deg_s2: float = 80.0
    max_acceleration_deg_s2: float = 320.0
    home_velocity_deg_s: float = 10.0
    home_position_deg: float = 0.0
    initial_position_deg: float = 12.5
    limits_deg: tuple[float, float] = (-170.0, 170.0)
    reset_time_s: float = 2.0
    config_save_time_s: float = 1.0
    following_error_time_s: float = 0.1
    smartstage_config: int = 2
    #: the table's ringing after a move (None: it stops dead); see the module docstring
    settling: TurntableSettling | None = None


@dataclass(frozen=True)
class _Segment:
    """Constant-acceleration piece of a motion profile, in nominal seconds from its start."""

    t0: float
    duration: float
    p0: float
    v0: float
    a: float

    def position(self, t: float) -> float:
        tau = min(max(t - self.t0, 0.0), self.duration)
        return self.p0 + self.v0 * tau + 0.5 * self.a * tau * tau

    def velocity(self, t: float) -> float:
        tau = min(max(t - self.t0, 0.0), self.duration)
        return self.v0 + self.a * tau


def trapezoid(p0: float, p1: float, v_max: float, a_max: float) -> list[_Segment]:
    """Segments of a rest-to-rest move from ``p0`` to ``p1`` (trapezoid, or triangle if short)."""
    return profile(p0, 0.0, p1, v_max, a_max)


def profile(p0: float, v0: float, p1: float, v_max: float, a_max: float) -> list[_Segment]:
    """Segments taking the stage from ``(p0, v0)`` to rest at ``p1`` with speed <= ``v_max``.

    If the stage moves away from ``p1``, or too fast to stop before it, it first decelerates to
    rest; then it accelerates, cruises at ``v_max`` (if the distance allows) and decelerates.
    """
    segments: list[_Segment] = []
    t = 0.0
    d = p1 - p0
    if v0 != 0.0 and (
        math.copysign(1.0, v0) != math.copysign(1.0, d) or abs(d) < v0 * v0 / (2 * a_max)
    ):
        tau = abs(v0) / a_max
        brake = _Segment(0.0, tau, p0, v0, -math.copysign(a_max, v0))
        segments.append(brake)
        t, p0, v0 = tau, brake.position(tau), 0.0
        d = p1 - p0
    if d == 0.0:
        return segments or [_Segment(0.0, 0.0, p0, 0.0, 0.0)]
    sign = math.copysign(1.0, d)
    distance, u = abs(d), abs(v0)
    v_top = max(v_max, u)
    needed = (v_top * v_top - u * u) / (2 * a_max) + v_top * v_top / (2 * a_max)
    if needed <= distance:
        v_peak, t_flat = v_top, (distance - needed) / v_top
    else:  # triangle: the peak speed is reached only for an instant
        v_peak, t_flat = math.sqrt((2 * a_max * distance + u * u) / 2), 0.0
    t_acc = (v_peak - u) / a_max
    acc = _Segment(t, t_acc, p0, sign * u, sign * a_max)
    flat = _Segment(t + t_acc, t_flat, acc.position(t + t_acc), sign * v_peak, 0.0)
    t_dec = t + t_acc + t_flat
    dec = _Segment(t_dec, v_peak / a_max, flat.position(t_dec), sign * v_peak, -sign * a_max)
    return [*segments, acc, flat, dec]


@dataclass
class _Motion:
    kind: str  # "move", "home" or "stop"
    segments: list[_Segment]
    t_start: float  # simulated time it began
    target: float
    end_state: str
    stall_after: float | None = None  # nominal seconds after start at which it stalls
    stall_hang: bool = False
    duration: float = field(init=False)

    def __post_init__(self) -> None:
        last = self.segments[-1]
        self.duration = last.t0 + last.duration

    def elapsed(self, clock: SimClock, now: float) -> float:
        """Nominal seconds of the profile executed by ``now``."""
        if clock.instant:
            return self.duration
        return (now - self.t_start) if now >= self.t_start else 0.0

    def effective(self, e: float) -> float:
        return e if self.stall_after is None else min(e, self.stall_after)

    def position(self, e: float) -> float:
        e = self.effective(e)
        for seg in self.segments:
            if e <= seg.t0 + seg.duration:
                return seg.position(e)
        return self.segments[-1].position(e)

    def velocity(self, e: float) -> float:
        if self.stall_after is not None and e >= self.stall_after:
            return 0.0
        for seg in self.segments:
            if e <= seg.t0 + seg.duration:
                return seg.velocity(e)
        return 0.0


class _RefusedError(Exception):
    """A command the controller does not execute; carries the TE letter."""

    def __init__(self, letter: str) -> None:
        super().__init__(letter)
        self.letter = letter


# States grouped the way the manual's "Usage" tables are (Motion = HOMING and MOVING).
_READY_DISABLE = READY_STATES | DISABLE_STATES
_WORKING = READY_STATES | DISABLE_STATES | frozenset({CONFIGURATION_STATE})

#: Commands of the stepper version only; an SMC100CC answers them with TE letter X.
_PP_ONLY = frozenset({"FR", "VB"})

#: Configuration-only parameters: initial value, and whether they are sent as integers.
_CONFIG_PARAMETERS: dict[str, tuple[float, bool]] = {
    "BA": (0.0, False),
    "BH": (0.0, False),
    "FE": (0.05, False),
    "HT": (0.0, True),
    "JR": (0.05, False),
    "KD": (0.0, False),
    "KI": (0.0, False),
    "KP": (0.0, False),
    "KV": (0.0, False),
    "OT": (100.0, False),
    "SC": (1.0, True),
    "SU": (0.0005, False),
}


class Smc100Sim:
    """The simulated controller.

    Parameters
    ----------
    config : Smc100Config
        Stage and firmware parameters.
    clock : SimClock
        Simulated time (``SimClock(instant=True)`` for tests that must not wait).
    faults : FaultInjector
        Armed faults; this class consumes ``stall`` and ``stall-hang`` (one event per move) and
        ``drift`` (one event per command received at rest).
    """

    reply_terminator = b"\r\n"

    def __init__(
        self,
        config: Smc100Config | None = None,
        *,
        clock: SimClock | None = None,
        faults: FaultInjector | None = None,
    ) -> None:
        self.config = config or Smc100Config()
        self.clock = clock or SimClock()
        self.faults = faults or FaultInjector()
        cfg = self.config
        low, high = ADDRESS_RANGE
        if not low <= cfg.address <= high:
            raise ValueError(f"address must be in {low}..{high}, got {cfg.address}")
        self._lock = threading.RLock()
        self.address = cfg.address
        self.state = "0A"
        self.error_bits = 0
        self.error = "@"
        self.position = cfg.initial_position_deg
        self.setpoint = cfg.initial_position_deg
        self.max_velocity = cfg.max_velocity_deg_s
        self.max_acceleration = cfg.max_acceleration_deg_s2
        self.velocity = cfg.velocity_deg_s
        self.acceleration = cfg.acceleration_deg_s2
        self.home_velocity = cfg.home_velocity_deg_s
        self.limits = list(cfg.limits_deg)
        self.stage_name = cfg.stage_name
        self.smartstage = cfg.smartstage_config
        self.parameters = {name: value for name, (value, _) in _CONFIG_PARAMETERS.items()}
        self.motion: _Motion | None = None
        self.settling = cfg.settling
        #: moves that ended and may still ring: (simulated end time [s], direction +-1)
        self._rings: list[tuple[float, float]] = []
        self._busy_until: float | None = None  # rebooting or saving: no replies
        self._state_after_busy = "0A"
        self.commands_seen = 0

    # -- public helpers for tests and the rig ----------------------------------------------
    def current_position(self) -> float:
        """The motor's position now, in degrees (what ``TP`` answers): the encoder sits on the
        motor, so the table's ringing is not in it (:meth:`table_angle_deg` has it)."""
        with self._lock:
            self._advance()
            return self.position

    def current_state(self) -> str:
        """Controller state now (what ``TS`` would answer in its last two characters)."""
        with self._lock:
            self._advance()
            return self.state

    def table_angle_deg(self, at_s: float | None = None) -> float:
        """The table's physical angle [deg] at simulated time ``at_s`` (now when None): the
        motor's position (what ``TP`` answers) plus the ringing of the moves that ended.

        A time after now is where the table will be if no command arrives before it (the
        running profile and the ringing are known in advance): the simulated camera asks it for
        the sub-frames of a frame it starts now.
        """
        with self._lock:
            self._advance()
            t_s = self.clock.now() if at_s is None else float(at_s)
            motor_deg, rings = self.position, list(self._rings)
            motion = self.motion
            if motion is not None:
                e = motion.elapsed(self.clock, t_s)
                motor_deg = motion.position(e)
                if (motion.stall_after is None and e >= motion.duration
                        and not self.clock.instant):
                    rings.append(self._ring_of(motion))
            settling = self.settling
            if settling is None or not rings:
                return motor_deg
            return motor_deg + ringing_of_moves_deg(
                settling, t_s, np.array([r[0] for r in rings]), np.array([r[1] for r in rings]))

    # -- time evolution ----------------------------------------------------------------------
    def _ring_of(self, motion: _Motion) -> tuple[float, float]:
        """When ``motion`` ends (simulated time) and the direction the table then swings."""
        v_before_stop = motion.segments[-1].v0
        sign = 0.0 if v_before_stop == 0.0 else math.copysign(1.0, v_before_stop)
        return motion.t_start + self.clock.duration(motion.duration), sign

    def _ended(self, motion: _Motion, now: float) -> None:
        """Record ``motion``'s ringing; forget rings decayed below 1e-12 deg (they add nothing
        a float can hold next to an angle of order 1)."""
        if self.settling is None or self.clock.instant:
            return  # no ringing, or an instant clock: it has decayed at once
        self._rings.append(self._ring_of(motion))
        self._rings = [r for r in self._rings
                       if float(envelope_deg(self.settling, now - r[0])) >= 1e-12]

    def _advance(self) -> None:
        now = self.clock.now()
        if self._busy_until is not None and now >= self._busy_until:
            self._busy_until = None
            self.state = self._state_after_busy
        motion = self.motion
        if motion is None:
            return
        e = motion.elapsed(self.clock, now)
        self.position = motion.position(e)
        if motion.stall_after is not None and e >= motion.stall_after:
            if motion.stall_hang:
                return  # frozen, still MOVING: only ST gets it out
            fe_delay = self.clock.duration(self.config.following_error_time_s)
            if self.clock.instant or now - motion.t_start >= motion.stall_after + fe_delay:
                self.error_bits |= FOLLOWING_ERROR_BIT
                self.state = "3D"
                self.setpoint = self.position
                self.motion = None
            return
        if e >= motion.duration:
            self.position = motion.target
            self.state = motion.end_state
            self.motion = None
            self._ended(motion, now)

    def _drift(self) -> None:
        """Fault ``drift``: a stage at rest in READY creeps ``offset_deg`` off its position.

        The controller's encoder sees it (``TP`` reads the new position) but it stays READY and
        does not pull the stage back (sim choice: a servo that lost its holding torque); the
        set-point is unchanged, so the next ``PA`` moves from where the stage really is.
        """
        if self.motion is not None or self.state not in READY_STATES:
            return
        spec = self.faults.fire("drift")
        if spec is not None:
            self.position += float(spec.params.get("offset_deg", 0.5))

    # -- line handling -----------------------------------------------------------------------
    def handle_line(self, line: str) -> list[str]:
        """Execute one command line; return the reply lines (possibly none)."""
        with self._lock:
            self._advance()
            self.commands_seen += 1
            self._drift()
            if self._busy_until is not None:
                return []  # rebooting / saving to flash: deaf
            text = "".join(line.split())  # blanks are ignored anywhere (manual 5.3)
            if not text:
                return []
            match = _LINE.match(text)
            if match is None:
                self.error = "A"
                return []
            command = match.group("command").upper()
            address_text = match.group("address")
            if address_text is None:
                if command not in ("ST", "MM"):
                    self.error = "B"
                    return []
                address = 0  # all controllers
            elif not address_text.isdigit():
                self.error = "A"  # floating point controller address
                return []
            else:
                address = int(address_text)
                low, high = ADDRESS_RANGE
                if not low <= address <= high and not (address == 0 and command in ("ST", "MM")):
                    self.error = "B"
                    return []
            if address not in (0, self.address):
                return []  # for another controller on the RS-485 bus
            value = match.group("value")
            if command in _PP_ONLY:
                self.error = "X"  # command not allowed for CC version
                return []
            handler = getattr(self, f"_cmd_{command.lower()}", None)
            if handler is None and command in _CONFIG_PARAMETERS:
                handler = lambda v, c=command: self._config_parameter(c, v)  # noqa: E731
            if handler is None:
                self.error = "A"
                return []
            try:
                reply = handler(value)
            except _RefusedError as refused:
                self.error = refused.letter
                return []
            if reply is None or address == 0:
                return []
            if isinstance(reply, list):
                return reply
            return [f"{self.address}{command}{reply}"]

    # -- helpers -----------------------------------------------------------------------------
    @staticmethod
    def _fmt(value: float) -> str:
        """Numbers as the controller prints them in replies: up to 6 significant digits."""
        return f"{(value + 0.0):.6g}"

    @staticmethod
    def _number(value: str) -> float:
        match = _NUMBER.match(value)
        if not match:
            raise _RefusedError("C")
        number = float(match.group(0))
        if not math.isfinite(number):
            raise _RefusedError("C")
        return number

    def _state_letter(self) -> str:
        """The TE letter for 'command not allowed in the current state'."""
        state = self.state
        if state in NOT_REFERENCED_STATES:
            return "H"
        if state == CONFIGURATION_STATE:
            return "I"
        if state in DISABLE_STATES:
            return "J"
        if state in READY_STATES:
            return "K"
        if state in HOMING_STATES:
            return "L"
        if state in MOVING_STATES:
            return "M"
        return "D"

    def _require(self, states: frozenset[str]) -> None:
        if self.state not in states:
            raise _RefusedError(self._state_letter())

    def _setting(
        self, value: str, current: float, low: float, high: float, states: frozenset[str]
    ) -> float | str:
        """Set/get parameter: ``?`` returns the value; else validate (state, range), return it."""
        if value.startswith("?"):
            return self._fmt(current)
        self._require(states)
        number = self._number(value)
        if not low <= number <= high:
            raise _RefusedError("C")
        return number

    def _config_parameter(self, name: str, value: str) -> str | None:
        """Parameters that can only be changed in CONFIGURATION (gains, HT, SU, ...)."""
        current = self.parameters[name]
        as_int = _CONFIG_PARAMETERS[name][1]
        if value.startswith("?"):
            return str(int(current)) if as_int else self._fmt(current)
        self._require(frozenset({CONFIGURATION_STATE}))
        number = self._number(value)
        if number < 0 or (as_int and number != int(number)):
            raise _RefusedError("C")
        self.parameters[name] = number
        return None

    def _target(self, value: str, relative: bool) -> float:
        if value == "":
            raise _RefusedError("C")
        number = self._number(value)
        if self.state in HOMING_STATES:
            raise _RefusedError("D")
        self._require(READY_STATES | MOVING_STATES)
        target = self.setpoint + number if relative else number
        low, high = self.limits
        if not low <= target <= high:
            raise _RefusedError("G")
        return target

    def _start_motion(self, kind: str, target: float, velocity: float, end_state: str) -> None:
        now = self.clock.now()
        v0 = 0.0
        if self.motion is not None:
            v0 = self.motion.velocity(self.motion.elapsed(self.clock, now))
        motion = _Motion(
            kind,
            profile(self.position, v0, target, velocity, self.acceleration),
            now,
            target,
            end_state,
        )
        if kind == "move":
            hang = self.faults.fire("stall-hang")
            spec = hang or self.faults.fire("stall")
            if spec is not None:
                fraction = float(spec.params.get("at_fraction", 0.5))
                motion.stall_after = fraction * motion.duration
                motion.stall_hang = hang is not None
        self.setpoint = target
        self.motion = motion
        self.state = "1E" if kind == "home" else "28"
        self._advance()

    def _go_busy(self, seconds: float, then: str) -> None:
        self._busy_until = self.clock.now() + self.clock.duration(seconds)
        self._state_after_busy = then
        self._advance()

    # -- commands (alphabetical; each returns the reply value, a list of lines, or None) --
    def _cmd_ac(self, value: str) -> str | None:
        result = self._setting(value, self.acceleration, 1e-6, self.max_acceleration, _WORKING)
        if isinstance(result, str):
            return result
        if self.state == CONFIGURATION_STATE:
            self.max_acceleration = result
        self.acceleration = result
        return None

    def _cmd_id(self, value: str) -> str | None:
        if value in ("", "?") or value.startswith("?"):
            return self.stage_name
        self._require(frozenset({CONFIGURATION_STATE}))
        if not 1 <= len(value) <= 31:
            raise _RefusedError("C")
        self.stage_name = value
        return None

    def _cmd_mm(self, value: str) -> str | None:
        if value.startswith("?"):
            return self.state
        if value[:1] not in ("0", "1"):
            raise _RefusedError("C")
        if value[0] == "0":
            if self.state in READY_STATES:
                self.state = "3C"
            elif self.state not in DISABLE_STATES:
                raise _RefusedError(self._state_letter())
            return None
        if self.state in DISABLE_STATES:
            self.state = "34"
            self.setpoint = self.position
        elif self.state not in READY_STATES:
            raise _RefusedError(self._state_letter())
        return None

    def _cmd_oh(self, value: str) -> str | None:
        configuration = frozenset({CONFIGURATION_STATE})
        result = self._setting(value, self.home_velocity, 1e-6, 1e12, configuration)
        if isinstance(result, str):
            return result
        self.home_velocity = result
        return None

    def _cmd_or(self, value: str) -> str | None:
        if self.state in HOMING_STATES:
            raise _RefusedError("E")
        self._require(NOT_REFERENCED_STATES)
        self._start_motion("home", self.config.home_position_deg, self.home_velocity, "32")
        return None

    def _cmd_pa(self, value: str) -> str | None:
        if value.startswith("?"):
            return self._fmt(self.setpoint)
        self._start_motion("move", self._target(value, relative=False), self.velocity, "33")
        return None

    def _cmd_pr(self, value: str) -> str | None:
        if value.startswith("?"):
            return self._fmt(self.setpoint)
        self._start_motion("move", self._target(value, relative=True), self.velocity, "33")
        return None

    def _cmd_pt(self, value: str) -> str | None:
        if value == "" or value.startswith("?"):
            raise _RefusedError("C")
        displacement = abs(self._number(value))
        self._require(_READY_DISABLE | MOVING_STATES | HOMING_STATES)
        segments = trapezoid(0.0, displacement, self.velocity, self.acceleration)
        return self._fmt(segments[-1].t0 + segments[-1].duration)

    def _cmd_pw(self, value: str) -> str | None:
        if value.startswith("?"):
            return "1" if self.state == CONFIGURATION_STATE else "0"
        if value[:1] == "1":
            if self.state != CONFIGURATION_STATE:
                self._require(NOT_REFERENCED_STATES)
                self.state = CONFIGURATION_STATE
            return None
        if value[:1] == "0":
            self._require(frozenset({CONFIGURATION_STATE}))
            self._go_busy(self.config.config_save_time_s, "0C")
            return None
        raise _RefusedError("C")

    def _cmd_rs(self, value: str) -> str | None:
        self._require(_READY_DISABLE)
        self.motion = None
        self.error_bits = 0
        self.error = "@"
        self.setpoint = self.position
        self.velocity = min(self.velocity, self.max_velocity)
        self._go_busy(self.config.reset_time_s, "0A")
        return None

    def _cmd_sa(self, value: str) -> str | None:
        if value == "" or value.startswith("?"):
            return str(self.address)
        self._require(frozenset({CONFIGURATION_STATE}))
        number = self._number(value)
        low, high = ADDRESS_RANGE
        if number != int(number) or not low <= number <= high:
            raise _RefusedError("C")
        self.address = int(number)
        return None

    def _cmd_sl(self, value: str) -> str | None:
        result = self._setting(value, self.limits[0], -1e12, 0.0, _WORKING)
        if isinstance(result, str):
            return result
        if self.state != CONFIGURATION_STATE and result > self.setpoint:
            raise _RefusedError("C")  # must be <= the set-point position
        self.limits[0] = result
        return None

    def _cmd_sr(self, value: str) -> str | None:
        result = self._setting(value, self.limits[1], 0.0, 1e12, _WORKING)
        if isinstance(result, str):
            return result
        if self.state != CONFIGURATION_STATE and result < self.setpoint:
            raise _RefusedError("C")  # must be >= the set-point position
        self.limits[1] = result
        return None

    def _cmd_st(self, value: str) -> str | None:
        if self.state in NOT_REFERENCED_STATES or self.state == CONFIGURATION_STATE:
            raise _RefusedError(self._state_letter())
        motion = self.motion
        if motion is None:
            return None
        v = motion.velocity(motion.elapsed(self.clock, self.clock.now()))
        end_state = "0B" if motion.kind == "home" else "33"
        t_stop = abs(v) / self.acceleration
        brake = _Segment(0.0, t_stop, self.position, v, -math.copysign(self.acceleration, v))
        self.motion = _Motion("stop", [brake], self.clock.now(), brake.position(t_stop), end_state)
        self.setpoint = self.motion.target
        self._advance()
        return None

    def _cmd_tb(self, value: str) -> str | None:
        code = value.rstrip("?")[:1]
        if not code:
            code, self.error = self.error, "@"
        elif code not in TE_ERRORS:
            raise _RefusedError("C")
        return f"{code} {TE_ERRORS[code].capitalize()}"

    def _cmd_te(self, value: str) -> str | None:
        code, self.error = self.error, "@"
        return code

    def _cmd_th(self, value: str) -> str | None:
        return self._fmt(self.setpoint)

    def _cmd_tp(self, value: str) -> str | None:
        return self._fmt(self.position)

    def _cmd_ts(self, value: str) -> str | None:
        bits, self.error_bits = self.error_bits, 0  # TS reads and clears the error buffer
        return f"{bits:04X}{self.state}"

    def _cmd_va(self, value: str) -> str | None:
        result = self._setting(value, self.velocity, 1e-6, self.max_velocity, _WORKING)
        if isinstance(result, str):
            return result
        if self.state == CONFIGURATION_STATE:
            self.max_velocity = result
        self.velocity = result
        return None

    def _cmd_ve(self, value: str) -> str | None:
        return f" {self.config.firmware}"

    def _cmd_zt(self, value: str) -> list[str]:
        a = self.address
        lines = [f"{a}PW1", f"{a}AC{self.max_acceleration:.6f}"]
        for name in ("BA", "BH", "FE", "HT", "JR", "KD", "KI", "KP", "KV"):
            lines.append(f"{a}{name}{self._config_text(name)}")
        lines += [
            f"{a}ID{self.stage_name}",
            f"{a}OH{self.home_velocity:.6f}",
            f"{a}OT{self._config_text('OT')}",
            f"{a}SA{a}",
            f"{a}SC{self._config_text('SC')}",
            f"{a}SL{self.limits[0]:.6f}",
            f"{a}SR{self.limits[1]:.6f}",
            f"{a}SU{self._config_text('SU')}",
            f"{a}VA{self.max_velocity:.6f}",
            f"{a}ZX{self.smartstage}",
            f"{a}PW0",
        ]
        return lines

    def _config_text(self, name: str) -> str:
        value = self.parameters[name]
        return str(int(value)) if _CONFIG_PARAMETERS[name][1] else f"{value:.6f}"

    def _cmd_zx(self, value: str) -> str | None:
        if value == "" or value.startswith("?"):
            return self.stage_name  # the manual's example: 1ZX? -> 1ZXURS100CC
        self._require(frozenset({CONFIGURATION_STATE}))
        if value[:1] not in ("1", "2", "3"):
            raise _RefusedError("C")
        self.smartstage = int(value[0])
        return None
