"""Acquisition (issue 26): any capture plan run on the simulated rig, in order, with progress and
a stop before the next capture."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import pytest

from calibration.capture_plan import CapturePlan, CaptureStep, MountStep, WaitStep, mount
from calibration.rig_sequence import SETTLING_REST_WAIT_S, RigCalibrationPlan, rig_capture_plan
from drivers.rig import Rig
from drivers.sim.rig import simulated_rig
from drivers.sim.world import SimulatedWorld
from service.lab.acquisition import acquire
from sim_core.errors import InvalidInputError
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene_spec import ObjectSpec, load_scene_spec, parse_scene_spec
from sim_core.twin_file import parse_reality
from sim_core.warmup import illumination_temperature_c
from tests.calibration.test_warmup import WALL
from tests.sim_core.scenes import EXAMPLES

WARMUP = {"illumination_start_c": 25.0, "illumination_end_c": 45.0, "time_constant_s": 600.0,
          "depth_drift_mm_per_c": 0.4}
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
    # the warm-up stage first: the first fixture mounted once, captures with waits between
    n_warm = plan.warmup_captures
    assert cp.n_captures == n_warm + 2 + 2 * 3 + 2 + 3 + 1
    assert [s.name for s in cp.captures][:n_warm] == [f"warmup/{i}" for i in range(n_warm)]
    assert all(c.keep_frames and c.turntable_angle_deg == 0.0 for c in cp.captures[:n_warm])
    # the pauses between warm-up captures, the first one's rest after its move, the settling
    # stage's wait for the table
    assert cp.waited_s == (n_warm - 1) * plan.warmup_interval_s + 2 * SETTLING_REST_WAIT_S
    assert cp.captures[0].rest_s == SETTLING_REST_WAIT_S
    assert all(c.rest_s == 0.0 for c in cp.captures[1:])
    assert isinstance(cp.steps[2], WaitStep) and cp.steps[1].name == "warmup/0"
    # then the settling stage: a move from the warm-up's angle, frames at once after it, a
    # wait, and frames at rest at the same angle (the board's pixels and yaw noise there)
    moved, rest = cp.captures[n_warm:n_warm + 2]
    assert (rest.name, moved.name) == ("settling/rest", "settling/moved")
    assert rest.settle and not moved.settle and moved.keep_frames and rest.keep_frames
    assert moved.turntable_angle_deg - cp.captures[n_warm - 1].turntable_angle_deg == (
        plan.settling_move_deg)
    assert rest.turntable_angle_deg == moved.turntable_angle_deg
    i = cp.steps.index(moved)
    assert isinstance(cp.steps[i + 1], WaitStep) and cp.steps[i + 2] == rest
    cold = rig_capture_plan(dataclasses.replace(plan, warmup_captures=0, settling_frames=0),
                            spec)
    assert cp.captures[n_warm + 2:] == cold.captures and cold.waited_s == 0.0
    assert [s for s in cp.steps if isinstance(s, MountStep)] == [
        s for s in cold.steps if isinstance(s, MountStep)]
    cp = cold
    mounts = [s.instruction for s in cp.steps if not isinstance(s, CaptureStep)]
    assert mounts[0].endswith(plan.fixtures[0].instruction)
    assert mounts[1].endswith(plan.fixtures[1].instruction)
    assert mounts[2].endswith(plan.fixtures[0].instruction)  # the noise stacks' board
    assert mounts[3] == "mount the test object again"
    assert [s.name for s in cp.captures][6:] == ["noise/dark", "noise/solar", "solar/0",
                                                 "solar/1", "solar/2", "solar/3"]
    assert [s.solar_suns for s in cp.captures][8:] == [0.0, *plan.solar_levels_suns]


def test_a_wait_lets_the_simulated_labs_clock_run_so_the_illumination_warms_between_captures():
    """The plan's wait (a real rig's sleep) advances the simulated lab's clock: the capture after
    it reports the temperature the reality's warm-up has reached by then."""
    world = SimulatedWorld(parse_scene_spec(WALL), ".", RenderRequest(
        RenderSettings(integrator="direct", spp=1), effects="auto"), reality=parse_reality(
        {"camera": {"temperature": WARMUP}}))
    events: list = []
    plan = CapturePlan((CaptureStep("cold", 0.0, 0.0, False, 2),
                        WaitStep(600.0, "the illumination warms"),
                        CaptureStep("warm", 0.0, 0.0, False, 2)))
    with simulated_rig(frame_source=world, seed=1, lab_wait=world.clock.wait) as rig:
        # the stage's move from where it stood at power-on to 0 deg takes its time first
        move_s = world.clock.move_duration_s(rig.turntable.position_deg(), 0.0)
        caps = acquire(rig, RecordingOperator([]), plan,
                       lambda done, total, message: events.append((done, total, message)))
        period_s = 1.0 / rig.camera.use_case.frame_rate_hz
    assert events[1] == (1, 2, "the illumination warms")
    assert plan.waited_s == 600.0
    cold, warm = caps["cold"].illumination_temperature_c, caps["warm"].illumination_temperature_c
    spec = parse_reality({"camera": {"temperature": WARMUP}}).camera.temperature
    # two frames before the wait (0 and one period), two after it; the wire carries float32
    assert move_s > 0.0
    assert cold == pytest.approx(np.mean([illumination_temperature_c(move_s + t, spec)
                                          for t in (0.0, period_s)]), abs=1e-4)
    assert warm == pytest.approx(np.mean([illumination_temperature_c(
        move_s + 600.0 + k * period_s, spec) for k in (2, 3)]), abs=1e-4)
    assert warm - cold > 10.0


