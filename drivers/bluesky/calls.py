"""Our drivers' blocking calls from ophyd-async's event loop: in a worker thread, under a lock.

The drivers (:class:`~drivers.turntable.Turntable`, :class:`~drivers.solar_simulator.
SolarSimulator`, the camera) block on their serial port or USB transfer; an ophyd-async device
runs in the Bluesky RunEngine's event loop, which must never block. :class:`DriverCalls` runs
each call in a worker thread (:func:`asyncio.to_thread`) while holding a lock, so that the
RunEngine reading one device while another moves never interleaves two exchanges on one
device, and (given a :class:`drivers.rig.Rig`'s ``hold``) never with the service's own use of
the rig.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["DriverCalls", "Hold"]

T = TypeVar("T")
#: what :class:`DriverCalls` holds around every call: ``hold()`` returns a context manager
#: (a :class:`threading.Lock`'s, or :meth:`drivers.rig.Rig.hold`)
Hold = Callable[[], contextlib.AbstractContextManager[Any]]


class DriverCalls:
    """Awaitable driver calls: ``await calls(driver.position_deg)``.

    Parameters
    ----------
    hold : callable or None
        Context manager factory held around every call (in the worker thread). None: a lock of
        this object's own. Devices of one rig pass the rig's :meth:`~drivers.rig.Rig.hold`, so
        their calls are serialised with each other and with every other user of the rig.
    """

    def __init__(self, hold: Hold | None = None) -> None:
        if hold is None:
            lock = threading.Lock()  # a lock is its own context manager
            hold = lambda: lock  # noqa: E731
        self.hold: Hold = hold

    def _locked(self, fn: Callable[..., T], args: tuple[Any, ...]) -> T:
        with self.hold():
            return fn(*args)

    async def __call__(self, fn: Callable[..., T], *args: Any) -> T:
        """``fn(*args)`` in a worker thread under :attr:`hold`; its result or its exception."""
        return await asyncio.to_thread(self._locked, fn, args)

    async def unlocked(self, fn: Callable[..., T], *args: Any) -> T:
        """``fn(*args)`` in a worker thread without the lock: for a stop, which must not wait
        for the move it stops (the drivers' transports serialise the bytes themselves)."""
        return await asyncio.to_thread(fn, *args)
