"""The rig calibration's warm-up stage (issue 27): the drift from averaged captures with their
frames, its keys and verdicts, and the drift's removal from a capture's phases."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from calibration.captures import average_frames, drift_free_phase_rad
from calibration.rig_warmup import (
    END_KEY,
    START_KEY,
    TIME_CONSTANT_KEY,
    fit_rig_warmup,
    observed_time_constant_s,
)
from calibration.warmup import DRIFT_KEY
from sim_core.errors import InvalidInputError
from sim_core.twin_file import CameraTemperature
from sim_core.warmup import TemperatureDrift
from tests.calibration.test_warmup import _frames_at

TIMES_S = np.arange(8) * 120.0
TAU_S = 500.0


def _captures(drift_mm_per_c: float, noise_mm: float = 1.0, frames: int = 3,
              temperatures=None) -> list:
    """One averaged capture (frames kept) per planned time, the temperature on its curve."""
    temps = 45.0 - 20.0 * np.exp(-TIMES_S / TAU_S) if temperatures is None else temperatures
    return [average_frames(_frames_at([t] * frames, drift_mm_per_c, noise_mm, seed=i),
                           keep_frames=True) for i, t in enumerate(temps)]


def test_a_warming_camera_gives_its_drift_and_the_keys_as_observed():
    warm = fit_rig_warmup(_captures(-0.35), TIMES_S)
    assert warm.verdicts[DRIFT_KEY].determined, warm.verdicts[DRIFT_KEY]
    key = warm.temperature
    assert key is not None
    assert key.depth_drift_mm_per_c[0] == pytest.approx(-0.35, abs=3 * warm.fit
                                                        .drift_std_mm_per_c[0])
    assert key.illumination_start_c == pytest.approx(25.0, abs=1e-4)  # the first capture's
    assert key.illumination_end_c == pytest.approx(45.0 - 20.0 * math.exp(-840.0 / TAU_S),
                                                   abs=1e-4)
    assert key.time_constant_s == pytest.approx(TAU_S, rel=0.03)
    assert list(warm.verdicts) == [START_KEY, END_KEY, TIME_CONSTANT_KEY, DRIFT_KEY]
    assert not warm.verdicts[TIME_CONSTANT_KEY].determined
    assert warm.summary["determined"] and warm.summary["frames"] == 24


def test_no_drift_writes_no_key_and_says_there_is_none_above_the_noise():
    warm = fit_rig_warmup(_captures(0.0), TIMES_S)
    assert warm.temperature is None
    assert list(warm.verdicts) == [DRIFT_KEY]
    v = warm.verdicts[DRIFT_KEY]
    assert v.verdict == "not determined" and "no drift above the noise" in v.reason


def test_a_camera_that_reports_no_temperature_gives_no_drift():
    caps = [dataclasses.replace(c, illumination_temperature_c=None) for c in _captures(0.4)]
    warm = fit_rig_warmup(caps, TIMES_S)
    assert warm.temperature is None and warm.fit is None
    assert "reports no illumination temperature" in warm.verdicts[DRIFT_KEY].reason


def test_a_temperature_that_barely_moves_gives_no_drift():
    warm = fit_rig_warmup(_captures(0.4, temperatures=np.linspace(30.0, 31.0, 8)), TIMES_S)
    assert warm.temperature is None
    assert "span" in warm.verdicts[DRIFT_KEY].reason


@settings(max_examples=40, deadline=None)
@given(tau_s=st.floats(60.0, 5000.0), rise_c=st.floats(1.0, 30.0))
def test_the_observed_time_constant_is_the_curves_within_the_search_grid(tau_s, rise_c):
    t = np.arange(10) * 120.0
    tau = observed_time_constant_s(t, 25.0 + rise_c * (1.0 - np.exp(-t / tau_s)))
    assert tau == pytest.approx(tau_s, rel=0.03)


def test_a_flat_or_a_straight_series_gives_a_finite_time_constant_and_bad_input_is_refused():
    t = np.arange(5) * 100.0
    for temps in (np.full(5, 30.0), 25.0 + 0.01 * t):  # no curve: the grid's end, finite
        tau = observed_time_constant_s(t, temps)
        assert math.isfinite(tau) and 0.0 < tau <= 1e6
    with pytest.raises(ValueError, match="length >= 3"):
        observed_time_constant_s([0.0, 1.0], [25.0, 26.0])
    with pytest.raises(ValueError, match="every time is the same"):
        observed_time_constant_s([5.0] * 4, [25.0, 26.0, 27.0, 28.0])


SPEC = CameraTemperature(illumination_start_c=25.0, illumination_end_c=45.0,
                         time_constant_s=600.0, depth_drift_mm_per_c=[0.8])


def test_the_drift_is_removed_at_the_captures_temperature_and_kept_without_one():
    cap = _captures(0.8, noise_mm=0.0, frames=1)[-1]
    fixed = drift_free_phase_rad(cap, SPEC)
    expected = _captures(0.0, noise_mm=0.0, frames=1)[-1].phase_rad  # the range at 25 degC
    np.testing.assert_allclose(np.angle(np.exp(1j * (fixed - expected))), 0.0, atol=1e-5)
    assert np.all((fixed >= 0.0) & (fixed < 2 * np.pi))
    assert drift_free_phase_rad(cap, None) is cap.phase_rad
    no_t = dataclasses.replace(cap, illumination_temperature_c=None)
    assert drift_free_phase_rad(no_t, SPEC) is no_t.phase_rad


@settings(max_examples=300, deadline=None)
@given(phase=st.floats(0.0, 2 * np.pi, exclude_max=True), t_c=st.floats(-20.0, 90.0),
       drift=st.floats(-2.0, 2.0))
@example(phase=0.0, t_c=-2.0, drift=-2.0)  # np.mod(-tiny, 2 pi) is 2 pi itself (CI found it)
def test_removing_the_drift_undoes_applying_it_and_stays_in_one_turn(phase, t_c, drift):
    d = TemperatureDrift(25.0, np.array([drift]), np.array([60.24e6]))
    z = np.exp(-1j * np.full((1, 2, 2), phase))
    drifted = np.mod(-np.angle(d.apply_to_phasor(z, t_c)), 2 * np.pi)
    back = d.remove_from_phase_rad(drifted, t_c)
    assert np.all((back >= 0.0) & (back < 2 * np.pi))
    np.testing.assert_allclose(np.angle(np.exp(1j * (back - phase))), 0.0, atol=1e-9)


def test_a_phase_of_the_wrong_frequencies_names_the_field():
    d = TemperatureDrift(25.0, np.array([0.3, 0.3]), np.array([80.32e6, 60.24e6]))
    with pytest.raises(InvalidInputError, match="phase_rad"):
        d.remove_from_phase_rad(np.zeros((1, 4, 4)), 30.0)
    with pytest.raises(InvalidInputError, match="illumination_temperature_c"):
        d.remove_from_phase_rad(np.zeros((2, 4, 4)), float("nan"))


def test_the_rig_plans_warmup_stage_on_the_simulated_lab_measures_the_worlds_drift():
    """The plan's warm-up steps acquired on the simulated rig (its waits run the lab's clock),
    fitted as the rig calibration fits them: the world's drift within 10 %."""
    from calibration.capture_plan import CapturePlan
    from calibration.rig_sequence import RigCalibrationPlan, rig_capture_plan
    from drivers.sim.operator import SimulatedOperator
    from drivers.sim.rig import simulated_rig
    from drivers.sim.world import SimulatedWorld
    from service.lab.acquisition import acquire
    from sim_core.render import RenderSettings
    from sim_core.render_request import RenderRequest
    from sim_core.scene_spec import load_scene_spec
    from sim_core.twin_file import parse_reality
    from tests.sim_core.scenes import EXAMPLES

    spec = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
    reality = parse_reality({"camera": {"temperature": {
        "illumination_start_c": 25.0, "illumination_end_c": 45.0, "time_constant_s": 900.0,
        "depth_drift_mm_per_c": 0.3}}})
    world = SimulatedWorld(spec, EXAMPLES, RenderRequest(RenderSettings(integrator="direct",
                                                                        spp=1), effects="auto"),
                           reality=reality)
    plan = RigCalibrationPlan(warmup_captures=6, warmup_interval_s=180.0, warmup_frames=3)
    full = rig_capture_plan(plan, spec)
    n_steps = 1 + 2 * plan.warmup_captures - 1  # the mount, the captures and the waits
    stage = CapturePlan(full.steps[:n_steps])
    assert [c.name for c in stage.captures] == [f"warmup/{i}" for i in range(6)]
    with simulated_rig(frame_source=world, seed=2, lab_wait=world.clock.wait) as rig:
        caps = acquire(rig, SimulatedOperator(world), stage)
    assert world.mounted != "scene"  # the first fixture's board
    warm = fit_rig_warmup(list(caps.values()), plan.warmup_times_s)
    assert warm.verdicts[DRIFT_KEY].determined, warm.verdicts[DRIFT_KEY]
    assert warm.temperature.depth_drift_mm_per_c[0] == pytest.approx(0.3, rel=0.10)
    assert warm.summary["patch_px"] > 500
    assert warm.temperature.illumination_end_c - warm.temperature.illumination_start_c > 10.0
