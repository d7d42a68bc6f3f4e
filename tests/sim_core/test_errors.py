"""Input errors survive pickling (they cross process boundaries from simulation workers)."""

from __future__ import annotations

import pickle

from hypothesis import given
from hypothesis import strategies as st

from sim_core.errors import InvalidInputError, SceneError


@given(field=st.text(max_size=40), message=st.text(max_size=80))
def test_input_errors_come_back_from_pickle_equal(field, message):
    for cls in (InvalidInputError, SceneError):
        error = pickle.loads(pickle.dumps(cls(field, message)))
        assert type(error) is cls
        assert (error.field, error.message, str(error)) == (field, message, f"{field}: {message}")


class _OutOfRangeError(InvalidInputError):
    """A subclass whose constructor takes other arguments (as drivers' LimitError does)."""

    def __init__(self, field: str, value: float, high: float) -> None:
        self.value, self.high = value, high
        super().__init__(field, f"{value:g} is above {high:g}")


def test_a_subclass_with_its_own_constructor_comes_back_with_its_attributes():
    error = _OutOfRangeError("poses[3].turntable_deg", 175.0, 170.0)
    back = pickle.loads(pickle.dumps(error))
    assert type(back) is _OutOfRangeError and str(back) == str(error)
    assert back.__dict__ == error.__dict__
