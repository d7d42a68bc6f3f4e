"""The rig calibration's settling stage (issue 27): the board's yaw per frame from its phases,
the ringing fitted from the frames' timestamps, and no key when the table does not ring."""

from __future__ import annotations

import dataclasses
import functools
import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.captures import average_frames
from calibration.rig_settling import (
    SETTLING_KEYS,
    RigSettling,
    board_yaw_deg,
    fit_rig_settling,
    ringing_bound,
    unknown_ringing,
)
from calibration.verdicts import Verdict, Verdicts
from sim_core.camera import Intrinsics, pixel_centre_grid, pixel_to_camera_direction
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.errors import InvalidInputError
from sim_core.raw import RawFrame
from sim_core.settling import ringing_deg
from sim_core.twin_file import TurntableSettling

F_HZ = 60.24e6
#: a small image (the pico flexx's field of view at a sixth of its pixels): fast frames
INTR = Intrinsics(56, 43, 52.0, 52.0, 27.5, 21.0)
RAYS = pixel_to_camera_direction(INTR, *pixel_centre_grid(INTR)).reshape(43, 56, 3)
TRUTH = TurntableSettling(amplitude_deg=0.5, frequency_hz=3.0, damping_ratio=0.08)


def _plane_frame(yaw_deg: float, t_s: float, rng: np.random.Generator, noise_rad: float):
    """A frame of a plane 1 m ahead turned by ``yaw_deg`` about the camera's y axis."""
    y = np.radians(yaw_deg)
    n = np.array([np.sin(y), 0.0, -np.cos(y)])  # towards the camera
    r = 1.0 / -(RAYS @ n)
    phi = 4 * np.pi * F_HZ * r / SPEED_OF_LIGHT_M_S + rng.normal(0.0, noise_rad, r.shape)
    c = np.stack([200 * np.cos(phi + k * np.pi / 2) for k in range(4)])[None]
    shape = INTR.shape
    return RawFrame(c.astype(np.float32), np.zeros(shape, np.float32), np.array([F_HZ]),
                    np.zeros(shape, bool), np.zeros(shape, bool), 500e-6, timestamp_s=t_s)


@functools.cache
def _stage(settling: TurntableSettling | None, noise_rad: float = 2e-3):
    """The rest capture and the capture after the move (cached: each test reads them only)."""
    rng = np.random.default_rng(4)
    rest = average_frames([_plane_frame(10.0, 100.0 + 0.1 * k, rng, noise_rad)
                           for k in range(8)], keep_frames=True)
    times = 200.0 + np.arange(60) / 45.0  # 1.3 s at 45 frames per second
    yaw = [30.0 + (0.0 if settling is None else float(ringing_deg(settling, t - 200.0)))
           for t in times]
    moved = average_frames([_plane_frame(a, t, rng, noise_rad)
                            for a, t in zip(yaw, times, strict=True)], keep_frames=True)
    return rest, moved


def test_the_boards_yaw_is_the_planes_turn():
    rng = np.random.default_rng(0)
    mask = np.ones(INTR.shape, bool)
    for yaw in (-25.0, 0.0, 12.5):
        assert board_yaw_deg(_plane_frame(yaw, 0.0, rng, 0.0), INTR, mask) == pytest.approx(
            yaw, abs=1e-3)
    with pytest.raises(InvalidInputError, match="mask"):
        board_yaw_deg(_plane_frame(0.0, 0.0, rng, 0.0), INTR, np.zeros(INTR.shape, bool))
    with pytest.raises(InvalidInputError, match="mask"):
        board_yaw_deg(_plane_frame(0.0, 0.0, rng, 0.0), INTR, np.ones((10, 10), bool))


