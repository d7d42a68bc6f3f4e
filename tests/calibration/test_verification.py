"""The twin check: with the reality's own values the twin reaches the ceiling; nominal does not."""

from __future__ import annotations

import pytest

from drivers.sim.rig import simulated_rig
from drivers.sim.world import SimulatedWorld
from service.lab.acquisition import run_twin_comparison
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene_spec import load_scene_spec
from sim_core.twin_file import CalibrationFile
from tests.calibration.realities import random_reality
from tests.sim_core.scenes import EXAMPLES

pytestmark = pytest.mark.timeout(300)


def test_a_perfect_calibration_reaches_the_ceiling_and_the_nominal_twin_does_not():
    spec = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
    reality = random_reality(11, nominal_power_w=spec.illumination.power_w * 20.0)
    # The reality's own keys, as a calibration would ideally find them.
    perfect = CalibrationFile.model_validate(reality.model_dump(exclude={"mount", "objects"}))
    settings = RenderSettings(integrator="direct", spp=16)
    world = SimulatedWorld(spec, EXAMPLES, RenderRequest(settings, effects="all"), reality=reality)
    with simulated_rig(frame_source=world, seed=2) as rig:
        res = run_twin_comparison(rig, spec, EXAMPLES, perfect, [-30.0, 30.0, 90.0],
                                  settings=settings)
    assert res.poses == 3
    assert res.calibrated_over_ceiling < 1.15, res.to_dict()
    assert res.nominal["depth_rmse_mm"] > 2.0 * res.calibrated["depth_rmse_mm"], res.to_dict()
    assert res.calibrated["grey_ssim"] > res.nominal["grey_ssim"]
