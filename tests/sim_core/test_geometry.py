"""The scene's rotations (sim_core/geometry.py) are scipy's, to rounding."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from sim_core.geometry import axis_angle_matrix, rotation_matrix_xyz_deg

angle_deg = st.floats(-3600.0, 3600.0, allow_nan=False)
component = st.floats(-1.0, 1.0, allow_nan=False)


@given(st.tuples(angle_deg, angle_deg, angle_deg))
def test_euler_rotation_is_scipys_extrinsic_xyz(angles_deg):
    ours = rotation_matrix_xyz_deg(angles_deg)
    theirs = Rotation.from_euler("xyz", angles_deg, degrees=True).as_matrix()
    np.testing.assert_allclose(ours, theirs, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(ours @ ours.T, np.eye(3), rtol=0.0, atol=1e-12)


@given(st.tuples(component, component, component).filter(
    lambda v: np.linalg.norm(v) > 1e-3), st.floats(-50.0, 50.0, allow_nan=False))
def test_axis_angle_rotation_is_scipys_rotation_vector(axis, angle_rad):
    ours = axis_angle_matrix(axis, angle_rad)
    unit = np.asarray(axis) / np.linalg.norm(axis)
    theirs = Rotation.from_rotvec(unit * angle_rad).as_matrix()
    np.testing.assert_allclose(ours, theirs, rtol=0.0, atol=1e-12)
    assert abs(np.linalg.det(ours) - 1.0) < 1e-12
