"""The service's side of the camera bridge: a camera on another process or PC over TCP.

:class:`BridgeCamera` is a :class:`~drivers.camera.source_camera.SourceCamera` whose source is
:class:`RemoteSource`, a client of :mod:`toftwin_camera_bridge` (the protocol is defined there,
once). When the bridge or its SDK dies, every call names the camera and the bridge and fails as
:class:`~drivers.camera.protocol.CameraError`; the next call connects again, so a campaign that
pauses on the error carries on when the bridge is back.
"""

from __future__ import annotations

import contextlib
import itertools
import queue
import socket
import threading
from typing import Any
from urllib.parse import urlsplit

from drivers.camera.source_camera import SourceCamera
from drivers.camera.wire import UseCase
from drivers.errors import DeviceInputError
from toftwin_camera_bridge import (
    PROTOCOL_VERSION,
    BridgeError,
    data_from_message,
    encode_message,
    read_message,
)

__all__ = ["BridgeCamera", "RemoteSource", "parse_bridge_url"]

#: how long a request waits for the bridge's reply
REQUEST_TIMEOUT_S = 10.0


def parse_bridge_url(url: str) -> tuple[str, int]:
    """``tcp://HOST:PORT`` as ``(host, port)``; :class:`DeviceInputError` naming ``camera``.

    >>> parse_bridge_url("tcp://labpc:5600")
    ('labpc', 5600)
    """
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme != "tcp" or not parts.hostname or port is None or not 1 <= port <= 65535:
        raise DeviceInputError("camera", f"got {url!r}; a camera bridge as tcp://HOST:PORT "
                                         "(PORT 1..65535)")
    return parts.hostname, port


class RemoteSource:
    """The bridge's camera source, seen through the protocol (the methods of
    :class:`toftwin_camera_bridge.RoyaleSource`); frames go to ``on_frame`` on the reader thread.

    A lost connection fails every pending and later request with a :class:`BridgeError` of kind
    ``disconnected`` naming the bridge, until a request connects again (``open`` with the
    camera and use case of before).
    """

    def __init__(self, url: str, on_frame: Any, *, connect_timeout_s: float = 5.0,
                 request_timeout_s: float = REQUEST_TIMEOUT_S,
                 world_url: str | None = None) -> None:
        self.url = url
        self.world_url = world_url
        self.host, self.port = parse_bridge_url(url)
        self.on_frame = on_frame
        self.connect_timeout_s = connect_timeout_s
        self.request_timeout_s = request_timeout_s
        self.callback_errors: list[str] = []
        self.camera_id: str | None = None
        self.streaming = False
        self.hello: dict[str, Any] = {}
        self.disconnect_reason: str | None = None
        self._identity: dict[str, Any] = {}
        self._use_case: str | None = None
        #: what the camera streams: royale's raw data or its processed depth (``open``)
        self.mode = "raw"
        self._sock: socket.socket | None = None
        self._ids = itertools.count(1)
        self._pending: dict[int, queue.Queue[dict[str, Any]]] = {}
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()

    # -- the connection -------------------------------------------------------------------------
    def _connect(self) -> socket.socket:
        try:
            sock = socket.create_connection((self.host, self.port),
                                            timeout=self.connect_timeout_s)
        except OSError as exc:
            raise BridgeError(f"camera bridge {self.url} cannot be reached ({exc}); is "
                              "toftwin-camera-bridge running there?", "disconnected") from exc
        sock.settimeout(None)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock, self.disconnect_reason = sock, None
        threading.Thread(target=self._read_loop, args=(sock,), name="bridge-reader",
                         daemon=True).start()
        self.hello = self._send(sock, "hello", protocol=PROTOCOL_VERSION)
        return sock

    def _read_loop(self, sock: socket.socket) -> None:
        reason = "the bridge closed the connection"
        try:
            while True:
                message, payload = read_message(sock)
                op = message["op"]
                if op == "reply":
                    waiting = self._pending.pop(message.get("id"), None)
                    if waiting is not None:
                        waiting.put(message)
                elif op == "frame":
                    self._frame(message, payload)
                elif op == "event" and message.get("kind") == "disconnected":
                    self.disconnect_reason = (f"the bridge reports camera "
                                              f"{message.get('camera')} disconnected: "
                                              f"{message.get('message')}")
                elif op == "event" and message.get("kind") == "error":
                    # lost frames on the bridge's side: a timeout's message names them
                    self.callback_errors.append(f"bridge: {message.get('message')}")
        except (ConnectionError, OSError) as exc:
            reason = f"connection lost ({exc})"
        except BridgeError as exc:
            reason = str(exc)
        self._lost(sock, reason)

    def _frame(self, message: dict[str, Any], payload: bytes) -> None:
        try:
            self.on_frame(data_from_message(message, payload))
        except Exception as exc:  # a garbled frame is counted, the stream goes on
            self.callback_errors.append(repr(exc))

    def _lost(self, sock: socket.socket, reason: str) -> None:
        with self._lock:
            if self._sock is sock:
                self._sock = None
                self.streaming = False
                self.disconnect_reason = self.disconnect_reason or reason
        with contextlib.suppress(OSError):
            sock.close()
        for waiting in list(self._pending.values()):
            waiting.put({"ok": False, "error": {"kind": "disconnected", "message": reason}})
        self._pending.clear()

    def _send(self, sock: socket.socket, op: str, **fields: Any) -> Any:
        request_id = next(self._ids)
        waiting: queue.Queue[dict[str, Any]] = queue.Queue(maxsize=1)
        self._pending[request_id] = waiting
        try:
            with self._send_lock:
                sock.sendall(encode_message({"op": op, "id": request_id, **fields}))
            reply = waiting.get(timeout=self.request_timeout_s)
        except queue.Empty:
            self._pending.pop(request_id, None)
            raise BridgeError(f"camera bridge {self.url}: no reply to {op!r} within "
                              f"{self.request_timeout_s:g} s", "disconnected") from None
        except OSError as exc:
            self._pending.pop(request_id, None)
            self._lost(sock, f"connection lost ({exc})")
            raise BridgeError(f"camera bridge {self.url}: {op!r} not sent, connection lost "
                              f"({exc})", "disconnected") from exc
        if not reply.get("ok"):
            error = reply.get("error") or {}
            raise BridgeError(f"camera bridge {self.url}: {error.get('message')}",
                              str(error.get("kind", "error")))
        return reply.get("result")

    def _request(self, op: str, **fields: Any) -> Any:
        sock = self._sock
        if sock is None:  # (re)connect and open the camera of before
            sock = self._connect()
            if op != "open" and self.camera_id is not None:
                self._identity = self._send(sock, "open", camera=self.camera_id,
                                            use_case=self._use_case, mode=self.mode)
                self._attach(sock)
        result = self._send(sock, op, **fields)
        if op == "open":
            self._attach(sock)
        return result

    def _attach(self, sock: socket.socket) -> None:
        """A simulated bridge films our simulated world (:mod:`drivers.sim.world_link`)."""
        if self.world_url is not None:
            self._send(sock, "attach_world", url=self.world_url)

    # -- the source's methods -------------------------------------------------------------------
    def describe(self) -> dict[str, Any]:
        return {"backend": f"bridge {self.url}", **{k: v for k, v in self.hello.items()
                                                     if k in ("royale", "bridge", "python")}}

    def list_cameras(self) -> list[str]:
        return list(self._request("list_cameras"))

    def open(self, camera_id: str | None = None, mode: str = "raw") -> dict[str, Any]:
        self.mode = mode
        self._identity = self._request("open", camera=camera_id, mode=mode)
        self.camera_id = self._identity.get("id") or camera_id
        return self.identity()

    def identity(self) -> dict[str, Any]:
        return {**self._identity, "bridge": self.url}

    def use_cases(self) -> list[str]:
        return list(self._identity.get("use_cases") or [])

    def set_use_case(self, name: str) -> None:
        self._request("use_case", name=name)
        self._use_case = name

    def set_exposure(self, exposure_us: int) -> None:
        self._request("exposure", us=int(exposure_us))

    def start(self) -> None:
        if not self.streaming:
            self._request("start")
            self.streaming = True

    def stop(self) -> None:
        if self.streaming:
            self.streaming = False
            self._request("stop")

    def is_connected(self) -> bool:
        return self._sock is not None and self.disconnect_reason is None

    def close(self) -> None:
        sock, self._sock = self._sock, None
        self.streaming = False
        if sock is not None:
            with contextlib.suppress(BridgeError, OSError):
                self._send(sock, "close")
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            with contextlib.suppress(OSError):
                sock.close()


