"""Simulated Oriel solar simulator: 69907-family arc-lamp supply and 68945 exposure controller.

Two serial devices, one physical state:

- :class:`LampSupplySim` speaks the lamp supply's protocol (9600 8N1, CR-terminated, replies
  terminated by CR): ``IDN?``, ``STB?``, ``ESR?``, ``AMPS?``, ``VOLTS?``, ``WATTS?``,
  ``LAMP HRS?``, ``A-PRESET?``/``=``, ``P-PRESET?``/``=``, ``A-LIM?``/``=``, ``P-LIM?``/``=``,
  ``MODE?``/``=``, ``START``, ``STOP``, ``RST``. Every command that is not a query is answered
  with the event status register (``ESR`` + 2 hex digits), which is then cleared.
- :class:`ShutterControllerSim` speaks the exposure controller's (CR-terminated, replies CR LF):
  ``IDN?``, ``RUN?``, ``EXPSTATE?``, ``ESR?``, ``START`` (open), ``STOP`` (close).
- :class:`SolarRigSim` owns both and answers "how many suns reach the sample now?" for the rest
  of the twin (lamp on, shutter open, warm-up, calibration).

Lamp model (phenomenological, documented in ``docs/devices.md``): after ``START`` the arc voltage
rises from 70 % to its hot value with time constant ``warmup_tau_s``; in power mode the supply
delivers ``P-PRESET * (1 - 0.15 exp(-t / tau))``, capped by ``A-LIM * V`` and ``P-LIM`` (STB
limit bit), so ``WATTS?`` converges to the preset as the lamp warms up. Lamp hours accumulate in
simulated time while the lamp burns.
"""

from __future__ import annotations

import math
import re
import threading
from dataclasses import dataclass

from drivers.sim import SimClock
from drivers.sim.faults import FaultInjector
from drivers.solar_simulator import (
    ESR_COMMAND_ERROR,
    ESR_DEVICE_ERROR,
    ESR_EXECUTION_ERROR,
    ESR_POWER_ON,
    STB_FAULT,
    STB_INTERLOCK,
    STB_LAMP_ON,
    STB_LIMIT,
    STB_POWER_MODE,
    SunsCalibration,
)

__all__ = ["LampSupplyConfig", "LampSupplySim", "ShutterControllerSim", "SolarRigSim"]

_SET = re.compile(r"^(?P<name>[A-Z][A-Z -]*?)\s*[= ]\s*(?P<value>[^=\s]+)$")
_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)$")


@dataclass
class LampSupplyConfig:
    """Parameters of the simulated supply and its lamp (a 450 W Xe arc lamp by default)."""

    model_id: str = "69907"
    max_power_w: float = 500.0
    max_current_a: float = 30.0
    power_limit_w: float = 500.0
    current_limit_a: float = 30.0
    power_preset_w: float = 400.0
    current_preset_a: float = 21.0
    lamp_hours: float = 412.0
    hot_voltage_v: float = 19.5
    cold_voltage_fraction: float = 0.7
    initial_power_deficit: float = 0.15
    warmup_tau_s: float = 360.0


