"""Solar simulator: Oriel arc-lamp supply (69907 family) and 68945 exposure controller (shutter).

Two RS-232 devices (see ``docs/devices.md``, "Solar simulator", for every command and source):

- the lamp supply, 9600 8N1, commands terminated by CR, replies by CR. Queries end in ``?``
  (``WATTS?`` -> ``0400``, ``STB?`` -> ``STB80``); every other command (``START``, ``STOP``,
  ``P-PRESET=400``) is answered by the event status register, ``ESR`` + 2 hex digits;
- the exposure controller driving the shutter: ``START`` opens, ``STOP`` closes, ``RUN?`` -> ``1``
  while open; replies end in CR LF.

The level at the sample is given in *suns* (1 sun = 1000 W/m^2); :class:`SunsCalibration` maps it
to a lamp power preset through a measured table (``drivers/data/solar_calibration.yaml`` by
default), interpolating linearly. An arc lamp needs a warm-up before its output is stable:
:meth:`SolarSimulator.wait_until_stable` waits for both the warm-up period and a steady power
reading at the preset.

Units: power in W, current in A, voltage in V, time in s, level in suns.
"""

from __future__ import annotations

import bisect
import logging
import math
import re
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import serial

from drivers.errors import (
    CalibrationError,
    DeviceInputError,
    InterlockError,
    LampFaultError,
    LimitError,
    ProtocolError,
    SolarSimulatorError,
)
from drivers.transport import SerialSettings, SerialTransport
from sim_core.lights import SUNS_RANGE  # level range in suns; its home is sim_core.lights

__all__ = [
    "DEFAULT_CALIBRATION_PATH",
    "ESR_BITS",
    "LAMP_SETTINGS",
    "SHUTTER_SETTINGS",
    "STB_BITS",
    "SUNS_RANGE",
    "SolarSimulator",
    "SolarSimulatorProtocol",
    "SolarStatus",
    "SunsCalibration",
    "describe_esr",
    "describe_stb",
    "parse_register",
]

DEFAULT_CALIBRATION_PATH = Path(__file__).parent / "data" / "solar_calibration.yaml"

#: Lamp supply serial port: 9600 8N1, no flow control, CR-terminated commands.
LAMP_SETTINGS = SerialSettings(
    baudrate=9600,
    bytesize=serial.EIGHTBITS,
    parity=serial.PARITY_NONE,
    stopbits=serial.STOPBITS_ONE,
    write_terminator=b"\r",
    timeout_s=1.0,
    retries=2,
    reconnect_timeout_s=5.0,
)
#: Exposure controller serial port: same framing.
SHUTTER_SETTINGS = LAMP_SETTINGS

# Status byte (STB?) bits: the front-panel indicators.
STB_LAMP_ON = 0x80
STB_EXT = 0x40
STB_POWER_MODE = 0x20
STB_CAL_MODE = 0x10
STB_FAULT = 0x08
STB_COMM = 0x04
STB_LIMIT = 0x02
STB_INTERLOCK = 0x01
STB_BITS: dict[int, str] = {
    STB_LAMP_ON: "lamp on",
    STB_EXT: "external control",
    STB_POWER_MODE: "power mode (else current mode)",
    STB_CAL_MODE: "calibration mode",
    STB_FAULT: "fault",
    STB_COMM: "communication",
    STB_LIMIT: "limit",
    STB_INTERLOCK: "interlock",
}

# Event status register (ESR?) bits, IEEE 488.2 layout.
ESR_POWER_ON = 0x80
ESR_USER_REQUEST = 0x40
ESR_COMMAND_ERROR = 0x20
ESR_EXECUTION_ERROR = 0x10
ESR_DEVICE_ERROR = 0x08
ESR_QUERY_ERROR = 0x04
ESR_REQUEST_CONTROL = 0x02
ESR_OPERATION_COMPLETE = 0x01
ESR_ERROR_MASK = ESR_COMMAND_ERROR | ESR_EXECUTION_ERROR | ESR_DEVICE_ERROR | ESR_QUERY_ERROR
ESR_BITS: dict[int, str] = {
    ESR_POWER_ON: "power on",
    ESR_USER_REQUEST: "user request",
    ESR_COMMAND_ERROR: "command error",
    ESR_EXECUTION_ERROR: "execution error",
    ESR_DEVICE_ERROR: "device dependent error",
    ESR_QUERY_ERROR: "query error",
    ESR_REQUEST_CONTROL: "request control",
    ESR_OPERATION_COMPLETE: "operation complete",
}

