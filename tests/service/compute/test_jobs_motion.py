"""A simulation job of a frame taken while the table turns renders each phase step at its angle."""

from __future__ import annotations

import numpy as np
import pytest

from service.compute.jobs import make_job, run_job
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene_spec import load_scene_spec
from tests.sim_core.scenes import EXAMPLES

pytestmark = pytest.mark.timeout(60)


def _job(speed_deg_s: float):
    spec = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
    spec = spec.model_copy(update={"camera": spec.camera.model_copy(update={
        "width_px": 40, "height_px": 31, "fx_px": 37.2, "fy_px": 37.2})})
    request = RenderRequest(RenderSettings(integrator="direct", spp=2, seed=1, threads=1),
                            effects="all", ideal=True)
    return make_job(spec, EXAMPLES, turntable_deg=20.0, solar_suns=0.0, request=request,
                    turntable_speed_deg_s=speed_deg_s)


def test_a_turning_job_smears_and_a_slow_one_is_the_frame_at_rest():
    rest = run_job(_job(0.0)).image.range_m
    slow = run_job(_job(0.01)).image.range_m  # 4.5e-5 deg in the frame: one render
    np.testing.assert_array_equal(slow, rest)
    turning = run_job(_job(1000.0)).image.range_m  # 1.5 deg between phase steps
    differs = np.abs(np.nan_to_num(turning - rest)) > 0.01
    assert differs.sum() > 0
    assert differs.mean() < 0.2  # at the edges of what turns, not everywhere