class LampSupplySim:
    """Simulated 69907-family arc-lamp power supply (one serial port).

    Consumes the faults ``lamp-fault`` (event: a command handled while the lamp burns) and
    ``interlock`` (event: any command; the interlock is open while the fault fires). An
    interlock that opens while the lamp burns puts it out, or refuses a ``START``, and latches the
    STB interlock bit (the front panel's indicator) until the next ``START``, ``STOP`` or ``RST``
    (sim choice: a lamp put out by a short interlock opening is reported as such, not as a lamp
    that is merely off).
    """

    reply_terminator = b"\r"

    def __init__(
        self,
        config: LampSupplyConfig | None = None,
        *,
        clock: SimClock | None = None,
        faults: FaultInjector | None = None,
    ) -> None:
        self.config = config or LampSupplyConfig()
        self.clock = clock or SimClock()
        self.faults = faults or FaultInjector()
        self._lock = threading.RLock()
        self._factory_settings()
        self.lamp_hours = self.config.lamp_hours
        self.lamp_on = False
        self.fault = False
        self.interlock_open = False
        #: the interlock put the lamp out or refused START: its indicator stays lit until
        #: START, STOP or RST
        self.interlock_tripped = False
        self.esr = ESR_POWER_ON
        self._on_since = 0.0
        self._last_t = self.clock.now()

    def _factory_settings(self) -> None:
        cfg = self.config
        self.power_mode = True
        self.power_preset_w = cfg.power_preset_w
        self.current_preset_a = cfg.current_preset_a
        self.power_limit_w = cfg.power_limit_w
        self.current_limit_a = cfg.current_limit_a

    # -- physics -----------------------------------------------------------------------------
    def _advance(self) -> None:
        now = self.clock.now()
        if self.lamp_on:
            self.lamp_hours += (now - self._last_t) / 3600.0
        self._last_t = now

    def warmth(self) -> float:
        """0 right after ignition, approaching 1 when warm (1 when the clock is instant)."""
        if not self.lamp_on:
            return 0.0
        if self.clock.instant:
            return 1.0
        t = max(self.clock.now() - self._on_since, 0.0)
        return 1.0 - math.exp(-t / self.config.warmup_tau_s)

    def electrical(self) -> tuple[float, float, float, bool]:
        """(volts, amps, watts, limited) delivered now."""
        if not self.lamp_on:
            return 0.0, 0.0, 0.0, False
        cfg = self.config
        warm = self.warmth()
        volts = cfg.hot_voltage_v * (
            cfg.cold_voltage_fraction + (1 - cfg.cold_voltage_fraction) * warm
        )
        if self.power_mode:
            wanted = self.power_preset_w * (1.0 - cfg.initial_power_deficit * (1.0 - warm))
        else:
            wanted = self.current_preset_a * volts
        cap = min(self.power_limit_w, self.current_limit_a * volts)
        watts = min(wanted, cap)
        limited = wanted > cap + 1e-9
        return volts, watts / volts, watts, limited

    def stb(self) -> int:
        """Status byte: lamp on, power mode, fault, limit, interlock bits."""
        value = 0
        if self.lamp_on:
            value |= STB_LAMP_ON
        if self.power_mode:
            value |= STB_POWER_MODE
        if self.fault:
            value |= STB_FAULT
        if self.interlock_open or self.interlock_tripped:
            value |= STB_INTERLOCK
        if self.electrical()[3]:
            value |= STB_LIMIT
        return value

    def _lamp_off(self) -> None:
        self._advance()
        self.lamp_on = False

    # -- protocol ----------------------------------------------------------------------------
    def handle_line(self, line: str) -> list[str]:
        """Execute one command line; return the reply lines."""
        with self._lock:
            self._advance()
            self.interlock_open = self.faults.fire("interlock") is not None
            if self.interlock_open and self.lamp_on:
                self._lamp_off()
                self.interlock_tripped = True
            if self.lamp_on and self.faults.fire("lamp-fault") is not None:
                self._lamp_off()
                self.fault = True
                self.esr |= ESR_DEVICE_ERROR
            text = " ".join(line.strip().upper().split())
            if not text:
                return []
            if text.endswith("?"):
                reply = self._query(text[:-1].strip())
                if reply is not None:
                    return [reply]
                self.esr |= ESR_COMMAND_ERROR
                return [self._esr_reply()]
            self._command(text)
            return [self._esr_reply()]

    def _esr_reply(self) -> str:
        value, self.esr = self.esr, 0
        return f"ESR{value:02X}"

    def _query(self, name: str) -> str | None:
        volts, amps, watts, _ = self.electrical()
        if name == "ESR":
            return self._esr_reply()
        answers = {
            "IDN": self.config.model_id,
            "STB": f"STB{self.stb():02X}",
            "AMPS": f"{amps:04.1f}",
            "VOLTS": f"{volts:04.1f}",
            "WATTS": f"{round(watts):04d}",
            "LAMP HRS": f"{math.floor(self.lamp_hours):04d}",
            "A-PRESET": f"{self.current_preset_a:04.1f}",
            "P-PRESET": f"{round(self.power_preset_w):04d}",
            "A-LIM": f"{self.current_limit_a:04.1f}",
            "P-LIM": f"{round(self.power_limit_w):04d}",
            "MODE": "0" if self.power_mode else "1",
        }
        return answers.get(name)

    def _command(self, text: str) -> None:
        cfg = self.config
        if text == "START":
            if self.interlock_open:
                self.esr |= ESR_EXECUTION_ERROR
                self.interlock_tripped = True  # the refusal shows on the panel until START
                return
            self.interlock_tripped = False
            if not self.lamp_on:
                self.fault = False
                self.lamp_on = True
                self._on_since = self.clock.now()
                self._last_t = self._on_since
            return
        if text == "STOP":
            self._lamp_off()
            self.fault = False
            self.interlock_tripped = False
            return
        if text == "RST":
            self._lamp_off()
            self.fault = False
            self.interlock_tripped = False
            self._factory_settings()
            return
        match = _SET.match(text)
        if match is None:
            self.esr |= ESR_COMMAND_ERROR
            return
        name, value_text = match.group("name").strip(), match.group("value")
        if not _NUMBER.match(value_text):
            self.esr |= ESR_EXECUTION_ERROR
            return
        value = float(value_text)
        if name == "P-PRESET" and 0 <= value <= self.power_limit_w:
            self.power_preset_w = float(round(value))
        elif name == "A-PRESET" and 0 <= value <= self.current_limit_a:
            self.current_preset_a = round(value, 1)
        elif name == "P-LIM" and 0 <= value <= cfg.max_power_w:
            self.power_limit_w = float(round(value))
            self.power_preset_w = min(self.power_preset_w, self.power_limit_w)
        elif name == "A-LIM" and 0 <= value <= cfg.max_current_a:
            self.current_limit_a = round(value, 1)
            self.current_preset_a = min(self.current_preset_a, self.current_limit_a)
        elif name == "MODE" and value in (0.0, 1.0):
            self.power_mode = value == 0.0
        elif name in ("P-PRESET", "A-PRESET", "P-LIM", "A-LIM", "MODE"):
            self.esr |= ESR_EXECUTION_ERROR
        else:
            self.esr |= ESR_COMMAND_ERROR