_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)$")
_log = logging.getLogger(__name__)


# -- pure protocol functions ---------------------------------------------------------------
def parse_register(name: str, line: str) -> int:
    """Parse ``STB80`` / ``ESR20``: the register name then 2 hex digits.

    >>> parse_register("STB", "STB80"), parse_register("ESR", "ESR20")
    (128, 32)
    """
    text = line.strip().upper()
    if not re.fullmatch(rf"{name}[0-9A-F]{{1,2}}", text):
        raise ProtocolError(f"{line!r} is not {name} followed by 2 hex digits")
    return int(text[len(name) :], 16)


def parse_value(line: str) -> float:
    """Parse a numeric reply (``0400``, ``21.5``)."""
    text = line.strip()
    if not _NUMBER.match(text):
        raise ProtocolError(f"{line!r} is not a number")
    return float(text)


def _describe(bits: Mapping[int, str], value: int) -> list[str]:
    return [name for bit, name in bits.items() if value & bit]


def describe_stb(value: int) -> list[str]:
    """Names of the status byte bits set in ``value``.

    >>> describe_stb(0xA0)
    ['lamp on', 'power mode (else current mode)']
    """
    return _describe(STB_BITS, value)


def describe_esr(value: int) -> list[str]:
    """Names of the event status register bits set in ``value``."""
    return _describe(ESR_BITS, value)


# -- calibration ---------------------------------------------------------------------------
@dataclass(frozen=True)
class SunsCalibration:
    """Measured mapping level [suns] -> lamp power preset [W], interpolated linearly.

    Both columns must have the same length (at least 2), be finite and increase strictly.

    Examples
    --------
    >>> cal = SunsCalibration((0.8, 1.0, 1.2), (320.0, 400.0, 480.0))
    >>> cal.power_for(0.9), cal.suns_for(440.0)
    (360.0, 1.1)
    """

    suns: tuple[float, ...]
    power_w: tuple[float, ...]
    source: str = "<memory>"

    def __post_init__(self) -> None:
        for name, column in (("suns", self.suns), ("power_w", self.power_w)):
            field = f"calibration.{name}"
            if len(column) < 2:
                raise CalibrationError(field, f"needs at least 2 points, got {len(column)}")
            for i, value in enumerate(column):
                if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                    raise CalibrationError(
                        field, f"value {value!r} at index {i} is not a finite number > 0"
                    )
            for i in range(1, len(column)):
                if not column[i] > column[i - 1]:
                    raise CalibrationError(
                        field,
                        f"must increase strictly: {column[i]!r} at index {i} follows "
                        f"{column[i - 1]!r} at index {i - 1} (table {self.source})",
                    )
        if len(self.suns) != len(self.power_w):
            raise CalibrationError(
                "calibration",
                f"suns has {len(self.suns)} values, power_w {len(self.power_w)} "
                f"(table {self.source})",
            )

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], source: str = "<memory>") -> SunsCalibration:
        """Build from ``{"suns": [...], "power_w": [...]}`` (extra keys are ignored)."""
        columns = []
        for key in ("suns", "power_w"):
            column = data.get(key)
            if not isinstance(column, Sequence) or isinstance(column, str):
                raise CalibrationError(f"calibration.{key}", f"missing or not a list in {source}")
            columns.append(tuple(float(v) if isinstance(v, int) else v for v in column))
        return cls(columns[0], columns[1], source)

    @classmethod
    def from_file(cls, path: str | Path) -> SunsCalibration:
        """Load a YAML (``.yaml``/``.yml``) or JSON (``.json``) table."""
        path = Path(path)
        if path.suffix.lower() not in (".json", ".yaml", ".yml"):
            raise CalibrationError(
                "calibration.path", f"{str(path)!r}: expected a .yaml, .yml or .json file"
            )
        # YAML is a project dependency; imported here so the driver loads without it
        from sim_core.files import StructuredFileError, load_structured

        try:
            data = load_structured(path)
        except StructuredFileError as exc:
            raise CalibrationError("calibration.path", str(exc)) from None
        if not isinstance(data, Mapping):
            raise CalibrationError("calibration", f"{str(path)!r} does not hold a mapping")
        return cls.from_mapping(data, source=str(path))

    @classmethod
    def load_default(cls) -> SunsCalibration:
        """The table shipped in ``drivers/data/solar_calibration.yaml``."""
        return cls.from_file(DEFAULT_CALIBRATION_PATH)

    @staticmethod
    def _interp(x: float, xs: tuple[float, ...], ys: tuple[float, ...]) -> float:
        i = min(max(bisect.bisect_right(xs, x), 1), len(xs) - 1)
        x0, x1, y0, y1 = xs[i - 1], xs[i], ys[i - 1], ys[i]
        return y0 + (y1 - y0) * (x - x0) / (x1 - x0)

    def power_for(self, suns: float) -> float:
        """Lamp power preset in W for a level in suns inside the table."""
        low, high = self.suns[0], self.suns[-1]
        if not (math.isfinite(suns) and low <= suns <= high):
            raise LimitError("suns", suns, low, high, "suns", f"calibration table {self.source}")
        return self._interp(suns, self.suns, self.power_w)

    def suns_for(self, power_w: float, *, extrapolate: bool = False) -> float:
        """Level in suns produced by a lamp power in W (inverse interpolation)."""
        low, high = self.power_w[0], self.power_w[-1]
        if not math.isfinite(power_w):
            raise DeviceInputError("power_w", f"got {power_w!r}; a finite power is required")
        if not extrapolate and not low <= power_w <= high:
            raise LimitError("power_w", power_w, low, high, "W", f"calibration table {self.source}")
        return self._interp(power_w, self.power_w, self.suns)


