"""The effect planner at the extremes: scenes that are mostly too dark to measure.

The planner switches multipath off when its range bias stays below a tolerance of a quarter of
the median predicted range noise of the pixels that see something. Pixels far too dark for the
camera to report (amplitude below the validity threshold) must not set that tolerance: a
white corner in front of the black flannel of the seed paper's ground test would otherwise
lose its multipath, and the plan would jump when a black material's albedo moves from 0 to
1e-9.
"""

from __future__ import annotations

import numpy as np
import pytest

from sim_core.pipeline import simulate
from sim_core.render_request import RenderRequest
from tests.hard_cases.helpers import PATH, build, camera, lambert, rectangle


def corner_before_backdrop(backdrop_albedo: float):
    """Two white panels at 90 degrees (strong interreflection) before a wide dark backdrop."""
    objs = [rectangle("backdrop", (30.0, 30.0), lambert(backdrop_albedo), (0.0, 6.0, 0.0),
                      (90.0, 0.0, 0.0)),
            rectangle("left", (0.6, 0.6), lambert(0.9), (-0.2, 1.5, 0.0), (90.0, 0.0, 45.0)),
            rectangle("right", (0.6, 0.6), lambert(0.9), (0.2, 1.5, 0.0), (90.0, 0.0, -45.0))]
    return build(camera((0, 0, 0), (0, 1, 0)), objs)


def multipath_of(frame):
    return next(e for e in frame.plan.effects if e.name == "multipath")


def test_corner_multipath_is_simulated_before_a_perfectly_black_backdrop():
    frame = simulate(corner_before_backdrop(0.0), RenderRequest(PATH))
    mp = multipath_of(frame)
    assert mp.enabled, mp.reason
    assert mp.numbers["range_bias_p95_mm"] > 10.0 * frame.plan.tolerance_mm


@pytest.mark.parametrize("backdrop_albedo", [1e-9, 0.02], ids=["1e-9", "black-flannel"])
def test_a_dark_backdrop_does_not_switch_the_corner_multipath_off(backdrop_albedo):
    black = simulate(corner_before_backdrop(0.0), RenderRequest(PATH))
    frame = simulate(corner_before_backdrop(backdrop_albedo), RenderRequest(PATH))
    # The backdrop is too dark to measure: its pixels are invalid in the frame ...
    backdrop = frame.light_field.object_id == 0
    assert frame.image.valid[backdrop].mean() < 0.05
    # ... so the plan is that of the perfectly black backdrop.
    assert multipath_of(frame).enabled
    assert frame.plan.tolerance_mm == pytest.approx(black.plan.tolerance_mm, rel=0.05)


def test_plan_of_a_bright_scene_is_stable_under_a_1e_9_albedo_change():
    def scene(albedo):
        return build(camera((0, 0, 0), (0, 1, 0)),
                     [rectangle("left", (2.0, 2.0), lambert(albedo), (-0.3, 1.5, 0.0),
                                (90.0, 0.0, 45.0)),
                      rectangle("right", (2.0, 2.0), lambert(0.9), (0.3, 1.5, 0.0),
                                (90.0, 0.0, -45.0))], power_w=5.0)

    a, b = simulate(scene(0.5),
                    RenderRequest(PATH)), simulate(scene(0.5 * (1.0 + 1e-9)), RenderRequest(PATH))
    assert [e.enabled for e in a.plan.effects] == [e.enabled for e in b.plan.effects]
    assert b.plan.tolerance_mm == pytest.approx(a.plan.tolerance_mm, rel=1e-6)
    np.testing.assert_allclose(b.light_field.dc_active, a.light_field.dc_active, rtol=1e-6)
