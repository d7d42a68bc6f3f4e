"""The object fit's spread over views: the delete-one-view jackknife at the solution."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.object_twin.refine import conv_std, jackknife_covariance


def _views(n_views: int, rows: int, n_par: int, rng: np.random.Generator):
    jac = rng.normal(size=(n_views * rows, n_par))
    slices = [slice(i * rows, (i + 1) * rows) for i in range(n_views)]
    return jac, slices


def _solution_residual(a: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The residual r = z - A x at the least-squares solution (so J = dr/dx = -A)."""
    x, *_ = np.linalg.lstsq(a, z, rcond=None)
    return z - a @ x


def test_on_a_linear_problem_it_is_the_exact_delete_one_refit_jackknife():
    rng = np.random.default_rng(1)
    a, slices = _views(5, 40, 3, rng)
    z = a @ np.array([1.0, -2.0, 0.5]) + rng.normal(size=a.shape[0])
    r = _solution_residual(a, z)
    fits = []
    for sl in slices:
        keep = np.ones(a.shape[0], bool)
        keep[sl] = False
        fits.append(np.linalg.lstsq(a[keep], z[keep], rcond=None)[0])
    d = np.array(fits) - np.mean(fits, axis=0)
    exact = (len(fits) - 1) / len(fits) * d.T @ d
    np.testing.assert_allclose(jackknife_covariance(-a, r, slices), exact, rtol=1e-9,
                               atol=1e-12)


def test_a_view_that_disagrees_widens_the_spread_far_beyond_the_noise():
    rng = np.random.default_rng(2)
    a, slices = _views(4, 50, 2, rng)
    z = a @ np.array([0.3, -0.7]) + rng.normal(size=a.shape[0])
    honest = np.sqrt(np.diag(jackknife_covariance(-a, _solution_residual(a, z), slices)))
    z[slices[2]] += a[slices[2]] @ np.array([2.0, 0.0])  # one view sees the object elsewhere
    biased = np.sqrt(np.diag(jackknife_covariance(-a, _solution_residual(a, z), slices)))
    statistical = np.sqrt(np.diag(np.linalg.inv(a.T @ a)))
    assert honest[0] < 3 * statistical[0]
    assert biased[0] > 5 * statistical[0] and biased[0] > 5 * honest[0]


def test_one_view_or_a_parameter_only_one_view_sees_is_unbounded_the_others_not():
    rng = np.random.default_rng(3)
    a, slices = _views(1, 30, 2, rng)
    assert np.all(np.isinf(jackknife_covariance(a, rng.normal(size=30), slices)))
    a, slices = _views(3, 20, 3, rng)
    a[20:, 1] = 0.0  # only the first view moves with the second parameter
    cov = jackknife_covariance(-a, _solution_residual(a, rng.normal(size=60)), slices)
    assert np.isinf(cov[1, 1]) and np.all(np.isfinite(np.diag(cov)[[0, 2]]))
    assert np.all(cov[1, [0, 2]] == 0.0)
    # what depends on it is unbounded, the rest keeps its spread
    conv = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0]])
    std = conv_std(cov, conv)
    assert np.all(np.isfinite(std[:2])) and np.isinf(std[2])
    np.testing.assert_allclose(std[:2], np.sqrt(np.diag(cov)[[0, 2]]))


@settings(max_examples=50, deadline=None)
@given(n_views=st.integers(2, 6), rows=st.integers(3, 30), n_par=st.integers(1, 4),
       seed=st.integers(0, 2**32 - 1), scale=st.floats(1e-6, 1e6))
def test_the_covariance_is_symmetric_and_its_variances_finite_or_inf(n_views, rows, n_par,
                                                                    seed, scale):
    rng = np.random.default_rng(seed)
    a, slices = _views(n_views, rows, n_par, rng)
    cov = jackknife_covariance(a * scale, rng.normal(size=a.shape[0]), slices)
    np.testing.assert_allclose(cov, cov.T, rtol=1e-9, atol=1e-300)
    assert np.all(np.diag(cov) >= 0.0)
    std = conv_std(cov, np.eye(n_par))
    assert np.all(std >= 0.0)
    assert np.array_equal(np.isfinite(std), np.isfinite(np.diag(cov)))


