"""Fault injection for the device simulators: names, parsing, and a thread-safe injector.

A fault is selected by name, optionally with how many times it fires and how many events it
lets pass first::

    no-reply          every reply is swallowed (the device went deaf on its TX line)
    garbled:1         the next reply is garbled once (bytes with the high bit flipped)
    truncated:2@3     let 3 replies through, then cut the next 2 short (no terminator)
    stall             every move stalls half way (SMC100: following error -> DISABLE 3D)

Grammar: ``name[:count][@skip]``; ``count`` defaults to "every time" (persistent), ``skip`` to 0.
What counts as an *event* depends on the fault (a reply, a move, a received command); see
:data:`FAULTS`. Faults are armed from the CLI (``--fault stall``) or injected at run time from a
test through :meth:`FaultInjector.inject` while the simulator runs.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Iterable
from dataclasses import dataclass, field, replace

from drivers.errors import DeviceInputError

__all__ = [
    "FAULTS",
    "FAULT_NAMES",
    "RIG_DEVICE_FAULTS",
    "SOLAR_FAULTS",
    "TURNTABLE_FAULTS",
    "FaultInjector",
    "FaultSpec",
    "parse_fault",
    "parse_rig_fault",
]

#: Every fault name with what it does and what one "event" is.
FAULTS: dict[str, str] = {
    "no-reply": "reply swallowed (event: a reply about to be sent)",
    "garbled": "reply bytes XOR 0x80, terminator kept (event: a reply)",
    "truncated": "reply cut to half its length, no terminator (event: a reply)",
    "disconnect": "port closed, reopened after 'downtime_s' (event: a received command)",
    "stall": "SMC100 move stops half way, following error, DISABLE from MOVING (event: a move)",
    "stall-hang": "SMC100 move stops half way and stays MOVING forever (event: a move)",
    "lamp-fault": "arc lamp goes out, STB fault bit, ESR device error (event: command, lamp on)",
    "interlock": "lamp supply interlock opens; lamp off, START refused (event: a command)",
    "shutter-close": "exposure controller: the shutter closes by itself (event: a command while "
    "it is open)",
    "drift": "SMC100: the stage creeps 'offset_deg' (default 0.5 deg) off its position and stays "
    "READY (event: a command at rest)",
}
# The camera simulator (drivers.sim.usb_camera) shares the grammar and the injector; its own
# faults, and what "truncated" and "disconnect" mean for it, are listed in its CAMERA_FAULTS.
FAULTS.update({
    "no-data": "camera: the bulk IN endpoint sends nothing, the host's read times out",
    "corrupt": "camera: payload bytes flipped after the CRC was computed",
    "drop": "camera: a frame is produced, its sequence number used, but never sent",
})
FAULT_NAMES: tuple[str, ...] = tuple(FAULTS)
CAMERA_FAULT_NAMES: tuple[str, ...] = ("no-data", "truncated", "corrupt", "drop", "disconnect")
_COMMON = ("no-reply", "garbled", "truncated", "disconnect")
TURNTABLE_FAULTS: tuple[str, ...] = (*_COMMON, "stall", "stall-hang", "drift")
SOLAR_FAULTS: tuple[str, ...] = (*_COMMON, "lamp-fault", "interlock", "shutter-close")

#: the devices of a simulated rig and the faults each can have
RIG_DEVICE_FAULTS: dict[str, tuple[str, ...]] = {
    "turntable": TURNTABLE_FAULTS,
    "solar-simulator": SOLAR_FAULTS,
    "camera": CAMERA_FAULT_NAMES,
}

_SPEC = re.compile(r"^(?P<name>[a-z][a-z-]*)(?::(?P<count>\d+))?(?:@(?P<skip>\d+))?$")


@dataclass(frozen=True)
class FaultSpec:
    """One armed fault.

    Attributes
    ----------
    name : str
        One of :data:`FAULT_NAMES`.
    count : int or None
        How many events it affects; ``None`` = every event from now on.
    skip : int
        Events let through unaffected before the first one it affects.
    params : dict
        Fault-specific parameters: ``downtime_s`` (disconnect, default 0.5 s), ``at_fraction``
        (stall, default 0.5 of the move), ``offset_deg`` (drift, default 0.5 deg).
    """

    name: str
    count: int | None = None
    skip: int = 0
    params: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.name not in FAULTS:
            raise DeviceInputError(
                "fault", f"unknown fault {self.name!r}; known faults: {', '.join(FAULT_NAMES)}"
            )
        if self.count is not None and self.count < 1:
            raise DeviceInputError("fault.count", f"got {self.count}; at least 1 (or omit)")
        if self.skip < 0:
            raise DeviceInputError("fault.skip", f"got {self.skip}; 0 or more")

    def __str__(self) -> str:
        text = self.name if self.count is None else f"{self.name}:{self.count}"
        return text if not self.skip else f"{text}@{self.skip}"


def parse_rig_fault(text: str) -> tuple[str, FaultSpec]:
    """Parse ``DEVICE:name[:count][@skip]``, a fault armed on one device of a simulated rig.

    >>> parse_rig_fault("solar-simulator:lamp-fault:1@6")
    ('solar-simulator', FaultSpec(name='lamp-fault', count=1, skip=6, params={}))
    """
    device, _, spec = text.strip().partition(":")
    if device not in RIG_DEVICE_FAULTS or not spec:
        raise DeviceInputError(
            "fault", f"cannot parse {text!r}; expected DEVICE:name[:count][@skip] with DEVICE "
            f"one of {', '.join(RIG_DEVICE_FAULTS)}, e.g. 'solar-simulator:lamp-fault:1@6'")
    try:
        return device, parse_fault(spec, RIG_DEVICE_FAULTS[device])
    except DeviceInputError as exc:
        raise DeviceInputError("fault", f"{device}: {exc.message}") from None


def parse_fault(text: str, allowed: tuple[str, ...] = FAULT_NAMES) -> FaultSpec:
    """Parse ``name[:count][@skip]`` into a :class:`FaultSpec`.

    >>> parse_fault("truncated:2@3")
    FaultSpec(name='truncated', count=2, skip=3, params={})
    """
    match = _SPEC.match(text.strip())
    if match is None:
        raise DeviceInputError(
            "fault", f"cannot parse {text!r}; expected name[:count][@skip], e.g. 'garbled:1'"
        )
    name = match.group("name")
    if name not in FAULTS:
        raise DeviceInputError(
            "fault", f"unknown fault {name!r}; known faults: {', '.join(FAULT_NAMES)}"
        )
    if name not in allowed:
        raise DeviceInputError(
            "fault", f"fault {name!r} does not apply here; allowed: {', '.join(allowed)}"
        )
    count = match.group("count")
    return FaultSpec(
        name=name, count=None if count is None else int(count), skip=int(match.group("skip") or 0)
    )


class FaultInjector:
    """Armed faults of one simulated device; safe to use from the server thread and tests.

    The simulator asks :meth:`fire` at every event of a kind ("is a 'garbled' fault due for this
    reply?"). Each call counts one event for every armed spec of that name: specs still skipping
    count down, the first due spec fires and loses one of its count.
    """

    def __init__(
        self,
        specs: Iterable[FaultSpec | str] | None = None,
        allowed: tuple[str, ...] = FAULT_NAMES,
    ) -> None:
        self._lock = threading.Lock()
        self.allowed = allowed
        self._specs: list[FaultSpec] = [
            parse_fault(s, allowed) if isinstance(s, str) else s for s in (specs or [])
        ]
        self.fired: list[str] = []

    def inject(self, spec: FaultSpec | str, **params: float) -> FaultSpec:
        """Arm a fault now (a spec or its text form); keyword arguments become its params."""
        if isinstance(spec, str):
            spec = parse_fault(spec, self.allowed)
        if params:
            spec = replace(spec, params={**spec.params, **params})
        with self._lock:
            self._specs.append(spec)
        return spec

    def clear(self, name: str | None = None) -> None:
        """Disarm every fault, or every fault called ``name``."""
        with self._lock:
            self._specs = [s for s in self._specs if name is not None and s.name != name]

    def armed(self) -> list[FaultSpec]:
        """The faults still armed (a copy)."""
        with self._lock:
            return list(self._specs)

    def is_armed(self, name: str) -> bool:
        """True if a fault called ``name`` is armed (whether or not it is due yet)."""
        with self._lock:
            return any(s.name == name for s in self._specs)

    def fire(self, name: str) -> FaultSpec | None:
        """Count one event for faults called ``name``; return the spec that fires, if any."""
        with self._lock:
            fired: FaultSpec | None = None
            kept: list[FaultSpec] = []
            for spec in self._specs:
                if spec.name != name:
                    kept.append(spec)
                elif spec.skip > 0:
                    kept.append(replace(spec, skip=spec.skip - 1))
                elif fired is None:
                    fired = spec
                    if spec.count is None:
                        kept.append(spec)
                    elif spec.count > 1:
                        kept.append(replace(spec, count=spec.count - 1))
                else:
                    kept.append(spec)
            self._specs = kept
            if fired is not None:
                self.fired.append(name)
            return fired