def test_a_ringing_table_gives_its_settling_from_the_frames_timestamps():
    out = fit_rig_settling(*_stage(TRUTH), INTR)
    freq, damping = (out.verdicts[k] for k in SETTLING_KEYS[1:])
    assert freq.determined and damping.determined, out.verdicts.to_json()
    assert out.settling is not None
    assert out.settling.frequency_hz == pytest.approx(TRUTH.frequency_hz, rel=0.05)
    assert out.settling.damping_ratio == pytest.approx(TRUTH.damping_ratio, rel=0.3)
    # the amplitude at the move's end: not seen by frames after it, never determined
    amp = out.verdicts[SETTLING_KEYS[0]]
    assert amp.verdict == "not determined" and "move's end" in amp.reason
    assert out.summary["frames"] == 60 and out.summary["yaw_noise_deg"] > 0.0


def test_a_table_that_does_not_ring_writes_no_key_and_says_why():
    out = fit_rig_settling(*_stage(None), INTR)
    assert out.settling is None
    assert list(out.verdicts) == list(SETTLING_KEYS)
    for key in SETTLING_KEYS:
        assert not out.verdicts[key].determined and out.verdicts[key].reason


def test_frames_without_times_or_stacks_give_no_settling():
    rest, moved = _stage(TRUTH)
    stale = dataclasses.replace(moved, frames=tuple(
        dataclasses.replace(f, timestamp_s=0.0) for f in moved.frames))
    out = fit_rig_settling(rest, stale, INTR)
    assert out.settling is None and "timestamps" in out.verdicts[SETTLING_KEYS[1]].reason
    out = fit_rig_settling(dataclasses.replace(rest, frames=()), moved, INTR)
    assert out.settling is None and "stacks" in out.verdicts[SETTLING_KEYS[0]].reason


def _settling_stage(rings_on_lab_clock: bool, frames: int, spp: int = 1):
    """The plan's settling steps (mount, moved, wait, rest) acquired on the simulated lab of a
    reality whose table rings as :data:`TRUTH` (an instant stage): the world, the rig (open),
    the captures and the nominal intrinsics."""
    from calibration.capture_plan import CapturePlan
    from calibration.rig_sequence import SETTLING_STEPS, RigCalibrationPlan, rig_capture_plan
    from drivers.sim.operator import SimulatedOperator
    from drivers.sim.rig import simulated_rig
    from drivers.sim.world import SimulatedWorld
    from service.lab.acquisition import acquire
    from sim_core.render import RenderSettings
    from sim_core.render_request import RenderRequest
    from sim_core.scene import build_camera
    from sim_core.scene_spec import load_scene_spec
    from sim_core.twin_file import parse_reality
    from tests.sim_core.scenes import EXAMPLES

    spec = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
    world = SimulatedWorld(spec, EXAMPLES, RenderRequest(RenderSettings(integrator="direct",
                                                                        spp=spp), effects="auto"),
                           reality=parse_reality({"turntable": {"settling": TRUTH.model_dump()}}),
                           rings_on_lab_clock=rings_on_lab_clock)
    plan = RigCalibrationPlan(warmup_captures=0, settling_frames=frames, settling_rest_frames=8)
    stage = CapturePlan(rig_capture_plan(plan, spec).steps[:4])  # mount, moved, wait, rest
    assert [c.name for c in stage.captures] == list(reversed(SETTLING_STEPS))
    rig = simulated_rig(frame_source=world, seed=5, lab_wait=world.clock.wait)
    try:
        caps = acquire(rig, SimulatedOperator(world), stage)
    except BaseException:
        rig.close()
        raise
    return world, rig, caps, build_camera(spec).intrinsics


