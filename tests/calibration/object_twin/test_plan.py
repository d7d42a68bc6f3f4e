"""The object fit's capture plan: one capture per angle, shutter closed, in the user's order."""

from __future__ import annotations

import pytest

from calibration.object_twin.plan import MAX_FIT_ANGLES, object_fit_capture_plan
from sim_core.errors import InvalidInputError


def test_one_closed_shutter_capture_per_angle_in_the_given_order():
    plan = object_fit_capture_plan([30.0, -60.0, 0.0], frames=8)
    steps = plan.captures
    assert [s.turntable_angle_deg for s in steps] == [30.0, -60.0, 0.0]
    assert [s.name for s in steps] == ["object@+30", "object@-60", "object@+0"]
    assert all(s.frames == 8 and not s.shutter_open and s.solar_suns == 0.0 for s in steps)
    assert plan.restore is None and plan.n_captures == 3


@pytest.mark.parametrize(("angles", "frames", "message"), [
    ([0.0, 0.0], 4, "given twice"),
    ([400.0], 4, "allowed"),
    ([float(a) for a in range(MAX_FIT_ANGLES + 1)], 4, f"{MAX_FIT_ANGLES}"),
    ([0.0], 0, "frames"),
])
def test_a_plan_the_fit_cannot_take_is_refused_naming_the_field(angles, frames, message):
    with pytest.raises(InvalidInputError, match=message) as info:
        object_fit_capture_plan(angles, frames, field="--angles")
    assert info.value.field in ("--angles", "object@+0.frames")
