"""The watch that resumes a campaign paused by a lost camera (:mod:`service.lab.camera_return`):
it resumes at the first frame, never after the operator acted, and stops when told.
The service end to end: tests/service/api/test_camera_bridge.py."""

from __future__ import annotations

import threading
import time

import pytest

from drivers.camera.protocol import CameraLostError
from drivers.errors import DeviceError
from service.errors import ConflictError
from service.lab.camera_return import CameraReturnWatch

pytestmark = pytest.mark.timeout(30)


class _Lab:
    """A campaign's stored state and a camera that is away for ``away`` probes."""

    def __init__(self, away: int, resume_refusals: int = 0) -> None:
        self.state, self.error = "paused", "lost"
        self.away = away
        self.probes = 0
        self.resume_refusals = resume_refusals
        self.resumed = threading.Event()

    def still_paused(self, cid: str, error: str) -> bool:
        return self.state == "paused" and self.error == error

    def probe(self) -> None:
        self.probes += 1
        if self.probes <= self.away:
            raise CameraLostError("camera sim-0001 at camera bridge tcp://x:1: cannot be reached")

    def resume(self, cid: str) -> None:
        if self.resume_refusals:
            self.resume_refusals -= 1
            raise ConflictError("calibration c1 is running and holds the rig")
        self.state = "running"
        self.resumed.set()


def _watch(lab: _Lab, within_s: float = 10.0) -> CameraReturnWatch:
    return CameraReturnWatch(lab.still_paused, lab.probe, lab.resume, within_s, 0.01)


def test_the_campaign_resumes_at_the_first_frame_once_the_rig_is_free():
    lab = _Lab(away=3, resume_refusals=2)
    watch = _watch(lab)
    watch.start("c" * 32, "lost")
    assert lab.resumed.wait(5.0)
    assert lab.probes == 6  # three away, then back: refused twice (the rig held), resumed
    watch.close()


def test_the_watch_leaves_a_campaign_the_operator_acted_on():
    lab = _Lab(away=10**9)
    watch = _watch(lab)
    watch.start("c" * 32, "lost")
    time.sleep(0.1)
    lab.state = "cancelled"
    watch.close()
    assert not lab.resumed.is_set() and lab.state == "cancelled"
    lab2 = _Lab(away=0)
    lab2.error = "another fault since"  # paused again, for another reason: not this watch's
    watch2 = _watch(lab2)
    watch2.start("c" * 32, "lost")
    time.sleep(0.1)
    watch2.close()
    assert lab2.probes == 0 and not lab2.resumed.is_set()


@pytest.mark.parametrize("within_s", [0.0, 0.05])
def test_the_watch_ends_after_its_time_or_when_off(within_s):
    lab = _Lab(away=10**9)
    watch = _watch(lab, within_s)
    watch.start("c" * 32, "lost")
    time.sleep(0.3)
    probes = lab.probes
    time.sleep(0.1)
    assert lab.probes == probes  # no longer probing
    assert probes == 0 if within_s == 0.0 else probes >= 1
    watch.close()
    assert not lab.resumed.is_set()


def test_a_closed_watch_starts_nothing_and_a_lost_camera_is_a_disconnection():
    lab = _Lab(away=0)
    watch = _watch(lab)
    watch.close()
    watch.start("c" * 32, "lost")
    time.sleep(0.1)
    assert lab.probes == 0
    assert issubclass(CameraLostError, DeviceError)
    assert issubclass(CameraLostError, ConnectionError)