# -- status --------------------------------------------------------------------------------
@dataclass(frozen=True)
class SolarStatus:
    """One reading of the lamp supply's status byte, with the shutter state."""

    stb: int
    shutter_open: bool | None = None  # None: not read with this status

    @property
    def lamp_on(self) -> bool:
        return bool(self.stb & STB_LAMP_ON)

    @property
    def power_mode(self) -> bool:
        return bool(self.stb & STB_POWER_MODE)

    @property
    def fault(self) -> bool:
        return bool(self.stb & STB_FAULT)

    @property
    def interlock(self) -> bool:
        return bool(self.stb & STB_INTERLOCK)

    @property
    def limit(self) -> bool:
        return bool(self.stb & STB_LIMIT)

    def describe(self) -> str:
        """``'STB 0xA0 (lamp on, power mode ...), shutter closed'``."""
        flags = ", ".join(describe_stb(self.stb)) or "no flags"
        text = f"STB 0x{self.stb:02X} ({flags})"
        if self.shutter_open is not None:
            text += f", shutter {'open' if self.shutter_open else 'closed'}"
        return text


# -- the interface the rest of the code depends on ------------------------------------------
@runtime_checkable
class SolarSimulatorProtocol(Protocol):
    """What the service and the pose loop need from the solar simulator."""

    def lamp_on(self) -> None:
        """Ignite the lamp; raise if it does not light (interlock, fault)."""
        ...

    def lamp_off(self) -> None:
        """Extinguish the lamp."""
        ...

    def is_lamp_on(self) -> bool:
        """True while the supply reports the lamp burning."""
        ...

    def set_power_w(self, power_w: float) -> None:
        """Set the lamp power preset in W."""
        ...

    def read_power_w(self) -> float:
        """Lamp power delivered now, in W."""
        ...

    def set_suns(self, suns: float) -> None:
        """Set the level at the sample in suns (0.8 to 1.2) through the calibration."""
        ...

    def read_suns(self) -> float:
        """Level in suns implied by the power delivered now (0 with the lamp off)."""
        ...

    def open_shutter(self) -> None: ...

    def close_shutter(self) -> None: ...

    def shutter_is_open(self) -> bool: ...

    def lamp_hours(self) -> float:
        """Hours on the current lamp."""
        ...

    def status(self) -> SolarStatus:
        """Lamp supply status byte and shutter state."""
        ...

    def wait_until_stable(self, timeout_s: float) -> float:
        """Wait for warm-up and a steady power at the preset; return the power in W."""
        ...

    def close(self) -> None: ...