class BridgeCamera(SourceCamera):
    """A pico flexx served by ``toftwin-camera-bridge`` at ``url`` (``tcp://HOST:PORT``).

    Parameters
    ----------
    url : str
        The bridge; :class:`~drivers.errors.DeviceInputError` naming ``camera`` if malformed.
    camera_id : str or None
        The camera's royale id at the bridge; its first camera when None.
    connect_timeout_s : float
        Longest wait for the bridge to accept a connection.
    world_url : str or None
        A simulated bridge (``toftwin camera-bridge --simulated``) films the simulated world
        served there (:class:`drivers.sim.world_link.WorldLinkServer`), attached at every
        connection.
    use_case, frame_timeout_s, queue_size, value_shift, mode
        As for :class:`~drivers.camera.source_camera.SourceCamera`.
    """

    backend = "bridge"

    def __init__(self, url: str, camera_id: str | None = None, *,
                 use_case: str | UseCase = "MODE_5_45FPS_500", frame_timeout_s: float = 2.0,
                 connect_timeout_s: float = 5.0, queue_size: int = 8, value_shift: int = 0,
                 world_url: str | None = None, mode: str = "raw") -> None:
        parse_bridge_url(url)
        super().__init__(camera_id, use_case=use_case, frame_timeout_s=frame_timeout_s,
                         queue_size=queue_size, value_shift=value_shift, mode=mode)
        self.url = url
        self.connect_timeout_s = connect_timeout_s
        self.world_url = world_url

    def _make_source(self) -> RemoteSource:
        return RemoteSource(self.url, self._on_frame, connect_timeout_s=self.connect_timeout_s,
                            world_url=self.world_url)

    def _who(self) -> str:
        return f"{super()._who()} at camera bridge {self.url}"