def test_a_captures_rest_after_its_move_passes_on_the_labs_clock_with_the_move_ended_first():
    """``CaptureStep.rest_s`` waits after the move: the move ends (and the table rings) before
    the rest, not when the frames come (the rig sweep's warm-up once rang through its first
    capture: the rest passed before the lab's clock had heard of the move)."""
    world = SimulatedWorld(parse_scene_spec(WALL), ".", RenderRequest(
        RenderSettings(integrator="direct", spp=1), effects="auto"))
    plan = CapturePlan((CaptureStep("rested", 0.0, 0.0, False, 1, rest_s=120.0),))
    with simulated_rig(frame_source=world, seed=1, lab_wait=world.clock.wait) as rig:
        move_s = world.clock.move_duration_s(rig.turntable.position_deg(), 0.0)
        acquire(rig, RecordingOperator([]), plan)
    ends_s, _signs = world.clock.moves()
    assert move_s > 0.0
    assert ends_s[-1] == pytest.approx(move_s)  # the move ended, then the 120 s of rest
    with pytest.raises(InvalidInputError, match=r"rested\.rest_s.*0 to 86400 s"):
        CaptureStep("rested", 0.0, 0.0, False, 1, rest_s=-1.0)


def test_a_wait_on_a_rig_without_a_lab_clock_returns_and_a_bad_wait_names_its_field(rig):
    with pytest.raises(InvalidInputError, match=r"wait.seconds.*0 to 86400 s"):
        WaitStep(-1.0)
    with pytest.raises(InvalidInputError, match=r"wait\.seconds"):
        WaitStep(float("nan"))
    with pytest.raises(ValueError, match="seconds: got -2"):
        rig.wait(-2.0)
    rig.wait(3600.0)  # an instant simulated rig: an hour passes at once
    slept: list[float] = []
    r = Rig(rig.turntable, rig.solar, rig.camera, sleep=slept.append)
    r.wait(1.5)
    assert slept == [1.5]


def test_a_warmup_stage_out_of_range_names_its_field():
    with pytest.raises(InvalidInputError, match=r"warmup_captures.*got 2; allowed: 3 to 64"):
        RigCalibrationPlan(warmup_captures=2)
    with pytest.raises(InvalidInputError, match=r"warmup_interval_s.*allowed: 0 to 3600 s"):
        RigCalibrationPlan(warmup_interval_s=-5.0)
    with pytest.raises(InvalidInputError, match="warmup_frames"):
        RigCalibrationPlan(warmup_frames=0)
    assert RigCalibrationPlan(warmup_captures=0).warmup_times_s == ()
    assert RigCalibrationPlan(warmup_captures=3, warmup_interval_s=60.0).warmup_times_s == (
        0.0, 60.0, 120.0)


def test_a_settling_stage_out_of_range_names_its_field():
    with pytest.raises(InvalidInputError, match=r"settling_frames.*got 5; allowed: 12 to 1024"):
        RigCalibrationPlan(settling_frames=5)
    with pytest.raises(InvalidInputError, match=r"settling_move_deg.*allowed: 1 to 90 deg"):
        RigCalibrationPlan(settling_move_deg=0.0)
    only = rig_capture_plan(RigCalibrationPlan(warmup_captures=0),
                            load_scene_spec(EXAMPLES / "satellite_ground_test.yaml"))
    assert isinstance(only.steps[0], MountStep)  # the settling stage mounts its own board
    assert [c.name for c in only.captures[:2]] == ["settling/moved", "settling/rest"]


def test_a_capture_that_does_not_settle_lifts_the_turntables_wait_for_its_move_only(rig):
    """The settling stage's capture: the driver's post-move wait is 0 during its move and
    restored after it, also inside the service's wait for a calibrated settling."""
    seen: list[float] = []
    real_move = rig.turntable.move_to

    def move_to(angle_deg: float, *args, **kwargs):
        seen.append(rig.turntable.settle_s)
        return real_move(angle_deg, *args, **kwargs)

    base = rig.turntable.settle_s
    rig.turntable.settle_s = 0.3
    rig.turntable.move_to = move_to
    try:
        acquire(rig, RecordingOperator([]), CapturePlan((
            CaptureStep("rest", 0.0, 0.0, False, 1),
            CaptureStep("moved", 20.0, 0.0, False, 2, settle=False),
            CaptureStep("after", 0.0, 0.0, False, 1))))
    finally:
        del rig.turntable.move_to
        after = rig.turntable.settle_s
        rig.turntable.settle_s = base
    assert seen == [0.3, 0.0, 0.3] and after == 0.3
