"""A campaign paused by a lost camera resumes by itself when the camera is back (issue 28).

The camera of a real lab is reached through the camera bridge (``toftwin_camera_bridge``) or
PMD's SDK; either may die and come back (the bridge restarted, the camera plugged in again)
while a campaign runs. The campaign pauses with the driver's message, which names the camera
and the bridge (:class:`drivers.camera.protocol.CameraLostError`), and a watch starts: every
``camera_return_poll_s`` it takes one frame through the rig (the camera's driver reconnects on
its own: :class:`drivers.camera.bridge_client.RemoteSource`), and at the first frame delivered
it resumes the campaign, which does only the units still missing (:mod:`service.lab.runner`).
The watch ends without resuming when the operator acts first (the campaign is no longer paused
with that error: resumed, cancelled), when another job holds the rig at that moment (tried
again at the next poll), after ``camera_return_s``, or when the service shuts down.

Every other device fault (a turntable that stalled, a lamp that went out) still waits for the
operator: those need a person at the rig; a camera coming back is a fact the service can check.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from drivers.errors import DeviceError
from service.errors import ConflictError, UnavailableError

__all__ = ["CameraReturnWatch"]

_log = logging.getLogger(__name__)


class CameraReturnWatch:
    """Watches for a lost camera and resumes the campaign it paused (module docstring).

    Parameters
    ----------
    still_paused : callable
        ``still_paused(campaign_id, error)``: whether the campaign is still paused with the
        error the watch was started for (the operator has not acted).
    probe : callable
        Takes one frame through the rig; raises a :class:`DeviceError` while the camera is
        away, a :class:`ConflictError` while another job holds the rig.
    resume : callable
        ``resume(campaign_id)``: resumes the campaign (a :class:`ConflictError` when it cannot
        now: tried again at the next poll).
    within_s, poll_s : float
        How long to watch, and how often to try [s].
    """

    def __init__(self, still_paused: Callable[[str, str], bool], probe: Callable[[], None],
                 resume: Callable[[str], None], within_s: float, poll_s: float) -> None:
        self.still_paused = still_paused
        self.probe = probe
        self.resume = resume
        self.within_s = within_s
        self.poll_s = poll_s
        self._closed = threading.Event()
        self._threads: list[threading.Thread] = []

    def start(self, campaign_id: str, error: str) -> None:
        """Watch for the camera that paused ``campaign_id`` with ``error`` (in a thread)."""
        if self.within_s <= 0.0 or self._closed.is_set():
            return
        thread = threading.Thread(target=self._watch, args=(campaign_id, error),
                                  name=f"camera-return-{campaign_id[:8]}", daemon=True)
        self._threads = [t for t in self._threads if t.is_alive()] + [thread]
        thread.start()

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop every watch (the service shuts down); waits up to ``timeout_s`` for them."""
        self._closed.set()
        for thread in self._threads:
            thread.join(timeout_s)

    def _watch(self, campaign_id: str, error: str) -> None:
        try:
            self._watch_until_back(campaign_id, error)
        except Exception:  # a bug or a broken database: logged, the operator resumes
            _log.exception("campaign %s: the watch for its camera failed", campaign_id)

    def _watch_until_back(self, campaign_id: str, error: str) -> None:
        deadline = time.monotonic() + self.within_s
        while not self._closed.wait(self.poll_s):
            if time.monotonic() > deadline:
                _log.info("campaign %s: the camera did not come back within %g s; the "
                          "operator resumes", campaign_id, self.within_s)
                return
            try:
                if not self.still_paused(campaign_id, error):
                    return  # the operator acted first
                self.probe()
            except (DeviceError, ConflictError, UnavailableError) as exc:
                _log.debug("campaign %s: camera not back yet: %s", campaign_id, exc)
                continue
            try:
                self.resume(campaign_id)
            except (ConflictError, UnavailableError) as exc:  # e.g. resumed a moment ago
                _log.info("campaign %s: not resumed after the camera came back: %s",
                          campaign_id, exc)
                if not self.still_paused(campaign_id, error):
                    return
                continue
            _log.warning("campaign %s: the camera is back; resumed", campaign_id)
            return
