"""The whole sequence on the simulated lab recovers a hidden, randomly drawn reality.

Issue 13's round trip: realities drawn at random in plausible ranges; the calibration sees only
the frames. Each takes about 5 minutes (138 board views and their synthesis, noise stacks, solar
levels): CI runs one (``SEEDS``), whose calibration the satellite campaign shares. Every
reality carries issue 27's three effects too (:func:`tests.calibration.realities.
with_world_effects`): the warm-up stage must measure the drift within 10 % and the solar stage
the stray light's fraction within 20 % whenever they are determined, and every other key keep
its target with the effects in the world.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.rig_sequence import RigCalibrationPlan
from calibration.rig_verdicts import calibration_keys
from drivers.sim.operator import SimulatedOperator
from drivers.sim.rig import simulated_rig
from drivers.sim.world import SimulatedWorld
from service.lab.acquisition import run_rig_calibration, run_twin_comparison
from sim_core.camera import F_60_24_MHZ
from sim_core.depth_errors import DepthErrorModel, range_to_phase_rad
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene_spec import load_scene_spec
from tests.calibration.realities import random_reality, reality_seeds, with_world_effects
from tests.calibration.rig_truth import (
    EFFECT_TARGETS_REL,
    key_figures,
    table,
    true_depth_at_calibration_start,
)
from tests.sim_core.scenes import EXAMPLES

pytestmark = [pytest.mark.slow, pytest.mark.timeout(1800)]

#: issue 13's targets
PRINCIPAL_POINT_PX = 0.5
AXIS_POINT_M = 0.002
ZERO_OFFSET_DEG = 0.1
DEPTH_MODEL_MM = 2.0
SPEC = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")


def _calibrate(reality, seed, frames_per_view=4):
    world = SimulatedWorld(SPEC, EXAMPLES, RenderRequest(
        RenderSettings(integrator="direct", spp=32), effects="all"), reality=reality)
    with simulated_rig(frame_source=world, seed=seed, lab_wait=world.clock.wait) as rig:
        return run_rig_calibration(rig, SimulatedOperator(world), SPEC, EXAMPLES,
                                   RigCalibrationPlan(frames_per_view=frames_per_view))


#: the round trip whose calibration the satellite campaign also uses (one sequence, not two)
CAMPAIGN_SEED = 202
_calibrated: dict[int, object] = {}


def _calibrated_reality(seed):
    """The reality drawn for ``seed``, with issue 27's three effects (the warm-up drift, the
    stray light and the table's ringing), and its calibration; the campaign's seed is
    calibrated once per session, whichever of its two tests runs first."""
    reality = with_world_effects(
        random_reality(seed, nominal_power_w=SPEC.illumination.power_w), seed)
    if seed != CAMPAIGN_SEED:
        return reality, _calibrate(reality, seed)
    if seed not in _calibrated:
        _calibrated[seed] = _calibrate(reality, seed)
    return reality, _calibrated[seed]


def _depth_model_rms_mm(result, reality) -> float:
    """RMS of (fitted - true) depth error over the board pixels and phases the sweep saw."""
    shape = (171, 224)
    fitted = DepthErrorModel.from_spec(result.calibration.camera.depth, [F_60_24_MHZ], shape)
    truth = DepthErrorModel.from_spec(
        true_depth_at_calibration_start(result, reality, [F_60_24_MHZ]), [F_60_24_MHZ], shape)
    depth = result.results["depth"]
    seen = depth.pixels_seen
    diffs = []
    for phi in np.linspace(*depth.phase_span_rad, 25):
        p = np.full(shape, phi)
        diffs.append((fitted.phase_error_rad(p, 0) - truth.phase_error_rad(p, 0))[seen])
    d = np.concatenate(diffs)
    d = np.angle(np.exp(1j * d))
    return float(np.sqrt(np.mean(d**2)) / range_to_phase_rad(1.0, F_60_24_MHZ) * 1e3)


#: with pytest-xdist (`-n 2 --dist loadgroup`, as CI runs the slow suite) the campaign's round
#: trip and the campaign run in one worker, so that they share one calibration
SHARED = pytest.mark.xdist_group(f"calibration-{CAMPAIGN_SEED}")


#: CI runs one reality within its time budget (5-8 min on two cores; issue 13 was shown on
#: 101-505 without the effects, issue 27 on 101-606 with them; the service's and the command's
#: full runs calibrate two hand-written realities more):
#: TOFTWIN_REALITY_SEEDS=101,202,303,404,505 runs five, any other seeds too
SEEDS = [pytest.param(s, marks=SHARED) if s == CAMPAIGN_SEED else s
         for s in reality_seeds([CAMPAIGN_SEED])]


@pytest.mark.parametrize("seed", SEEDS)
def test_round_trip_recovers_a_random_reality(seed):
    reality, result = _calibrated_reality(seed)
    cal, rc = result.calibration.camera, reality.camera
    report = result.calibration.provenance.procedures
    axis = result.results["turntable"]
    true_dir = np.asarray(reality.turntable.axis_direction)
    true_dir = true_dir / np.linalg.norm(true_dir)
    off = axis.axis_point_m - np.asarray(reality.turntable.axis_point_m)
    figures = {
        "fx_rel": cal.fx_px / rc.fx_px - 1, "fy_rel": cal.fy_px / rc.fy_px - 1,
        "cx_px": cal.cx_px - rc.cx_px, "cy_px": cal.cy_px - rc.cy_px,
        "rms_px": result.results["intrinsics"].rms_px,
        "axis_deg": float(np.degrees(np.arccos(np.clip(axis.axis_direction @ true_dir, -1, 1)))),
        "axis_point_mm": float(np.linalg.norm(off - (off @ true_dir) * true_dir) * 1e3),
        "zero_deg": axis.zero_offset_deg - reality.turntable.zero_offset_deg,
        "depth_model_mm": _depth_model_rms_mm(result, reality),
        "depth_after_mm": result.results["depth"].rms_after_mm,
        "gain_rel": cal.sensor.adc_gain_e_per_dn / rc.sensor.adc_gain_e_per_dn - 1,
        "read_rel": cal.sensor.read_noise_e / rc.sensor.read_noise_e - 1,
        "power_rel": result.calibration.illumination.power_w / reality.illumination.power_w - 1,
        "solar_rel": result.calibration.solar_simulator.irradiance_scale
        / reality.solar_simulator.irradiance_scale - 1,
        "solar_method": result.results["solar"].method,
    }
    print(f"round trip {seed}:", {k: round(v, 4) if isinstance(v, float) else v
                                  for k, v in figures.items()})
    assert cal.fx_px == pytest.approx(rc.fx_px, rel=0.005), report["intrinsics"]
    assert cal.fy_px == pytest.approx(rc.fy_px, rel=0.005), report["intrinsics"]
    assert abs(cal.cx_px - rc.cx_px) <= PRINCIPAL_POINT_PX
    assert abs(cal.cy_px - rc.cy_px) <= PRINCIPAL_POINT_PX
    assert result.results["intrinsics"].rms_px <= 0.3
    assert np.degrees(np.arccos(np.clip(axis.axis_direction @ true_dir, -1, 1))) <= 0.2
    assert np.linalg.norm(off - (off @ true_dir) * true_dir) <= AXIS_POINT_M
    assert axis.zero_offset_deg == pytest.approx(reality.turntable.zero_offset_deg,
                                                 abs=ZERO_OFFSET_DEG)
    assert figures["depth_model_mm"] <= DEPTH_MODEL_MM
    assert cal.sensor.adc_gain_e_per_dn == pytest.approx(rc.sensor.adc_gain_e_per_dn, rel=0.05)
    assert cal.sensor.read_noise_e == pytest.approx(rc.sensor.read_noise_e, rel=0.10)
    assert result.calibration.illumination.power_w == pytest.approx(
        reality.illumination.power_w, rel=0.03)
    solar = result.results["solar"]
    if solar.method == "frames":
        assert result.calibration.solar_simulator.irradiance_scale == pytest.approx(
            reality.solar_simulator.irradiance_scale, rel=0.03)
    _assert_verdicts(result, reality)


#: the keys issue 13 asked for: determined on the default plan (k3 is held at 0 and, being 0,
#: not written)
ASKED_FOR = ("camera.fx_px", "camera.fy_px", "camera.cx_px", "camera.cy_px",
             "camera.distortion.k1", "camera.distortion.k2", "camera.distortion.p1",
             "camera.distortion.p2", "turntable.axis_point_m", "turntable.axis_direction",
             "turntable.zero_offset_deg", "camera.depth.phase_offset_rad",
             "camera.depth.wiggling", "camera.depth.pixel_offset_m",
             "camera.sensor.adc_gain_e_per_dn", "camera.sensor.read_noise_e",
             "illumination.power_w", "solar_simulator.irradiance_scale")


#: issue 27's effect keys
EFFECT_PREFIXES = ("camera.temperature.", "camera.stray_light.", "turntable.settling.")


def _assert_verdicts(result, reality):
    """Issue 27: every key of the file judged; on the default plan every key issue 13 asked
    for determined; a determined key's error within 3 of its standard deviations, or within
    its target."""
    verdicts = result.verdicts
    figures = key_figures(result, reality, [F_60_24_MHZ])
    print(table(figures))
    print(verdicts.counts())
    print({k: v.to_json() for k, v in verdicts.items() if k.startswith(EFFECT_PREFIXES)})
    keys = calibration_keys(result.calibration)
    assert list(verdicts)[:len(keys)] == keys
    # the effects' keys not written are judged too, never determined, each with its reason
    for key in list(verdicts)[len(keys):]:
        assert key.startswith(EFFECT_PREFIXES) and not verdicts[key].determined, (
            key, verdicts[key])
        assert verdicts[key].reason
    for key in ASKED_FOR:
        assert verdicts[key].determined, (key, verdicts[key])
    for f in figures:
        if f.verdict == "determined":
            assert f.z <= 3.0 or f.within_target, f
        if f.key in EFFECT_TARGETS_REL and f.verdict == "determined":
            assert f.within_target, f  # issue 27's targets, whenever determined
    if reality.camera.temperature is None:  # no warm-up in the world: no drift written
        assert result.calibration.camera.temperature is None


@SHARED
def test_the_calibrated_twin_lands_near_the_ceiling_on_a_satellite_campaign():
    """Issue 13's end to end: nominal twin, calibrated twin, ceiling on 8 satellite poses all
    round (every 45 deg), in a world with issue 27's three effects: the calibrated twin with
    their models (the drift at each frame's reported temperature, the stray light) near the
    ceiling. The campaign's world starts cold (a lab clock of its own: the drift is largest)."""
    reality, result = _calibrated_reality(CAMPAIGN_SEED)  # a drawn reality has no object diffs
    world = SimulatedWorld(SPEC, EXAMPLES, RenderRequest(
        RenderSettings(integrator="path", spp=32, max_bounces=2), effects="all"), reality=reality)
    with simulated_rig(frame_source=world, seed=7) as rig:
        res = run_twin_comparison(rig, SPEC, EXAMPLES, result.calibration,
                                  [-165.0 + 45.0 * i for i in range(8)],
                                  settings=RenderSettings(integrator="path", spp=32, max_bounces=2))
    print(res.to_dict())
    assert res.poses == 8
    assert res.calibrated_over_ceiling <= 1.25, res.to_dict()
    assert res.nominal["depth_rmse_mm"] > res.calibrated["depth_rmse_mm"]
