"""Server-sent events of a background job's status: the one loop behind every ``.../events``.

A route (``GET /campaigns/{id}/events``, ``GET /calibrations/{id}/events``) takes a stream slot
in its dependency (404 for an unknown job and 503 when ``sse_max_streams`` are open, both before
the stream starts) and hands :func:`status_events` what differs between jobs: a cheap key that
changes whenever the status does, the status itself (as ``GET`` returns it), the final states
and the event id. The loop asks for the key every ``sse_interval_s`` (in a worker thread: both
read the database) and sends an event ``status`` when it changed, never an unchanged status
again; it ends after a final state or ``sse_max_s`` and gives the slot back however it ends
(a final state, the time limit, the client gone). FastAPI sends the keep-alive comments.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable, Collection, Hashable
from typing import Any

from fastapi.concurrency import run_in_threadpool
from fastapi.sse import ServerSentEvent

from service.api.deps import StreamSlots
from service.settings import Settings

#: a status and how many were sent before it -> the event's ``id``
EventId = Callable[[dict[str, Any], int], str]


def numbered(status: dict[str, Any], sent: int) -> str:
    """The event id by default: 1 for the first status sent, 2 for the next, ..."""
    return str(sent + 1)


async def status_events(
    key: Callable[[], Hashable],
    status: Callable[[], dict[str, Any]],
    *,
    terminal: Collection[str],
    settings: Settings,
    slots: StreamSlots,
    event_id: EventId = numbered,
) -> AsyncIterator[ServerSentEvent]:
    """The job's status whenever ``key()`` changes, until ``status()["state"]`` is in
    ``terminal`` or the stream has been open ``settings.sse_max_s``; gives back the slot the
    route took from ``slots``. A browser reconnects after four intervals (``retry``)."""
    retry_ms = int(settings.sse_interval_s * 4000)
    try:
        deadline = time.monotonic() + settings.sse_max_s
        last = None
        last_sent: dict[str, Any] | None = None
        sent = 0
        while True:
            now = await run_in_threadpool(key)
            if now != last:
                last = now
                current = await run_in_threadpool(status)
                # the key and the status are read at two moments: a status read after a later
                # change may already be the one the next key announces (never send it twice)
                if current != last_sent:
                    last_sent = current
                    yield ServerSentEvent(data=current, event="status",
                                          id=event_id(current, sent), retry=retry_ms)
                    sent += 1
                if current["state"] in terminal:
                    return
            if time.monotonic() > deadline:
                return
            await asyncio.sleep(settings.sse_interval_s)
    finally:
        slots.give_back()
