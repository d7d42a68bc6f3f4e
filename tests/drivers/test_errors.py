"""Device input errors cross process boundaries intact (a worker's error reaching the service)."""

from __future__ import annotations

import pickle

from drivers.errors import DeviceInputError, LimitError


def test_a_limit_error_comes_back_from_pickle_with_its_range():
    error = LimitError("poses[3].turntable_deg", 175.0, -170.0, 170.0, "deg", "software limits")
    back = pickle.loads(pickle.dumps(error))
    assert type(back) is LimitError and str(back) == str(error)
    assert (back.field, back.value, back.low, back.high, back.unit) == (
        "poses[3].turntable_deg", 175.0, -170.0, 170.0, "deg")
    plain = pickle.loads(pickle.dumps(DeviceInputError("angle_deg", "not finite")))
    assert str(plain) == "angle_deg: not finite"
