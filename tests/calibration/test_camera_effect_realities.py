"""Random realities with issue 27's camera effects: drawn in their ranges, seen in the frames."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.camera.wire import get_use_case
from drivers.rig import RigState
from drivers.sim.usb_camera import CameraRequest
from drivers.sim.world import SimulatedWorld
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene_spec import load_scene_spec
from tests.calibration.realities import (
    DRIFT_MM_PER_C,
    STRAY_LIGHT_FRACTION,
    STRAY_LIGHT_RADIUS_PX,
    WARMUP_TIME_CONSTANT_S,
    random_reality,
    with_camera_effects,
)
from tests.sim_core.scenes import EXAMPLES

pytestmark = pytest.mark.timeout(120)
UC = get_use_case("MODE_5_45FPS_500")


@pytest.mark.parametrize("seed", range(20))
def test_the_effects_are_drawn_in_their_plausible_ranges(seed):
    reality = with_camera_effects(random_reality(seed), seed)
    warm, stray = reality.camera.temperature, reality.camera.stray_light
    assert (warm.illumination_start_c, warm.illumination_end_c) == (25.0, 45.0)
    assert WARMUP_TIME_CONSTANT_S[0] <= warm.time_constant_s <= WARMUP_TIME_CONSTANT_S[1]
    assert DRIFT_MM_PER_C[0] <= abs(warm.depth_drift_mm_per_c[0]) <= DRIFT_MM_PER_C[1]
    assert STRAY_LIGHT_FRACTION[0] <= stray.fraction <= STRAY_LIGHT_FRACTION[1]
    assert STRAY_LIGHT_RADIUS_PX[0] <= stray.kernel_radius_px <= STRAY_LIGHT_RADIUS_PX[1]
    # the other keys are those of the same seed without the effects
    assert reality.camera.fx_px == random_reality(seed).camera.fx_px


def test_a_random_reality_with_the_effects_warms_and_scatters_in_the_world():
    seed = 3
    plain = random_reality(seed)
    effects = with_camera_effects(plain, seed)
    spec = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
    render = RenderRequest(RenderSettings(integrator="direct", spp=2), effects="auto")
    worlds = [SimulatedWorld(spec, EXAMPLES, render, reality=r) for r in (plain, effects)]
    state = RigState(turntable_angle_deg=20.0, solar_suns=0.0, shutter_open=False)
    frames = [w(CameraRequest(UC, 0, seed=1, rig_state=state)) for w in worlds]
    assert frames[0].illumination_temperature_c is None
    assert frames[1].illumination_temperature_c == 25.0  # the service's start
    # both worlds moved the stage 20 deg -> 160 deg: 7.25 s pass on the lab's clock
    far = RigState(turntable_angle_deg=160.0, solar_suns=0.0, shutter_open=False)
    later = worlds[1](CameraRequest(UC, 1, seed=1, rig_state=far))
    warm = effects.camera.temperature
    expected = 45.0 - 20.0 * np.exp(-(1 / 45 + 7.25) / warm.time_constant_s)
    assert later.illumination_temperature_c == pytest.approx(expected)
    # the stray light lights the background corner of the image
    corner = np.s_[0:15, 0:25]
    assert frames[1].intensity[corner].mean() > frames[0].intensity[corner].mean()


@pytest.mark.parametrize("seed", range(20))
def test_the_world_effects_add_the_tables_settling_in_its_ranges(seed):
    from tests.calibration.realities import (
        SETTLING_AMPLITUDE_DEG,
        SETTLING_DAMPING_RATIO,
        SETTLING_FREQUENCY_HZ,
        with_world_effects,
    )

    plain = random_reality(seed)
    reality = with_world_effects(plain, seed)
    s = reality.turntable.settling
    assert SETTLING_AMPLITUDE_DEG[0] <= s.amplitude_deg <= SETTLING_AMPLITUDE_DEG[1]
    assert SETTLING_FREQUENCY_HZ[0] <= s.frequency_hz <= SETTLING_FREQUENCY_HZ[1]
    assert SETTLING_DAMPING_RATIO[0] <= s.damping_ratio <= SETTLING_DAMPING_RATIO[1]
    # the camera's effects and the rig's other keys are those of the same seed
    assert reality.camera.stray_light == with_camera_effects(plain, seed).camera.stray_light
    assert reality.turntable.zero_offset_deg == plain.turntable.zero_offset_deg