@pytest.mark.slow  # two renders of the satellite scene and 32 frames over the wire: ~30 s
def test_the_plans_settling_stage_on_a_table_that_settles_at_once_writes_no_key():
    """The plan's settling steps acquired on the simulated lab, whose instant turntable has
    settled at once (a world that does not ring its table on the lab's clock): no ringing
    above the yaw's noise, so no key, each verdict with its reason."""
    from calibration.rig_sequence import SETTLING_STEPS

    _, rig, caps, intrinsics = _settling_stage(rings_on_lab_clock=False, frames=24)
    rig.close()
    out = fit_rig_settling(caps[SETTLING_STEPS[0]], caps[SETTLING_STEPS[1]], intrinsics)
    assert out.summary["board_px"] > 500 and out.summary["yaw_noise_deg"] < 0.2
    assert out.settling is None, out.summary
    # the series is noise about the angle at rest: explained, just no ringing in it (the frames
    # at rest once came from before the move, their mask off the moved board: unexplained)
    assert out.summary["reduced_chi2"] < 2.0, out.summary
    for key in SETTLING_KEYS:
        assert out.verdicts[key].verdict == "not determined" and out.verdicts[key].reason


@pytest.mark.slow  # 60 frames of a ringing table, each phase step rendered at its angle
def test_a_table_ringing_on_the_lab_clock_is_measured_then_waited_out():
    """The world rings its instant stage's table on the lab's clock and stamps the frames with
    it: the settling stage measures the frequency within issue 27's 5 % (and the damping), and
    a move waited out for what it measured (:func:`calibration.rig_settling.
    fit_rig_settling`, :func:`service.lab.settling.settled_moves`) is captured at rest."""
    from calibration.rig_sequence import SETTLING_STEPS
    from drivers.rig import RigState
    from service.lab.settling import settle_wait_s, settled_moves
    from sim_core.twin_file import TurntableParameters, TwinParameters

    world, rig, caps, intrinsics = _settling_stage(rings_on_lab_clock=True, frames=60, spp=16)
    with rig:
        rest, moved = caps[SETTLING_STEPS[0]], caps[SETTLING_STEPS[1]]
        t = np.array([f.timestamp_s for f in moved.frames])
        # the lab's frame period (45 frames a second), not the renders' pace (the wire holds
        # whole microseconds)
        np.testing.assert_allclose(np.diff(t), 1.0 / 45.0, atol=2e-6)
        out = fit_rig_settling(rest, moved, intrinsics)
        print(out.summary, {k: v.to_json() for k, v in out.verdicts.items()})
        assert out.settling is not None, out.summary
        for key in SETTLING_KEYS[1:]:
            assert out.verdicts[key].determined, out.verdicts[key]
        assert out.settling.frequency_hz == pytest.approx(TRUTH.frequency_hz, rel=0.05)
        assert out.settling.damping_ratio == pytest.approx(TRUTH.damping_ratio, rel=0.2)
        bound = ringing_bound(out.settling)
        assert bound.amplitude_deg >= out.settling.amplitude_deg
        wait = TwinParameters(turntable=TurntableParameters(settling=out.settling))
        before_s = world.clock.now_s
        angle = caps[SETTLING_STEPS[0]].turntable_angle_deg + 15.0
        with settled_moves(rig, wait) as waited_s:
            rig.apply(RigState(angle, 0.0, False))
        assert waited_s == pytest.approx(settle_wait_s(wait)) and waited_s > 1.0
        rig.capture(2)
        assert not world.last_rendered_per_step  # at rest: one render a frame
        assert world.clock.now_s - before_s >= waited_s  # the wait passed on the lab's clock


def _fit(settling, verdict: str, ratio: float) -> RigSettling:
    reason = None if verdict == "determined" else "reduced chi-square 5.9 after the fit"
    return RigSettling(settling, Verdicts({k: Verdict(verdict, 0.01 if verdict == "determined"
                                                      else None, reason)
                                           for k in SETTLING_KEYS}),
                       {"ringing_over_noise": ratio})


