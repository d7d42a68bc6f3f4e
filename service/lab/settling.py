"""The service waits for the turntable's ringing to decay before it captures (issue 27).

A calibration's ``turntable.settling`` (:class:`sim_core.twin_file.TurntableSettling`) says how
the table rings after a move; the controller cannot tell (its encoder sits on the motor:
:mod:`drivers.sim.smc100`), so the service waits after every move until the ringing's envelope
is below :data:`SETTLE_TOLERANCE_DEG` (:func:`sim_core.settling.settle_time_s`): the turntable
driver's own post-move wait (``Turntable.settle_s``) is raised to it while the service captures.
A campaign that asks for motion (capture while turning) does not wait.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

from calibration.rig_settling import ringing_bound
from sim_core.settling import settle_time_s
from sim_core.subframes import MOTION_TOLERANCE_DEG
from sim_core.twin_file import TwinParameters

__all__ = ["SETTLE_TOLERANCE_DEG", "settle_wait_s", "settled_moves", "unsettled_moves"]

#: the ringing the service accepts in a capture [deg]: the same as a table "not moving" during a
#: frame (below it a frame is rendered once: :data:`sim_core.subframes.MOTION_TOLERANCE_DEG`)
SETTLE_TOLERANCE_DEG = MOTION_TOLERANCE_DEG


def settle_wait_s(calibration: TwinParameters | None) -> float:
    """Seconds to wait after a move for ``calibration``'s turntable (0 without one): until its
    ringing's bound (:func:`calibration.rig_settling.ringing_bound`: the fitted amplitude
    raised for the move end the calibration did not see) has decayed below
    :data:`SETTLE_TOLERANCE_DEG`, and at least its ``rest_after_move_s`` (a table seen ringing
    whose ringing the calibration did not determine).

    >>> from sim_core.twin_file import parse_calibration
    >>> cal = parse_calibration({"turntable": {"settling": {
    ...     "amplitude_deg": 0.1, "frequency_hz": 4.0, "damping_ratio": 0.1}}})
    >>> round(settle_wait_s(cal), 3), settle_wait_s(None)
    (1.958, 0.0)
    >>> settle_wait_s(parse_calibration({"turntable": {"rest_after_move_s": 120.0}}))
    120.0
    """
    if calibration is None:
        return 0.0
    table = calibration.turntable
    ringing_s = (0.0 if table.settling is None
                 else settle_time_s(ringing_bound(table.settling), SETTLE_TOLERANCE_DEG))
    return max(ringing_s, table.rest_after_move_s or 0.0)


@contextlib.contextmanager
def settled_moves(rig: Any, calibration: TwinParameters | None,
                  motion: bool = False) -> Iterator[float]:
    """Inside, every move of ``rig``'s turntable waits for ``calibration``'s settling before it
    returns (the driver's ``settle_s`` raised to :func:`settle_wait_s`, never lowered); the
    driver's own wait is restored on exit. ``motion=True`` (a campaign that captures while
    turning) leaves it as it is. Yields the wait in force [s].
    """
    turntable = rig.turntable
    base_s = getattr(turntable, "settle_s", None)
    if base_s is None or motion:  # a turntable without a post-move wait, or motion wanted
        yield 0.0 if base_s is None else base_s
        return
    turntable.settle_s = max(base_s, settle_wait_s(calibration))
    try:
        yield turntable.settle_s
    finally:
        turntable.settle_s = base_s


@contextlib.contextmanager
def unsettled_moves(rig: Any) -> Iterator[None]:
    """Inside, a move of ``rig``'s turntable returns as soon as the controller reports it done,
    with no post-move wait at all (the driver's ``settle_s`` 0): the settling stage captures
    the table while it still rings (:mod:`calibration.rig_settling`). The wait in force before
    is restored on exit."""
    turntable = rig.turntable
    base_s = getattr(turntable, "settle_s", None)
    if base_s is None:  # a turntable without a post-move wait: nothing to lift
        yield
        return
    turntable.settle_s = 0.0
    try:
        yield
    finally:
        turntable.settle_s = base_s
