"""Line-oriented serial transport over pyserial: open, frame, time out, retry, reconnect.

Both serial devices of the rig speak short ASCII lines: a command goes out with a terminator
(CR LF for the SMC100, CR for the Oriel units) and at most one line comes back. This module does
the byte-level work once, so the device drivers only build commands and parse replies:

- ``port`` is a device path (``/dev/ttyUSB0``, a pty such as ``/dev/pts/7`` or a symlink to one)
  or any pyserial URL (``socket://127.0.0.1:5025``, ``loop://``); it is opened with
  :func:`serial.serial_for_url`, so the simulators' TCP endpoints work unchanged.
- Replies are framed on CR or LF (either, or both, so CR LF leaves an empty line that is skipped);
  XON/XOFF bytes are dropped; any other byte outside printable ASCII marks the reply as garbled.
- Every exchange starts by discarding stale input, so the tail of an earlier, truncated or late
  reply can never be taken for the answer to the current command.
- :meth:`SerialTransport.query` retries idempotent queries on a timeout or a malformed reply, and
  reopens the port (within ``reconnect_timeout_s``) when it went away.

Every line sent and received is kept in :attr:`SerialTransport.transcript`, a bounded record
``(monotonic time, "tx"/"rx", bytes)`` that a campaign can store next to its results.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import serial

from drivers.errors import (
    DeviceDisconnectedError,
    DeviceTimeoutError,
    GarbledReplyError,
    ProtocolError,
)

__all__ = ["XOFF", "XON", "SerialSettings", "SerialTransport", "TranscriptEntry", "open_port"]

_log = logging.getLogger(__name__)

T = TypeVar("T")

XON = 0x11
XOFF = 0x13
_FLOW_BYTES = bytes([XON, XOFF])

# What a port that went away raises: pyserial's exception, the OS's, and termios.error (not an
# OSError) from tcflush on a pty whose other side closed.
try:
    import termios

    _PORT_ERRORS: tuple[type[BaseException], ...] = (
        serial.SerialException,
        OSError,
        termios.error,
    )
except ImportError:  # pragma: no cover - Windows has no termios
    _PORT_ERRORS = (serial.SerialException, OSError)

# Granularity of the read loop. pyserial re-programs the tty on every timeout change, so the
# port keeps this short timeout and the loop below enforces the real deadline.
_POLL_S = 0.02


@dataclass(frozen=True)
class SerialSettings:
    """How to talk to one serial device.

    Attributes
    ----------
    baudrate : int
        Bits per second (ignored by ``socket://`` URLs).
    bytesize, parity, stopbits
        Character framing, pyserial constants (8N1 by default).
    xonxoff, rtscts : bool
        Software / hardware flow control.
    write_terminator : bytes
        Appended to every command (``b"\\r\\n"`` for the SMC100, ``b"\\r"`` for the Oriel units).
    timeout_s : float
        How long to wait for a complete reply line, in seconds.
    write_timeout_s : float
        How long a write may block (flow control held off), in seconds.
    retries : int
        Extra attempts for idempotent queries after a timeout or a malformed reply.
    reconnect_timeout_s : float
        How long to keep trying to reopen a port that went away, in seconds.
    """

    baudrate: int = 9600
    bytesize: int = serial.EIGHTBITS
    parity: str = serial.PARITY_NONE
    stopbits: float = serial.STOPBITS_ONE
    xonxoff: bool = False
    rtscts: bool = False
    write_terminator: bytes = b"\r"
    timeout_s: float = 1.0
    write_timeout_s: float = 1.0
    retries: int = 2
    reconnect_timeout_s: float = 5.0


@dataclass(frozen=True)
class TranscriptEntry:
    """One line on the wire: when (``time.monotonic()``), which way, and the exact bytes."""

    t: float
    direction: str
    data: bytes


def open_port(port: str, settings: SerialSettings) -> serial.SerialBase:
    """Open a device path or pyserial URL with ``settings``; raise DeviceDisconnectedError if not.

    The port keeps a short read timeout (the transport's read loop applies the real one).
    """
    try:
        ser = serial.serial_for_url(
            port,
            do_not_open=True,
            baudrate=settings.baudrate,
            bytesize=settings.bytesize,
            parity=settings.parity,
            stopbits=settings.stopbits,
            xonxoff=settings.xonxoff,
            rtscts=settings.rtscts,
            timeout=_POLL_S,
            write_timeout=settings.write_timeout_s,
        )
        ser.open()
    except (*_PORT_ERRORS, ValueError) as exc:
        raise DeviceDisconnectedError(f"cannot open port {port!r}: {exc}") from exc
    return ser


class SerialTransport:
    """A line-framed, retrying connection to one serial device.

    Parameters
    ----------
    port : str
        Device path or pyserial URL.
    settings : SerialSettings
        Framing, timeouts and retry policy.
    name : str
        Human name of the device used in error messages (``"SMC100 turntable"``).

    Examples
    --------
    >>> t = SerialTransport("loop://", SerialSettings(write_terminator=b"\\r"), name="echo")
    >>> t.open()
    >>> t.query("IDN?", str)  # loop:// echoes what was written
    'IDN?'
    >>> t.close()
    """

    def __init__(self, port: str, settings: SerialSettings, *, name: str = "device") -> None:
        self.port = port
        self.settings = settings
        self.name = name
        self.transcript: collections.deque[TranscriptEntry] = collections.deque(maxlen=2000)
        self._ser: Any = None
        self._rx = bytearray()
        # One exchange at a time: a query's reply must not be read by another thread's query.
        self._lock = threading.RLock()

    # -- life cycle -------------------------------------------------------------------------
    def open(self) -> None:
        """Open the port (no-op if already open)."""
        if self._ser is None:
            self._ser = open_port(self.port, self.settings)
            self._rx.clear()

    def close(self) -> None:
        """Close the port; safe to call twice."""
        ser, self._ser = self._ser, None
        self._rx.clear()
        if ser is not None:
            with contextlib.suppress(*_PORT_ERRORS):
                ser.close()

    @property
    def is_open(self) -> bool:
        """True while a port object is open."""
        return self._ser is not None

    def reconnect(self) -> None:
        """Close and reopen the port, trying until ``reconnect_timeout_s`` has passed."""
        self.close()
        deadline = time.monotonic() + self.settings.reconnect_timeout_s
        delay = 0.05
        while True:
            try:
                self.open()
                _log.info("%s: reopened %s", self.name, self.port)
                return
            except DeviceDisconnectedError as exc:
                if time.monotonic() + delay > deadline:
                    raise DeviceDisconnectedError(
                        f"{self.name} at {self.port}: port gone and not back within "
                        f"{self.settings.reconnect_timeout_s:g} s ({exc})"
                    ) from exc
                time.sleep(delay)
                delay = min(delay * 2.0, 0.5)

    def __enter__(self) -> SerialTransport:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- byte level -------------------------------------------------------------------------
    def _port(self) -> Any:
        if self._ser is None:
            self.open()
        return self._ser

    def discard_input(self) -> None:
        """Drop everything received but not yet read (stale or late replies)."""
        ser = self._port()
        self._rx.clear()
        try:
            ser.reset_input_buffer()
        except _PORT_ERRORS as exc:
            raise DeviceDisconnectedError(f"{self.name} at {self.port}: {exc}") from exc

    def write_line(self, command: str) -> None:
        """Send ``command`` followed by the write terminator (ASCII only)."""
        data = command.encode("ascii") + self.settings.write_terminator
        ser = self._port()
        try:
            ser.write(data)
            ser.flush()
        except serial.SerialTimeoutException as exc:
            raise DeviceTimeoutError(
                f"{self.name} at {self.port}: write of {command!r} blocked for more than "
                f"{self.settings.write_timeout_s:g} s (flow control held off?)"
            ) from exc
        except _PORT_ERRORS as exc:
            raise DeviceDisconnectedError(
                f"{self.name} at {self.port}: write of {command!r} failed: {exc}"
            ) from exc
        self.transcript.append(TranscriptEntry(time.monotonic(), "tx", data))

    def read_line(self, timeout_s: float | None = None, *, context: str = "") -> str:
        """Return the next non-empty reply line, without its terminator.

        Raises
        ------
        DeviceTimeoutError
            No complete line within ``timeout_s`` (default ``settings.timeout_s``); the message
            shows any partial bytes received (a truncated reply).
        GarbledReplyError
            The line holds bytes outside printable ASCII.
        DeviceDisconnectedError
            The port went away while waiting.
        """
        timeout = self.settings.timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout
        ser = self._port()
        while True:
            line = self._pop_line()
            if line is not None:
                return self._decode(line, context)
            if time.monotonic() >= deadline:
                partial = bytes(self._rx)
                what = f"partial reply {partial!r}" if partial else "no reply"
                raise DeviceTimeoutError(
                    f"{self.name} at {self.port}: {what} to {context or 'command'} "
                    f"within {timeout:g} s"
                )
            try:
                waiting = ser.in_waiting
                chunk = ser.read(max(1, waiting))
            except _PORT_ERRORS as exc:
                raise DeviceDisconnectedError(
                    f"{self.name} at {self.port}: read failed waiting for reply to "
                    f"{context or 'command'}: {exc}"
                ) from exc
            if chunk:
                self._rx.extend(b for b in chunk if b not in _FLOW_BYTES)

    def _pop_line(self) -> bytes | None:
        """Cut the first complete line out of the receive buffer; skip empty lines."""
        while True:
            cut = [i for i in (self._rx.find(b"\r"), self._rx.find(b"\n")) if i >= 0]
            if not cut:
                return None
            end = min(cut)
            line = bytes(self._rx[:end])
            del self._rx[: end + 1]
            if line:
                self.transcript.append(TranscriptEntry(time.monotonic(), "rx", line))
                return line

    def _decode(self, line: bytes, context: str) -> str:
        if any(b < 0x20 or b > 0x7E for b in line):
            raise GarbledReplyError(
                f"{self.name} at {self.port}: garbled reply to {context or 'command'}: {line!r} "
                "(bytes outside printable ASCII; noise or wrong baud rate?)"
            )
        return line.decode("ascii")

    # -- exchanges --------------------------------------------------------------------------
    def send(self, command: str, *, idempotent: bool = True) -> None:
        """Send a command that has no reply; reopen and resend once if the port went away.

        A non-idempotent command (a relative move) is never resent: if the port fails the error
        propagates, because the device may or may not have executed it.
        """
        with self._lock:
            try:
                self.write_line(command)
            except DeviceDisconnectedError:
                if not idempotent:
                    raise
                self.reconnect()
                self.write_line(command)

    def query(
        self,
        command: str,
        parse: Callable[[str], T],
        *,
        idempotent: bool = True,
        timeout_s: float | None = None,
    ) -> T:
        """Send ``command``, read one line and return ``parse(line)``.

        ``parse`` raises :class:`ProtocolError` (or ``ValueError``) when the line is not a valid
        reply to ``command``. Idempotent queries are retried ``settings.retries`` times on a
        timeout, a garbled or malformed reply, and after reopening a port that went away.

        Raises
        ------
        DeviceTimeoutError, ProtocolError
            Still no valid reply after the last attempt; the message counts the attempts.
        DeviceDisconnectedError
            The port could not be reopened within ``settings.reconnect_timeout_s``.
        """
        with self._lock:
            return self._query(command, parse, idempotent, timeout_s)

    def _query(
        self,
        command: str,
        parse: Callable[[str], T],
        idempotent: bool,
        timeout_s: float | None,
    ) -> T:
        attempts = 1 + (self.settings.retries if idempotent else 0)
        last: Exception | None = None
        for attempt in range(1, attempts + 1):
            try:
                self.discard_input()
                self.write_line(command)
                line = self.read_line(timeout_s, context=repr(command))
                try:
                    return parse(line)
                except (ValueError, ProtocolError) as exc:
                    raise ProtocolError(
                        f"{self.name} at {self.port}: unexpected reply {line!r} to "
                        f"{command!r}: {exc}"
                    ) from exc
            except (DeviceTimeoutError, ProtocolError) as exc:
                last = exc
                _log.warning("%s: attempt %d/%d: %s", self.name, attempt, attempts, exc)
            except DeviceDisconnectedError as exc:
                last = exc
                _log.warning("%s: attempt %d/%d: %s", self.name, attempt, attempts, exc)
                if attempt < attempts:
                    self.reconnect()
        assert last is not None
        message = f"{last} (gave up after {attempts} attempt{'s' if attempts > 1 else ''})"
        raise type(last)(message) from last