class ShutterControllerSim:
    """Simulated Oriel 68945 digital exposure controller driving the solar simulator's shutter.

    Consumes the fault ``shutter-close`` (event: a command received while the shutter is open;
    the shutter closes before the command is executed, as if its exposure had ended).
    """

    reply_terminator = b"\r\n"

    def __init__(
        self,
        *,
        model_id: str = "68945",
        clock: SimClock | None = None,
        faults: FaultInjector | None = None,
    ) -> None:
        self.model_id = model_id
        self.clock = clock or SimClock()
        self.faults = faults or FaultInjector()
        self._lock = threading.RLock()
        self.is_open = False
        self.esr = ESR_POWER_ON

    def handle_line(self, line: str) -> list[str]:
        """Execute one command line; return the reply lines."""
        with self._lock:
            text = " ".join(line.strip().upper().split())
            if not text:
                return []
            if self.is_open and self.faults.fire("shutter-close") is not None:
                self.is_open = False  # the shutter closes by itself (fault "shutter-close")
            if text == "IDN?":
                return [self.model_id]
            if text in ("RUN?", "EXPSTATE?"):
                return ["1" if self.is_open else "0"]
            if text == "ESR?":
                return [self._esr_reply()]
            if text == "START":
                self.is_open = True
            elif text == "STOP":
                self.is_open = False
            else:
                self.esr |= ESR_COMMAND_ERROR
            return [self._esr_reply()]

    def _esr_reply(self) -> str:
        value, self.esr = self.esr, 0
        return f"ESR{value:02X}"


class SolarRigSim:
    """The solar simulator as a whole: lamp supply + shutter controller + optics.

    Parameters
    ----------
    lamp_config : LampSupplyConfig
        Supply and lamp parameters.
    calibration : SunsCalibration
        The *true* mapping lamp power -> suns at the sample plane (the default table unless
        given); the twin can perturb it to test the driver's calibration.
    clock : SimClock
        Shared simulated time.
    lamp_faults, shutter_faults : FaultInjector
        Armed faults of each port.
    """

    def __init__(
        self,
        lamp_config: LampSupplyConfig | None = None,
        *,
        calibration: SunsCalibration | None = None,
        clock: SimClock | None = None,
        lamp_faults: FaultInjector | None = None,
        shutter_faults: FaultInjector | None = None,
    ) -> None:
        self.clock = clock or SimClock()
        self.calibration = calibration or SunsCalibration.load_default()
        self.lamp = LampSupplySim(lamp_config, clock=self.clock, faults=lamp_faults)
        self.shutter = ShutterControllerSim(clock=self.clock, faults=shutter_faults)

    def irradiance_suns(self) -> float:
        """Irradiance at the sample in suns now: 0 unless the lamp burns and the shutter is open."""
        if not (self.lamp.lamp_on and self.shutter.is_open):
            return 0.0
        watts = self.lamp.electrical()[2]
        return self.calibration.suns_for(watts, extrapolate=True)