def test_how_later_moves_wait_follows_what_the_settling_stage_learnt():
    """A determined ringing is waited out (its amplitude raised for the move end's ambiguity);
    a ringing seen but not determined makes every later move rest (the rig sweep's reality
    205: unexplained at 34 yaw noises, its zero 0.67 deg off without a wait); a table seen not
    to ring waits only the driver's own wait."""
    assert unknown_ringing(_fit(TRUTH, "determined", 40.0)) is None  # waited out instead
    assert ringing_bound(TRUTH).amplitude_deg == pytest.approx(
        TRUTH.amplitude_deg * np.exp(np.pi * 0.08 / np.sqrt(1 - 0.08**2)))
    why = unknown_ringing(_fit(None, "unexplained", 34.0))
    assert why.startswith("the table was seen ringing (34 times the yaw's noise)")
    assert "turntable.settling.frequency_hz unexplained: reduced chi-square 5.9" in why
    for ratio in (0.55, 2.9, float("nan")):  # nothing seen above the noise
        assert unknown_ringing(_fit(None, "not determined", ratio)) is None


def test_a_plan_rests_after_its_moves_only():
    from calibration.capture_plan import CapturePlan, CaptureStep, WaitStep
    from calibration.rig_sequence import (
        SETTLING_REST_WAIT_S,
        RigCalibrationPlan,
        rig_capture_plan,
        split_after_settling,
    )
    from tests.calibration.test_rig_roundtrip import SPEC

    first, rest = split_after_settling(rig_capture_plan(RigCalibrationPlan(), SPEC))
    start = first.captures[-1].turntable_angle_deg
    rested = rest.rested_after_moves(SETTLING_REST_WAIT_S, start)
    angles = [start] + [c.turntable_angle_deg for c in rest.captures]
    moves = sum(a != b for a, b in itertools.pairwise(angles))
    assert sum(c.rest_s > 0 for c in rested.captures) == moves > 100
    assert rested.waited_s == pytest.approx(rest.waited_s + moves * SETTLING_REST_WAIT_S)
    assert rested.restore == rest.restore
    plan = CapturePlan((CaptureStep("a", 0.0, 0.0, False, 1), WaitStep(5.0, "w"),
                        CaptureStep("b", 10.0, 0.0, False, 1, settle=False),
                        CaptureStep("c", 10.0, 0.0, False, 1, rest_s=200.0)))
    assert [c.rest_s for c in plan.rested_after_moves(60.0).captures] == [60.0, 0.0, 200.0]
    with pytest.raises(InvalidInputError, match=r"^rest_s: got -1"):
        plan.rested_after_moves(-1.0)


def test_what_the_calibration_file_says_of_a_table_seen_ringing_but_not_known():
    """A settling stage that saw ringing without determining it writes
    ``turntable.rest_after_move_s`` (judged, with the reason) so that every later capture
    rests; a determined ringing or none seen writes no rest."""
    from calibration.rig_sequence import REST_AFTER_MOVE_KEY, _rest_after_move

    verdict = _rest_after_move(_fit(None, "unexplained", 34.0))
    assert verdict.determined and verdict.std is None
    assert verdict.reason.startswith("a wait, not a fit: the table was seen ringing (34 times")
    assert "120 s" in verdict.reason
    assert _rest_after_move(_fit(TRUTH, "determined", 40.0)) is None
    assert _rest_after_move(_fit(None, "not determined", 1.0)) is None
    assert REST_AFTER_MOVE_KEY == "turntable.rest_after_move_s"


@settings(max_examples=200, deadline=None)
@given(amplitude=st.floats(0.0, 5.0), frequency=st.floats(0.05, 500.0),
       zeta=st.floats(0.001, 0.9))
def test_the_ringing_bound_is_finite_no_smaller_and_within_the_key_s_range(
        amplitude, frequency, zeta):
    ringing = TurntableSettling(amplitude_deg=amplitude, frequency_hz=frequency,
                                damping_ratio=zeta)
    bound = ringing_bound(ringing)  # validated again: within the key's range
    assert amplitude <= bound.amplitude_deg <= 5.0
    assert np.isfinite(bound.amplitude_deg)
    assert (bound.frequency_hz, bound.damping_ratio) == (frequency, zeta)