# -- the real driver ------------------------------------------------------------------------
class SolarSimulator:
    """Oriel solar simulator over two serial ports (lamp supply and exposure controller).

    Parameters
    ----------
    lamp_port, shutter_port : str
        Device paths or pyserial URLs.
    calibration : SunsCalibration or str or Path or None
        The suns -> power table, or a path to one; ``None`` loads the default table.
    warmup_s : float
        Minimum time after ignition before the output counts as stable (arc lamps drift for
        about 30 minutes after ignition).
    power_tolerance_w : float
        Largest difference between the power read back and the preset counted as steady.
    stable_reads : int
        Consecutive steady readings required by :meth:`wait_until_stable`.
    poll_interval_s : float
        Period of the polling while waiting for ignition or stability.
    ignition_timeout_s : float
        Longest wait for the lamp-on bit after ``START``.
    lamp_already_warm : bool
        When the lamp is found burning at :meth:`connect`, count it as warm (else its warm-up
        is counted from the connection).
    """

    def __init__(
        self,
        lamp_port: str,
        shutter_port: str,
        *,
        calibration: SunsCalibration | str | Path | None = None,
        warmup_s: float = 1800.0,
        power_tolerance_w: float = 2.0,
        stable_reads: int = 3,
        poll_interval_s: float = 0.5,
        ignition_timeout_s: float = 10.0,
        lamp_already_warm: bool = False,
        lamp_settings: SerialSettings = LAMP_SETTINGS,
        shutter_settings: SerialSettings = SHUTTER_SETTINGS,
    ) -> None:
        for field, value in (
            ("warmup_s", warmup_s),
            ("power_tolerance_w", power_tolerance_w),
            ("poll_interval_s", poll_interval_s),
            ("ignition_timeout_s", ignition_timeout_s),
        ):
            if not (math.isfinite(value) and value >= 0):
                raise DeviceInputError(field, f"got {value!r}; a finite number >= 0 is required")
        if stable_reads < 1:
            raise DeviceInputError("stable_reads", f"got {stable_reads!r}; at least 1")
        if calibration is None:
            calibration = SunsCalibration.load_default()
        elif not isinstance(calibration, SunsCalibration):
            calibration = SunsCalibration.from_file(calibration)
        self.calibration = calibration
        self.warmup_s = warmup_s
        self.power_tolerance_w = power_tolerance_w
        self.stable_reads = stable_reads
        self.poll_interval_s = poll_interval_s
        self.ignition_timeout_s = ignition_timeout_s
        self.lamp_already_warm = lamp_already_warm
        self.lamp = SerialTransport(lamp_port, lamp_settings, name="Oriel lamp supply")
        self.shutter = SerialTransport(shutter_port, shutter_settings, name="Oriel shutter")
        self.model_id = ""
        self.shutter_model_id = ""
        self.power_limit_w = math.inf
        self.lamp_on_since: float | None = None

    # -- connection ---------------------------------------------------------------------------
    def connect(self) -> None:
        """Open both ports, identify, clear the ESR, ensure power mode, read the power limit."""
        self.lamp.open()
        self.shutter.open()
        self.model_id = self.lamp.query("IDN?", str.strip)
        self._clear_esr()
        stb = self._stb()
        if not stb & STB_POWER_MODE:
            self._lamp_command("MODE=0")
        self.power_limit_w = self.lamp.query("P-LIM?", parse_value)
        needed = self.calibration.power_for(min(SUNS_RANGE[1], self.calibration.suns[-1]))
        if needed > self.power_limit_w:
            raise CalibrationError(
                "calibration.power_w",
                f"{needed:g} W needed for {SUNS_RANGE[1]:g} suns exceeds the supply's "
                f"P-LIM {self.power_limit_w:g} W",
            )
        if stb & STB_LAMP_ON:
            now = time.monotonic()
            self.lamp_on_since = now - self.warmup_s if self.lamp_already_warm else now
        self.shutter_model_id = self.shutter.query("IDN?", str.strip)
        self.shutter.query("ESR?", lambda line: parse_register("ESR", line))

    def close(self) -> None:
        """Close both ports (the lamp and shutter keep their state)."""
        self.lamp.close()
        self.shutter.close()

    def __enter__(self) -> SolarSimulator:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- low level ----------------------------------------------------------------------------
    def _stb(self) -> int:
        return self.lamp.query("STB?", lambda line: parse_register("STB", line))

    def _check_esr(self, device: str, command: str, esr: int) -> None:
        errors = esr & ESR_ERROR_MASK
        if not errors:
            return
        names = ", ".join(describe_esr(errors))
        message = f"{device}: ESR 0x{esr:02X} ({names}) after {command!r}"
        if esr & ESR_DEVICE_ERROR:
            raise LampFaultError(f"{message}; {self.lamp_status().describe()}")
        if command == "START" and device == "lamp supply":
            status = self.lamp_status()
            if status.interlock:
                raise InterlockError(f"{message}: interlock open ({status.describe()})")
        raise SolarSimulatorError(message)

    def _clear_esr(self) -> int:
        """Read (and so clear) the lamp supply's event status register."""
        return self.lamp.query("ESR?", lambda line: parse_register("ESR", line))

    def _lamp_command(self, command: str) -> None:
        esr = self.lamp.query(command, lambda line: parse_register("ESR", line))
        self._check_esr("lamp supply", command, esr)

    def _shutter_command(self, command: str) -> None:
        esr = self.shutter.query(command, lambda line: parse_register("ESR", line))
        self._check_esr("shutter controller", command, esr)

    # -- status -------------------------------------------------------------------------------
    def status(self) -> SolarStatus:
        """Status byte of the lamp supply and the shutter state."""
        return SolarStatus(self._stb(), self.shutter_is_open())

    def lamp_status(self) -> SolarStatus:
        """Status byte of the lamp supply only (one exchange on the lamp port)."""
        return SolarStatus(self._stb())

    def check_faults(self) -> SolarStatus:
        """Raise :class:`InterlockError` / :class:`LampFaultError` if the supply reports one."""
        status = self.lamp_status()
        if status.interlock:
            raise InterlockError(
                f"lamp supply interlock open (or tripped since the lamp was lit, which puts the "
                f"lamp out): {status.describe()}; close the interlock, then relight the lamp")
        if status.fault:
            raise LampFaultError(f"lamp supply reports a lamp fault: {status.describe()}")
        return status

    def is_lamp_on(self) -> bool:
        return bool(self._stb() & STB_LAMP_ON)

    def lamp_hours(self) -> float:
        """Hours on the current lamp (``LAMP HRS?``)."""
        return self.lamp.query("LAMP HRS?", parse_value)

    def read_current_a(self) -> float:
        return self.lamp.query("AMPS?", parse_value)

    def read_voltage_v(self) -> float:
        return self.lamp.query("VOLTS?", parse_value)

    def read_power_w(self) -> float:
        """Power delivered to the lamp now (``WATTS?``), in W."""
        return self.lamp.query("WATTS?", parse_value)

    def power_preset_w(self) -> float:
        """Power preset (``P-PRESET?``), in W."""
        return self.lamp.query("P-PRESET?", parse_value)

    # -- lamp ---------------------------------------------------------------------------------
    def lamp_on(self) -> None:
        """Ignite the lamp (``START``) and wait for the lamp-on bit.

        Raises :class:`InterlockError` when the interlock is open, :class:`LampFaultError` when
        the supply reports a fault or the lamp does not light within ``ignition_timeout_s``.
        """
        status = self.lamp_status()
        if status.lamp_on:
            return
        # An interlock bit here may be a trip latched since the lamp went out (START clears it)
        # or an interlock still open: then the supply refuses START (InterlockError below).
        self._clear_esr()  # so that the ESR answering START holds START's events only
        self._lamp_command("START")
        deadline = time.monotonic() + self.ignition_timeout_s
        while True:
            status = self.lamp_status()
            if status.fault:
                raise LampFaultError(f"lamp fault after START: {status.describe()}")
            if status.interlock:
                raise InterlockError(f"interlock opened after START: {status.describe()}")
            if status.lamp_on:
                self.lamp_on_since = time.monotonic()
                return
            if time.monotonic() > deadline:
                raise LampFaultError(
                    f"lamp did not ignite within {self.ignition_timeout_s:g} s of START "
                    f"({status.describe()})"
                )
            time.sleep(self.poll_interval_s)

    def lamp_off(self) -> None:
        """Extinguish the lamp (``STOP``).

        A device-dependent error in the ESR (a lamp fault since the ESR was last read) is only
        logged here: the lamp is off either way, which is what was asked.
        """
        esr = self.lamp.query("STOP", lambda line: parse_register("ESR", line))
        self.lamp_on_since = None
        if esr & ESR_DEVICE_ERROR:
            _log.warning("lamp supply: ESR 0x%02X after 'STOP' (a lamp fault was latched)", esr)
            esr &= ~ESR_DEVICE_ERROR
        self._check_esr("lamp supply", "STOP", esr)

    def set_power_w(self, power_w: float) -> None:
        """Set the power preset (``P-PRESET=<W>``, whole watts) and read it back."""
        value = float(power_w)
        if not (math.isfinite(value) and 0 < value <= self.power_limit_w):
            raise LimitError(
                "power_w", value, 0.0, self.power_limit_w, "W", "lamp supply power limit P-LIM"
            )
        watts = round(value)
        command = f"P-PRESET={watts}"
        self._lamp_command(command)
        readback = self.power_preset_w()
        if readback != watts:
            raise SolarSimulatorError(
                f"lamp supply: {command!r} accepted but P-PRESET? reads {readback:g} W"
            )

    # -- suns ---------------------------------------------------------------------------------
    def power_for_suns(self, suns: float) -> float:
        """Power preset in W for a level in suns, checking the allowed range 0.8..1.2."""
        value = float(suns)
        low, high = SUNS_RANGE
        if not (math.isfinite(value) and low <= value <= high):
            raise LimitError("suns", value, low, high, "suns", "solar simulator level")
        return self.calibration.power_for(value)

    def set_suns(self, suns: float) -> None:
        """Set the level at the sample in suns (0.8 to 1.2) through the calibration table."""
        self.set_power_w(self.power_for_suns(suns))

    def read_suns(self) -> float:
        """Level in suns implied by the power delivered now; 0 with the lamp off (also when it
        goes out between the two reads: the level is never negative)."""
        if not self.is_lamp_on():
            return 0.0
        return max(0.0, self.calibration.suns_for(self.read_power_w(), extrapolate=True))

    # -- shutter ------------------------------------------------------------------------------
    def shutter_is_open(self) -> bool:
        """True while the exposure controller holds the shutter open (``RUN?`` -> ``1``)."""

        def parse(line: str) -> bool:
            if line.strip() not in ("0", "1"):
                raise ProtocolError(f"RUN? reply {line!r} is not 0 or 1")
            return line.strip() == "1"

        return self.shutter.query("RUN?", parse)

    def open_shutter(self) -> None:
        """Open the shutter (``START``) and check it reports open."""
        self._shutter_command("START")
        if not self.shutter_is_open():
            raise SolarSimulatorError("shutter controller: START accepted but RUN? reads 0")

    def close_shutter(self) -> None:
        """Close the shutter (``STOP``) and check it reports closed."""
        self._shutter_command("STOP")
        if self.shutter_is_open():
            raise SolarSimulatorError("shutter controller: STOP accepted but RUN? reads 1")

    # -- stability ----------------------------------------------------------------------------
    def warmup_remaining_s(self) -> float:
        """Seconds of warm-up left (``inf`` with the lamp off)."""
        if self.lamp_on_since is None:
            return math.inf
        return max(0.0, self.warmup_s - (time.monotonic() - self.lamp_on_since))

    def is_stable(self) -> bool:
        """One check: lamp on, no fault, warm-up over, power within tolerance of the preset."""
        status = self.check_faults()
        if not status.lamp_on or self.warmup_remaining_s() > 0:
            return False
        return abs(self.read_power_w() - self.power_preset_w()) <= self.power_tolerance_w

    def wait_until_stable(self, timeout_s: float) -> float:
        """Wait for the warm-up and ``stable_reads`` steady power readings; return the power.

        Raises :class:`LampFaultError` / :class:`InterlockError` as soon as the supply reports
        one, :class:`SolarSimulatorError` if the lamp is off or not stable within ``timeout_s``.
        """
        deadline = time.monotonic() + timeout_s
        preset = self.power_preset_w()
        steady = 0
        power = math.nan
        while True:
            status = self.check_faults()
            if not status.lamp_on:
                raise SolarSimulatorError(
                    f"lamp is off; nothing to stabilise ({status.describe()})"
                )
            power = self.read_power_w()
            warm = self.warmup_remaining_s() <= 0
            steady = steady + 1 if warm and abs(power - preset) <= self.power_tolerance_w else 0
            if steady >= self.stable_reads:
                return power
            if time.monotonic() > deadline:
                raise SolarSimulatorError(
                    f"output not stable within {timeout_s:g} s: WATTS {power:g} W vs preset "
                    f"{preset:g} W (tolerance {self.power_tolerance_w:g} W), warm-up remaining "
                    f"{self.warmup_remaining_s():.1f} s"
                )
            time.sleep(self.poll_interval_s)
