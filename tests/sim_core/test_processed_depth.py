"""royale's processed depth as an image (:mod:`sim_core.processed_depth`): safe at its edges."""

from __future__ import annotations

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from sim_core.processed_depth import CAMERA_DATA_DEPTH, ProcessedDepthFrame, camera_data

EDGY = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=32),
                 st.sampled_from([0.0, -0.0, 1e-38, -1.0, 3e38]))


def _frame(x, y, z, confidence) -> ProcessedDepthFrame:
    nan = np.full(z.shape, np.nan, np.float32)
    return ProcessedDepthFrame(x, y, z, nan, np.abs(np.nan_to_num(z)), confidence,
                               np.array([60.24e6]), 500e-6)


@settings(max_examples=200, deadline=None)
@given(arrays(np.float32, (3, 4), elements=EDGY), arrays(np.float32, (3, 4), elements=EDGY),
       arrays(np.float32, (3, 4), elements=EDGY),
       arrays(np.float32, (3, 4), elements=st.floats(0.0, 1.0, width=32)))
@example(np.full((3, 4), 3e38, np.float32), np.full((3, 4), 3e38, np.float32),
         np.full((3, 4), 3e38, np.float32), np.ones((3, 4), np.float32))
def test_the_image_is_finite_and_positive_where_valid_and_nan_elsewhere(x, y, z, confidence):
    image = _frame(x, y, z, confidence).image()
    v = image.valid
    assert (v == ((confidence > 0) & np.isfinite(x) & np.isfinite(y) & np.isfinite(z)
                  & (z > 0))).all()
    assert np.isnan(image.range_m[~v]).all() and np.isnan(image.depth_z_m[~v]).all()
    # range >= z where valid; float32 points far apart overflow nothing in float64
    assert np.isfinite(image.range_m[v]).all() and (image.range_m[v] >= image.depth_z_m[v]).all()
    assert (image.depth_z_m[v] > 0).all()
    assert image.phase_rad.shape == (1, 3, 4) and np.isnan(image.phase_rad).all()


def test_a_frame_says_what_it_is():
    z = np.ones((2, 2), np.float32)
    frame = _frame(z * 0, z * 0, z, z)
    assert camera_data(frame) == CAMERA_DATA_DEPTH
    assert np.allclose(frame.image().range_m, 1.0)