@pytest.mark.parametrize("empty", [False, True])
def test_a_view_without_pixels_is_not_counted(empty):
    rng = np.random.default_rng(4)
    a, _ = _views(3, 10, 2, rng)
    if empty:  # the middle view has no rows: two views count
        a, slices = a[np.r_[0:10, 20:30]], [slice(0, 10), slice(10, 10), slice(10, 20)]
    else:
        slices = [slice(0, 10), slice(10, 20), slice(20, 30)]
    cov = jackknife_covariance(a, rng.normal(size=a.shape[0]), slices)
    assert cov.shape == (2, 2) and np.all(np.isfinite(cov))


def test_over_tiles_it_sees_errors_correlated_across_neighbouring_pixels():
    # One 48 x 48 view, a brightness and a slope fitted, the noise blurred over ~3 px (as the
    # optics blur a misfit): the Jacobian's error counts each pixel as independent and is far
    # too small; the spread over 12 px tiles is the estimates' real spread.
    from scipy import ndimage

    rng = np.random.default_rng(5)
    cols = np.tile(np.arange(48.0), 48)
    a = np.stack([np.ones(48 * 48), (cols - 23.5) / 24.0], axis=1)
    tiles = ((np.arange(48 * 48) // 48) // 12) * 4 + (np.arange(48 * 48) % 48) // 12
    groups = [np.flatnonzero(tiles == t) for t in range(16)]
    estimates, spreads = [], []
    for _ in range(150):
        noise = ndimage.gaussian_filter(rng.normal(size=(48, 48)), 3.0).ravel()
        noise /= noise.std()
        x, *_ = np.linalg.lstsq(a, noise, rcond=None)
        estimates.append(x)
        spreads.append(np.sqrt(np.diag(jackknife_covariance(-a, noise - a @ x, groups))))
    real = np.std(estimates, axis=0)
    statistical = np.sqrt(np.diag(np.linalg.inv(a.T @ a)))
    assert np.all(real > 4 * statistical)
    np.testing.assert_allclose(np.median(spreads, axis=0), real, rtol=0.5)


def test_a_tile_whose_removal_leaves_a_direction_undetermined_is_passed_over_when_asked():
    rng = np.random.default_rng(6)
    a = rng.normal(size=(40, 2))
    a[10:, 1] = 0.0  # only the first tile sees the second parameter
    groups = [np.arange(0, 10), np.arange(10, 20), np.arange(20, 30), np.arange(30, 40)]
    r = rng.normal(size=40)
    assert np.isinf(jackknife_covariance(a, r, groups)[1, 1])
    skipped = jackknife_covariance(a, r, groups, "skip")
    assert np.all(np.isfinite(skipped))


def test_the_tiles_split_every_view_s_residual_rows_once_each_by_pixel():
    from calibration.object_twin.refine import _Problem

    rng = np.random.default_rng(7)
    masks = [rng.random((30, 40)) < 0.3, np.zeros((30, 40), bool), rng.random((30, 40)) < 0.5]
    masks[1][5:9, 33:38] = True
    measured = [np.zeros((n_f, 30, 40), complex) for n_f in (1, 2, 2)]
    prob = _Problem(None, measured, masks, [], (), {}, np.zeros(3))  # type: ignore[arg-type]
    n_rows = sum(2 * z.shape[0] * int(m.sum()) for z, m in zip(measured, masks, strict=True))
    groups = prob.pixel_blocks(12)
    rows = np.concatenate(groups)
    assert np.array_equal(np.sort(rows), np.arange(n_rows))  # every row, once
    # each group is one tile of one view: 2 * n_f rows per pixel of the tile
    view1 = [g for g in groups if g.min() >= 2 * int(masks[0].sum())
             and g.max() < 2 * int(masks[0].sum()) + 4 * int(masks[1].sum())]
    assert sorted(g.size for g in view1) == sorted([4 * 4 * 3, 4 * 4 * 2])  # cols 33-35, 36-37
