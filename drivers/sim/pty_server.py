"""Serve a device simulator on a pseudo-terminal or a loopback TCP socket.

A :class:`DeviceServer` runs one line-oriented simulator (anything with ``handle_line(str) ->
list[str]`` and a ``reply_terminator``) in a background thread:

- ``transport="pty"``: ``os.openpty()``; the client opens a *stable symlink* to the slave side
  (``<link_dir>/<name>``), so a simulated unplug (fault ``disconnect``) can close the pty and a
  reconnect can re-point the same path at a fresh one - like a USB adapter coming back.
- ``transport="tcp"``: a listening socket on 127.0.0.1; clients use ``socket://127.0.0.1:<port>``.
  A new connection replaces the previous one.

Byte handling mirrors a UART device: input is framed on CR and/or LF, XON/XOFF bytes are
dropped, commands may arrive split across writes, empty lines are ignored; output to a client
that does not read is dropped rather than blocking the device. Link-level faults are applied
here: ``no-reply``, ``garbled``, ``truncated`` (per reply) and ``disconnect`` (per command).

:func:`serve` is the entry point of ``toftwin sim-device``: it prints the port path as the first
line of stdout (the solar simulator's shutter port as the second), flushes, and serves until
interrupted. ``python -m drivers.sim.pty_server turntable --fault stall`` does the same.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import logging
import os
import select
import shutil
import signal
import socket
import sys
import tempfile
import threading
import tty
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol, TextIO

from drivers.errors import DeviceInputError
from drivers.sim import SimClock
from drivers.sim.faults import SOLAR_FAULTS, TURNTABLE_FAULTS, FaultInjector, parse_fault
from drivers.sim.oriel import LampSupplySim, ShutterControllerSim, SolarRigSim
from drivers.sim.smc100 import Smc100Sim

__all__ = [
    "KINDS",
    "DeviceServer",
    "LineDevice",
    "LineFramer",
    "SimHandle",
    "serve",
    "start_simulator",
]

_log = logging.getLogger(__name__)

#: Simulator kinds :func:`serve` accepts, with the faults each accepts.
KINDS: dict[str, tuple[str, ...]] = {
    "turntable": TURNTABLE_FAULTS,
    "solar-simulator": SOLAR_FAULTS,
    "lamp": SOLAR_FAULTS,
    "shutter": SOLAR_FAULTS,
}

_XON_XOFF = b"\x11\x13"
_MAX_LINE = 512  # a longer line is noise; it is discarded, as a device's input buffer would


class LineDevice(Protocol):
    """What a simulator offers the server."""

    reply_terminator: bytes

    def handle_line(self, line: str) -> list[str]: ...


class LineFramer:
    """Accumulate received bytes and cut them into command lines.

    >>> f = LineFramer()
    >>> f.feed(b"1T"), f.feed(b"S\\r\\n\\r\\n1TP\\x11?\\r")
    ([], ['1TS', '1TP?'])
    """

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[str]:
        """Add received bytes; return the complete, non-empty lines."""
        self._buf.extend(b for b in data if b not in _XON_XOFF)
        lines: list[str] = []
        while True:
            cuts = [i for i in (self._buf.find(b"\r"), self._buf.find(b"\n")) if i >= 0]
            if not cuts:
                if len(self._buf) > _MAX_LINE:
                    self._buf.clear()
                return lines
            end = min(cuts)
            raw = bytes(self._buf[:end])
            del self._buf[: end + 1]
            if raw.strip():
                lines.append(raw.decode("ascii", errors="replace"))


# -- endpoints ------------------------------------------------------------------------------
class _PtyEndpoint:
    """A pty pair; the client-facing path is a symlink re-pointed at every (re)open."""

    def __init__(self, link_path: str) -> None:
        self.link_path = link_path
        self.master: int | None = None
        self.slave: int | None = None

    @property
    def address(self) -> str:
        return self.link_path

    def open(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line editing before the client configures the port
        os.set_blocking(master, False)
        self.master, self.slave = master, slave
        tmp = f"{self.link_path}.tmp{os.getpid()}"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, self.link_path)

    def close(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.link_path)
        for fd in (self.master, self.slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self.master = self.slave = None

    def fds(self) -> list[Any]:
        return [] if self.master is None else [self.master]

    def on_readable(self, fd: Any) -> bytes:
        assert self.master is not None
        try:
            return os.read(self.master, 4096)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:  # no client at the moment
                return b""
            raise

    def write(self, data: bytes) -> None:
        if self.master is None:
            return
        try:
            os.write(self.master, data)
        except (BlockingIOError, OSError) as exc:
            _log.debug("pty output dropped (%s)", exc)


class _TcpEndpoint:
    """A listening socket on the loopback interface; one client at a time."""

    def __init__(self, host: str, port: int) -> None:
        self.host = host
        self.port = port
        self.listener: socket.socket | None = None
        self.client: socket.socket | None = None

    @property
    def address(self) -> str:
        return f"socket://{self.host}:{self.port}"

    def open(self) -> None:
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind((self.host, self.port))
        listener.listen(4)
        self.port = listener.getsockname()[1]
        self.listener = listener

    def close(self) -> None:
        for sock in (self.client, self.listener):
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.close()
        self.client = self.listener = None

    def fds(self) -> list[Any]:
        return [s for s in (self.listener, self.client) if s is not None]

    def on_readable(self, fd: Any) -> bytes:
        if fd is self.listener and self.listener is not None:
            conn, _ = self.listener.accept()
            conn.settimeout(1.0)
            if self.client is not None:
                with contextlib.suppress(OSError):
                    self.client.close()
            self.client = conn
            return b""
        if self.client is None:
            return b""
        try:
            data = self.client.recv(4096)
        except OSError:
            data = b""
        if not data:
            with contextlib.suppress(OSError):
                self.client.close()
            self.client = None
        return data

    def write(self, data: bytes) -> None:
        if self.client is None:
            return
        try:
            self.client.sendall(data)
        except OSError as exc:
            _log.debug("tcp output dropped (%s)", exc)


# -- the server -----------------------------------------------------------------------------
class DeviceServer:
    """Run one simulated device on a pty or a TCP socket in a background thread.

    Parameters
    ----------
    device : LineDevice
        The simulator (``handle_line`` and ``reply_terminator``).
    faults : FaultInjector
        Armed faults; the server consumes ``no-reply``, ``garbled``, ``truncated`` and
        ``disconnect``. Tests inject more at run time through :meth:`inject`.
    transport : {"pty", "tcp"}
        Where to serve.
    name : str
        Name of the symlink (pty) and of log lines.
    link_dir : str or None
        Directory for the pty symlink; a temporary directory when ``None``.
    host, port : str, int
        TCP address (port 0 = any free port).
    """

    def __init__(
        self,
        device: LineDevice,
        faults: FaultInjector | None = None,
        *,
        transport: str = "pty",
        name: str = "device",
        link_dir: str | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
    ) -> None:
        if transport not in ("pty", "tcp"):
            raise DeviceInputError("transport", f"got {transport!r}; 'pty' or 'tcp'")
        self.device = device
        self.faults = faults if faults is not None else FaultInjector()
        self.name = name
        self._own_dir: str | None = None
        if transport == "pty":
            if link_dir is None:
                link_dir = self._own_dir = tempfile.mkdtemp(prefix="toftwin-sim-")
            self._endpoint: _PtyEndpoint | _TcpEndpoint = _PtyEndpoint(os.path.join(link_dir, name))
        else:
            self._endpoint = _TcpEndpoint(host, port)
        self._framer = LineFramer()
        self._stop = threading.Event()
        self._disconnect_request: float | None = None
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self.disconnects = 0

    @property
    def port(self) -> str:
        """The device path (pty symlink) or ``socket://`` URL a client opens."""
        return self._endpoint.address

    def start(self) -> str:
        """Open the endpoint and start serving; return :attr:`port`."""
        self._endpoint.open()
        self._thread = threading.Thread(target=self._run, name=f"sim-{self.name}", daemon=True)
        self._thread.start()
        return self.port

    def stop(self) -> None:
        """Stop serving and release the endpoint (and the temporary directory)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self._endpoint.close()
        if self._own_dir is not None:
            shutil.rmtree(self._own_dir, ignore_errors=True)
            self._own_dir = None

    def __enter__(self) -> DeviceServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def inject(self, fault: str, **params: float) -> None:
        """Arm a fault at run time (``"garbled:1"``, ``"stall"``, ...)."""
        self.faults.inject(fault, **params)

    def disconnect(self, downtime_s: float = 0.5) -> None:
        """Unplug now: close the endpoint and reopen it after ``downtime_s`` seconds."""
        with self._lock:
            self._disconnect_request = downtime_s

    # -- loop ---------------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                downtime, self._disconnect_request = self._disconnect_request, None
            if downtime is not None:
                self._unplug(downtime)
                continue
            fds = self._endpoint.fds()
            if not fds:
                self._stop.wait(0.05)
                continue
            try:
                readable, _, _ = select.select(fds, [], [], 0.05)
            except (OSError, ValueError):
                continue
            for fd in readable:
                try:
                    data = self._endpoint.on_readable(fd)
                except OSError as exc:
                    _log.warning("%s: read error %s", self.name, exc)
                    continue
                if data:
                    self._handle_bytes(data)

    def _unplug(self, downtime_s: float) -> None:
        _log.info("%s: disconnect for %.3g s", self.name, downtime_s)
        self.disconnects += 1
        self._endpoint.close()
        self._framer = LineFramer()
        if self._stop.wait(downtime_s):
            return
        self._endpoint.open()

    def _handle_bytes(self, data: bytes) -> None:
        for line in self._framer.feed(data):
            spec = self.faults.fire("disconnect")
            if spec is not None:
                with self._lock:
                    self._disconnect_request = float(spec.params.get("downtime_s", 0.5))
                return  # this command and the rest of the buffer are lost in the unplug
            try:
                replies = self.device.handle_line(line)
            except Exception:  # a simulator bug must not kill the port; log and go on
                _log.exception("%s: simulator failed on %r", self.name, line)
                continue
            for reply in replies:
                self._send_reply(reply)

    def _send_reply(self, reply: str) -> None:
        data = reply.encode("ascii", errors="replace")
        if self.faults.fire("no-reply") is not None:
            return
        if self.faults.fire("truncated") is not None:
            self._endpoint.write(data[: max(1, len(data) // 2)])
            return
        if self.faults.fire("garbled") is not None:
            data = bytes(b ^ 0x80 for b in data)
        self._endpoint.write(data + self.device.reply_terminator)


# -- assembling simulators ------------------------------------------------------------------
@dataclass
class SimHandle:
    """Running simulator(s) of one kind: the model objects and their servers."""

    kind: str
    servers: dict[str, DeviceServer]
    models: dict[str, Any] = field(default_factory=dict)
    link_dir: str | None = None  # temporary directory of the pty symlinks, removed at stop

    @property
    def ports(self) -> list[str]:
        """Client port of every server, in print order (lamp before shutter)."""
        return [server.port for server in self.servers.values()]

    def stop(self) -> None:
        """Stop every server and remove the temporary symlink directory."""
        for server in self.servers.values():
            server.stop()
        if self.link_dir is not None:
            shutil.rmtree(self.link_dir, ignore_errors=True)
            self.link_dir = None

    def __enter__(self) -> SimHandle:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


#: the model of each kind served on one port (the solar simulator's two share a SolarRigSim)
_ONE_PORT_MODELS: dict[str, Callable[..., Any]] = {
    "turntable": Smc100Sim,
    "lamp": LampSupplySim,
    "shutter": ShutterControllerSim,
}


def _injector(kind: str, faults: Iterable[str]) -> FaultInjector:
    allowed = KINDS[kind]
    return FaultInjector([parse_fault(text, allowed) for text in faults])


def start_simulator(
    kind: str,
    faults: Iterable[str] = (),
    *,
    transport: str = "pty",
    instant: bool = False,
    time_scale: float = 1.0,
    link_dir: str | None = None,
) -> SimHandle:
    """Build the simulator(s) for ``kind`` and start serving them; return a :class:`SimHandle`.

    Kinds: ``"turntable"`` (one port), ``"solar-simulator"`` (two ports: lamp supply then
    shutter controller, sharing one :class:`SolarRigSim`), ``"lamp"``, ``"shutter"``. Every
    port of a kind gets its own injector armed with ``faults``.
    """
    if kind not in KINDS:
        raise DeviceInputError("kind", f"got {kind!r}; one of {', '.join(KINDS)}")
    faults = list(faults)
    own_dir = None
    if transport == "pty" and link_dir is None:
        link_dir = own_dir = tempfile.mkdtemp(prefix="toftwin-sim-")
    clock = SimClock(time_scale=time_scale, instant=instant)
    models: dict[str, Any] = {}
    if kind == "solar-simulator":
        lamp_faults, shutter_faults = _injector(kind, faults), _injector(kind, faults)
        rig = SolarRigSim(clock=clock, lamp_faults=lamp_faults, shutter_faults=shutter_faults)
        models.update(rig=rig, lamp=rig.lamp, shutter=rig.shutter)
        ports: dict[str, tuple[Any, FaultInjector]] = {
            "lamp": (rig.lamp, lamp_faults), "shutter": (rig.shutter, shutter_faults)
        }
    else:
        injector = _injector(kind, faults)
        model = _ONE_PORT_MODELS[kind](clock=clock, faults=injector)
        models[kind] = model
        ports = {kind: (model, injector)}
    servers = {
        name: DeviceServer(sim, port_faults, transport=transport, name=name, link_dir=link_dir)
        for name, (sim, port_faults) in ports.items()
    }
    handle = SimHandle(kind, servers, models, own_dir)
    try:
        for server in servers.values():
            server.start()
    except Exception:
        handle.stop()
        raise
    return handle


def serve(
    kind: str,
    faults: list[str],
    *,
    transport: str = "pty",
    instant: bool = False,
    time_scale: float = 1.0,
    link_dir: str | None = None,
    out: TextIO | None = None,
    stop_event: threading.Event | None = None,
) -> None:
    """Run the simulator for ``kind`` until interrupted (Ctrl-C, SIGTERM, or ``stop_event``).

    Prints the client port as the first line of ``out`` (stdout by default) and flushes; for
    ``"solar-simulator"`` the lamp supply's port is the first line and the shutter controller's
    the second. Faults are names as in :mod:`drivers.sim.faults` (``["stall"]``,
    ``["garbled:1@3"]``).
    """
    out = sys.stdout if out is None else out
    stop = stop_event if stop_event is not None else threading.Event()
    handle = start_simulator(
        kind,
        faults,
        transport=transport,
        instant=instant,
        time_scale=time_scale,
        link_dir=link_dir,
    )
    previous: dict[int, Any] = {}
    if threading.current_thread() is threading.main_thread():
        # Ctrl-C and SIGTERM both just set the event: a KeyboardInterrupt raised wherever the
        # main thread happens to be (inside Event.wait's lock, say) could leave the shutdown
        # half done, and a loaded machine showed the SIGINT path hanging where SIGTERM did not.
        for signum in (signal.SIGINT, signal.SIGTERM):
            previous[signum] = signal.signal(signum, lambda *_: stop.set())
    try:
        for port in handle.ports:
            print(port, file=out)
        out.flush()
        while not stop.wait(0.2):
            pass
    except KeyboardInterrupt:  # a SIGINT before the handler was installed
        pass
    finally:
        handle.stop()
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def main(argv: list[str] | None = None) -> int:
    """``python -m drivers.sim.pty_server KIND [--fault NAME]...``"""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("kind", choices=sorted(KINDS))
    parser.add_argument("--fault", action="append", default=[], help="name[:count][@skip]")
    parser.add_argument("--transport", choices=("pty", "tcp"), default="pty")
    parser.add_argument("--instant", action="store_true", help="complete motions at once")
    parser.add_argument("--time-scale", type=float, default=1.0)
    parser.add_argument("--link-dir", default=None, help="directory for the pty symlink")
    args = parser.parse_args(argv)
    try:
        serve(
            args.kind,
            args.fault,
            transport=args.transport,
            instant=args.instant,
            time_scale=args.time_scale,
            link_dir=args.link_dir,
        )
    except DeviceInputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
