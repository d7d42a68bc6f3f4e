"""Shared helpers of the driver tests: fast port settings, a scripted peer on a real pty.

:class:`ScriptedPeer` is the far end of an ``os.openpty()`` pair: it records the exact bytes a
driver writes and answers with scripted bytes (taken from the manuals' examples), for the
message-exchange tests. No code of ours is mocked: the driver under test does real pty I/O.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import select
import threading
import time
import tty

from drivers.camera.wire import USE_CASES
from drivers.solar_simulator import LAMP_SETTINGS, SHUTTER_SETTINGS, SolarSimulator
from drivers.transport import SerialSettings
from drivers.turntable import SMC100_SETTINGS

#: Fast port settings for tests against simulators: short timeouts, quick reconnects.
FAST_SMC100 = dataclasses.replace(
    SMC100_SETTINGS, timeout_s=0.25, retries=2, reconnect_timeout_s=3.0
)
FAST_LAMP = dataclasses.replace(LAMP_SETTINGS, timeout_s=0.25, retries=2, reconnect_timeout_s=3.0)
FAST_SHUTTER = dataclasses.replace(
    SHUTTER_SETTINGS, timeout_s=0.25, retries=2, reconnect_timeout_s=3.0
)


def fast_solar(lamp_port: str, shutter_port: str, **kwargs: object) -> SolarSimulator:
    """A solar simulator driver with fast test settings: no warm-up, quick polls, the fast port
    settings (``kwargs`` override them). It connects on ``with``."""
    options: dict[str, object] = {
        "warmup_s": 0.0,
        "poll_interval_s": 0.01,
        "lamp_settings": FAST_LAMP,
        "shutter_settings": FAST_SHUTTER,
    }
    return SolarSimulator(lamp_port, shutter_port, **(options | kwargs))  # type: ignore[arg-type]


#: The camera tests' usual use cases, and the pico flexx's image size (rows, columns).
MODE5 = USE_CASES["MODE_5_45FPS_500"]
MODE9 = USE_CASES["MODE_9_5FPS_2000"]
H, W = 171, 224

#: The pico flexx line of royale's udev rules file 10-royale-ubuntu.rules.
ROYALE_RULE = (
    'SUBSYSTEMS=="usb", ATTRS{idVendor}=="1c28", ATTRS{idProduct}=="c012", MODE="0666", '
    'SYMLINK+="camboard_pico_flexx-%k", GROUP="plugdev"'
)


class ScriptedPeer:
    """The device end of a real pty pair, answering a fixed script.

    ``script`` is a list of ``(expected_bytes, reply_bytes_or_None)``. A background thread reads
    exactly ``len(expected)`` bytes for each step, records them in :attr:`received`, then writes
    the reply. :meth:`check` asserts that everything received equals what was expected.
    """

    def __init__(self, script: list[tuple[bytes, bytes | None]], step_timeout_s: float = 3.0):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.script = script
        self.received: list[bytes] = []
        self.step_timeout_s = step_timeout_s
        self.error: str | None = None
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _read_exactly(self, n: int) -> bytes:
        data = bytearray()
        deadline = time.monotonic() + self.step_timeout_s
        while len(data) < n:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            ready, _, _ = select.select([self.master], [], [], remaining)
            if ready:
                data.extend(os.read(self.master, n - len(data)))
        return bytes(data)

    def _run(self) -> None:
        try:
            for expected, reply in self.script:
                got = self._read_exactly(len(expected))
                self.received.append(got)
                if got != expected:
                    self.error = f"expected {expected!r}, got {got!r}"
                    return
                if reply is not None:
                    os.write(self.master, reply)
        except OSError as exc:  # the test closed the pty before the script ended
            self.error = f"pty closed during the script: {exc}"

    def check(self) -> None:
        """Wait for the script to finish and assert every exchange matched."""
        self._thread.join(timeout=self.step_timeout_s)
        assert self.error is None, self.error
        assert self.received == [expected for expected, _ in self.script]

    def close(self) -> None:
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


def settings_for(kind: str) -> SerialSettings:
    """The fast test settings of a device kind."""
    return {"smc100": FAST_SMC100, "lamp": FAST_LAMP, "shutter": FAST_SHUTTER}[kind]


def free_port() -> int:
    """A TCP port on the loopback that nothing listens on (now)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def simulated_bridge_process(port: int):
    """``toftwin camera-bridge --simulated --port PORT`` as a process of its own, returned once it
    has said where it listens (its first line)."""
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "toftwin_cli", "camera-bridge", "--simulated",
                             "--port", str(port)], stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline().strip()
    assert line == f"tcp://127.0.0.1:{port}", line
    return proc
