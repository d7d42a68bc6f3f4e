"""The object fit's solver and parameters, on residuals with a known minimum (no renders)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.object_twin import refine
from calibration.object_twin.refine import (
    REACH,
    _levenberg_marquardt,
    _reach_used,
    offset_of,
    pivot_parameters,
)
from sim_core.scene_spec import ObjectPose


class Quadratic:
    """``r(x) = A (x - x_true)``: the problem's ``residual`` and ``jacobian`` for a solver test;
    ``A`` may be badly conditioned (a tilt that trades against a scale)."""

    def __init__(self, a: np.ndarray, x_true: np.ndarray) -> None:
        self.a, self.x_true = a, x_true
        self.evaluations = 0

    def residual(self, x: np.ndarray) -> np.ndarray:
        self.evaluations += 1
        return self.a @ (x - self.x_true)

    def jacobian(self, x: np.ndarray, wide: bool = False) -> np.ndarray:
        return self.a  # exact: any differences of a linear residual


def _problem(seed: int, n_scales: int = 2, condition: float = 1e3) -> Quadratic:
    rng = np.random.default_rng(seed)
    n = 6 + n_scales
    q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    a = np.vstack([q * np.geomspace(1.0, 1.0 / condition, n), rng.normal(size=(20, n)) * 1e-2])
    x_true = np.r_[rng.uniform(-3, 3, 3), rng.uniform(-0.6, 0.6, 3),
                   rng.uniform(0.8, 1.2, n_scales)]
    return Quadratic(a, x_true)


@pytest.mark.parametrize("seed", range(5))
def test_the_solver_reaches_the_minimum_within_the_reach(seed):
    prob = _problem(seed)
    x0 = np.r_[np.zeros(6), np.ones(prob.x_true.size - 6)]
    x, r, _, _, at_edge = _levenberg_marquardt(prob, x0, 50, centre=x0)
    assert not at_edge
    np.testing.assert_allclose(x, prob.x_true, atol=1e-6)
    assert float(r @ r) < 1e-12


def test_a_minimum_beyond_the_reach_stops_the_solve_at_its_edge():
    prob = _problem(7)
    prob.x_true[0] = 3.0 * REACH[0]  # far beyond what the regions allow
    x0 = np.r_[np.zeros(6), np.ones(prob.x_true.size - 6)]
    x, _, _, _, at_edge = _levenberg_marquardt(prob, x0, 50, centre=x0)
    assert at_edge
    assert _reach_used(x, x0) <= 1.0 + 1e-9
    assert _reach_used(x, x0) > refine.RECENTRE_AT


def test_steps_longer_than_an_iteration_may_go_are_damped_not_cut():
    # a far minimum: every accepted step respects the per-iteration limit
    prob = _problem(3)
    prob.x_true[:3] = [7.0, -7.0, 7.0]
    x = np.r_[np.zeros(6), np.ones(prob.x_true.size - 6)]
    for _ in range(4):
        x_next, *_ = _levenberg_marquardt(prob, x, 1, centre=prob.x_true)
        assert np.all(np.abs(x_next[:3] - x[:3]) <= refine.MAX_STEP[0] * refine.MAX_STRETCH)
        x = x_next


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-0.01, 0.01), min_size=3, max_size=3),
       st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
       st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3))
def test_the_pivot_parameters_and_the_offset_are_inverse(position_m, rotation_deg, lever_m):
    offset = ObjectPose(position_m=tuple(position_m), rotation_deg=tuple(rotation_deg))
    lever = np.asarray(lever_m)
    back = offset_of(pivot_parameters(offset, lever), lever)
    np.testing.assert_allclose(back[:3], np.asarray(position_m) * 1e3, atol=1e-9)
    np.testing.assert_allclose(back[3:], rotation_deg, atol=1e-12)


class Jittery(Quadratic):
    """:class:`Quadratic` plus a jitter far finer than a difference step: the sample coverage
    of the silhouettes, which moves in steps as the pose moves."""

    fitted = ("a", "b")

    def __init__(self, a: np.ndarray, x_true: np.ndarray, jitter: float, seed: int) -> None:
        super().__init__(a, x_true)
        rng = np.random.default_rng(seed)
        self.jitter = jitter
        self.freq = rng.uniform(2e3, 4e3, size=(a.shape[0], a.shape[1]))

    def residual(self, x: np.ndarray) -> np.ndarray:
        return super().residual(x) + self.jitter * np.sin(self.freq @ x)

    def jacobian(self, x: np.ndarray, wide: bool = False) -> np.ndarray:
        return refine._Problem.jacobian(self, x, wide)


@pytest.mark.parametrize("seed", range(4))
def test_the_wide_central_differences_do_not_read_a_fine_jitter_as_information(seed):
    base = _problem(seed)
    prob = Jittery(base.a, base.x_true, jitter=2e-3, seed=seed)
    x = base.x_true + 0.01
    exact = np.diag(base.a.T @ base.a)[:6]
    narrow = np.diag(prob.jacobian(x).T @ prob.jacobian(x))[:6]
    wide_j = prob.jacobian(x, wide=True)
    wide = np.diag(wide_j.T @ wide_j)[:6]
    # the forward differences add the jitter's slope to J^T J; the wide central ones far less
    assert np.all(np.abs(wide - exact) < np.abs(narrow - exact))
    np.testing.assert_allclose(wide_j[:, 6:], prob.jacobian(x)[:, 6:])  # the scales as before
