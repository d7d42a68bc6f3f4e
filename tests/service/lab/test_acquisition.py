"""Acquisition (issue 26): any capture plan run on the simulated rig, in order, with progress and
a stop before the next capture."""

from __future__ import annotations

from collections.abc import Sequence

import pytest

from calibration.capture_plan import CapturePlan, CaptureStep, mount
from calibration.rig_sequence import RigCalibrationPlan, rig_capture_plan
from drivers.sim.rig import simulated_rig
from service.lab.acquisition import acquire
from sim_core.errors import InvalidInputError
from sim_core.scene_spec import ObjectSpec, load_scene_spec
from tests.sim_core.scenes import EXAMPLES

PLATE = ObjectSpec.model_validate({"name": "plate", "material": "white-matte-tile",
                                   "mesh": {"kind": "rectangle", "size_m": [0.2, 0.2]}})


class RecordingOperator:
    """The operator's part: records what it was asked to mount."""

    def __init__(self, events: list) -> None:
        self.events = events

    def mount(self, objects: Sequence[ObjectSpec] | None, instruction: str) -> None:
        self.events.append(("mount", None if objects is None else [o.name for o in objects]))


def _plan(restore: bool = False) -> CapturePlan:
    steps = (mount([PLATE], "mount the plate"),
             CaptureStep("a", 10.0, 0.0, False, 1, message="a at 10 deg"),
             CaptureStep("b", 20.0, 0.0, False, 3, keep_frames=True, message="b at 20 deg"),
             CaptureStep("c", 30.0, 0.0, False, 1, message="c at 30 deg"))
    if restore:
        return CapturePlan(steps, restore=mount(None, "the test object again"))
    return CapturePlan((*steps, mount(None, "the test object again")))


@pytest.fixture(scope="module")
def rig():
    with simulated_rig(seed=3) as r:
        yield r


def test_mounts_and_captures_run_in_the_plans_order_with_progress_before_each_capture(rig):
    events: list = []
    captures = acquire(rig, RecordingOperator(events), _plan(),
                       lambda done, total, message: events.append((done, total, message)))
    assert events == [("mount", ["plate"]), (0, 3, "a at 10 deg"), (1, 3, "b at 20 deg"),
                      (2, 3, "c at 30 deg"), ("mount", None)]
    assert list(captures) == ["a", "b", "c"]
    assert [c.turntable_angle_deg for c in captures.values()] == [10.0, 20.0, 30.0]
    assert [c.n_frames for c in captures.values()] == [1, 3, 1]
    assert len(captures["b"].frames) == 3 and captures["a"].frames == ()


def test_a_stop_is_raised_before_the_next_capture_and_the_restore_mount_still_happens(rig):
    """A job's cancel raises from its progress callback: nothing more is captured."""
    events: list = []

    class CancelledError(Exception):
        pass

    def progress(done: int, total: int, message: str) -> None:
        if done == 1:
            raise CancelledError(f"after {done} of {total} captures")

    with pytest.raises(CancelledError, match="after 1 of 3 captures"):
        acquire(rig, RecordingOperator(events), _plan(restore=True), progress)
    assert rig.state().turntable_angle_deg == 10.0  # b was never moved to
    assert events == [("mount", ["plate"]), ("mount", None)]


def test_a_progress_callback_that_raises_stops_before_the_capture(rig):
    class CancelledError(Exception):
        pass

    def progress(done: int, total: int, message: str) -> None:
        if done == 2:
            raise CancelledError

    with pytest.raises(CancelledError):
        acquire(rig, RecordingOperator([]), _plan(), progress)
    assert rig.state().turntable_angle_deg == 20.0  # c was never moved to


def test_a_plan_names_each_capture_once():
    with pytest.raises(InvalidInputError, match="'a' is planned twice"):
        CapturePlan((CaptureStep("a", 0.0, 0.0, False, 1), CaptureStep("a", 5.0, 0.0, False, 1)))


def test_the_rig_sequences_plan_captures_what_it_counts_in_the_order_it_fits():
    spec = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
    plan = RigCalibrationPlan(fixtures=RigCalibrationPlan().fixtures[:2],
                              sweep_deg=(-10.0, 0.0, 10.0))
    cp = rig_capture_plan(plan, spec)
    assert cp.n_captures == 2 * 3 + 2 + 3 + 1
    mounts = [s.instruction for s in cp.steps if not isinstance(s, CaptureStep)]
    assert mounts[0].endswith(plan.fixtures[0].instruction)
    assert mounts[1].endswith(plan.fixtures[1].instruction)
    assert mounts[2].endswith(plan.fixtures[0].instruction)  # the noise stacks' board
    assert mounts[3] == "mount the test object again"
    assert [s.name for s in cp.captures][6:] == ["noise/dark", "noise/solar", "solar/0",
                                                 "solar/1", "solar/2", "solar/3"]
    assert [s.solar_suns for s in cp.captures][8:] == [0.0, *plan.solar_levels_suns]
