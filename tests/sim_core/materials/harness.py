"""Shared test harness for materials: albedo by quadrature vs sampling, chi-square GOF of the
sampler against its pdf, energy bound.

Every material's tests call these checks, so that each model is held to the same contract
(``sim_core/materials/base.py``):

- :func:`check_albedo_consistency`: the directional albedo ``a(wo) = ∫ f(wi, wo) cos θi dwi``
  by Gauss–Legendre quadrature over the hemisphere agrees with the sampling estimator
  ``mean(weight)``, within ``z`` standard errors of the estimator plus the quadrature's own
  accuracy.
- :func:`chi2_goodness_of_fit`: a chi-square test of ``sample_local`` against ``pdf_local``
  in the style of Mitsuba 3's ``ChiSquareTest``: the hemisphere is cut into a (θ, φ) grid,
  the expected count of each cell is the sample count times the integral of ``pdf_local`` over
  the cell (Gauss–Legendre per cell), cells expecting fewer than 5 samples are pooled, and the
  mass ``pdf_local`` leaves out of the hemisphere is compared with the count of invalid
  samples (``pdf == 0``) as one more cell. A sample in a cell of zero expected mass fails
  outright.
- :func:`check_albedo_at_most_one`: ``a(wo) <= 1`` (and ``<= material.albedo_bound``) up to
  the estimator's statistical error.

All randomness comes from explicit seeds, so every check is deterministic.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from scipy import stats

from sim_core.errors import InvalidInputError
from sim_core.materials import Material


# -------------------------------------------------------------------------------------------
# Directions
# -------------------------------------------------------------------------------------------
def spherical(theta: np.ndarray | float, phi: np.ndarray | float = 0.0) -> np.ndarray:
    """Unit vectors (n, 3) from polar angle ``theta`` and azimuth ``phi`` [rad]."""
    theta, phi = np.broadcast_arrays(np.atleast_1d(theta), np.atleast_1d(phi))
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=1).astype(float)


def direction_deg(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    """One unit vector (3,) from angles in degrees."""
    return spherical(math.radians(theta_deg), math.radians(phi_deg))[0]


def repeat(w: np.ndarray, n: int) -> np.ndarray:
    """Tile a single direction (3,) into (n, 3)."""
    return np.tile(np.asarray(w, float).reshape(1, 3), (n, 1))


# -------------------------------------------------------------------------------------------
# Albedo
# -------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=8)
def hemisphere_quadrature(n_mu: int = 512, n_phi: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (m, 3) and weights (m,) for ``∫ g(w) dw`` over the upper hemisphere.

    Gauss–Legendre in ``μ = cos θ`` on [0, 1] times the midpoint rule in ``φ`` (spectrally
    accurate for smooth periodic integrands). Resolves lobes down to a width of ~0.05 rad.
    """
    x, wx = np.polynomial.legendre.leggauss(n_mu)
    mu = 0.5 * (x + 1.0)
    w_mu = 0.5 * wx
    phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    mu_g, phi_g = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1.0 - mu_g * mu_g)
    dirs = np.stack([s * np.cos(phi_g), s * np.sin(phi_g), mu_g], axis=-1).reshape(-1, 3)
    weights = (w_mu[:, None] * np.full(n_phi, 2.0 * np.pi / n_phi)[None, :]).ravel()
    dirs.setflags(write=False)
    weights.setflags(write=False)
    return dirs, weights


def albedo_quadrature(material: Material, wo: np.ndarray, n_mu: int = 512) -> float:
    """``∫ f(wi, wo) cos θi dwi`` by quadrature (see :func:`hemisphere_quadrature`)."""
    dirs, weights = hemisphere_quadrature(n_mu, 2 * n_mu)
    f = material.eval_local(dirs, repeat(wo, len(dirs)))
    return float(np.sum(f * dirs[:, 2] * weights))


def albedo_sampled(
    material: Material, wo: np.ndarray, n_samples: int, seed: int
) -> tuple[float, float]:
    """Sampling estimate of the albedo: ``(mean(weight), standard error of the mean)``."""
    rng = np.random.default_rng(seed)
    s = material.sample_local(repeat(wo, n_samples), rng.random((n_samples, 3)))
    return float(np.mean(s.weight)), float(np.std(s.weight) / math.sqrt(n_samples))


def check_albedo_consistency(
    material: Material,
    wo: np.ndarray,
    n_samples: int = 100_000,
    seed: int = 0,
    z: float = 5.0,
    quad_tol: float = 2e-3,
) -> None:
    """Assert ``|mean(weight) - quadrature| <= z * stderr + quad_tol``.

    ``z = 5`` makes a false alarm a < 1e-6 event for a correct model; ``quad_tol`` is the
    accuracy of the quadrature for lobes at least ~0.05 rad wide.
    """
    quad = albedo_quadrature(material, wo)
    mean, se = albedo_sampled(material, wo, n_samples, seed)
    tol = z * se + quad_tol
    assert abs(mean - quad) <= tol, (
        f"{material!r} at wo={wo}: sampled albedo {mean:.6f} ± {se:.2e} vs quadrature "
        f"{quad:.6f} (tolerance {tol:.2e})"
    )


def check_albedo_at_most_one(
    material: Material,
    wos: np.ndarray,
    n_samples: int = 20_000,
    seed: int = 0,
    z: float = 5.0,
    use_quadrature: bool = False,
) -> None:
    """Assert ``a(wo) <= min(1, albedo_bound)`` for every row of ``wos``.

    The sampling estimate is allowed ``z`` standard errors of slack (a true albedo above the
    bound by more than that is caught); with ``use_quadrature`` (for smooth BRDFs) the
    quadrature is checked too, with a relative slack of 1e-6.
    """
    bound = min(1.0, material.albedo_bound)
    for k, wo in enumerate(np.atleast_2d(wos)):
        mean, se = albedo_sampled(material, wo, n_samples, seed + k)
        assert mean <= bound + z * se + 1e-12, (
            f"{material!r} at wo={wo}: sampled albedo {mean:.6f} ± {se:.2e} > {bound:.6f}"
        )
        if use_quadrature:
            quad = albedo_quadrature(material, wo)
            assert quad <= bound * (1.0 + 1e-6), (
                f"{material!r} at wo={wo}: quadrature albedo {quad:.6f} > {bound:.6f}"
            )


# -------------------------------------------------------------------------------------------
# Chi-square goodness of fit (Mitsuba 3 style)
# -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Chi2Result:
    """Outcome of :func:`chi2_goodness_of_fit`."""

    p_value: float
    statistic: float
    dof: int
    n_valid: int
    expected_invalid: float
    message: str

    def passed(self, significance: float) -> bool:
        return self.p_value >= significance


def _cell_integrals(
    material: Material, wo: np.ndarray, n_theta: int, n_phi: int, order: int
) -> np.ndarray:
    """∫ pdf_local dω over each (θ, φ) cell of the upper hemisphere, shape (n_theta, n_phi)."""
    x, wx = np.polynomial.legendre.leggauss(order)
    dt = 0.5 * np.pi / n_theta
    dp = 2.0 * np.pi / n_phi
    t_edges = np.arange(n_theta) * dt
    p_edges = np.arange(n_phi) * dp
    theta = t_edges[:, None] + 0.5 * dt * (x[None, :] + 1.0)  # (n_theta, order)
    phi = p_edges[:, None] + 0.5 * dp * (x[None, :] + 1.0)  # (n_phi, order)
    th = theta[:, None, :, None]
    ph = phi[None, :, None, :]
    th, ph = np.broadcast_arrays(th, ph)
    dirs = spherical(th.ravel(), ph.ravel())
    pdf = material.pdf_local(dirs, repeat(wo, len(dirs))).reshape(th.shape)
    w = (0.5 * dt * wx)[None, None, :, None] * (0.5 * dp * wx)[None, None, None, :]
    return np.sum(pdf * np.sin(th) * w, axis=(2, 3))


def chi2_goodness_of_fit(
    material: Material,
    wo: np.ndarray,
    n_samples: int = 200_000,
    n_theta: int = 18,
    n_phi: int = 36,
    order: int = 16,
    seed: int = 0,
    min_expected: float = 5.0,
) -> Chi2Result:
    """Chi-square test of the histogram of ``sample_local(wo)`` against ``pdf_local``."""
    rng = np.random.default_rng(seed)
    s = material.sample_local(repeat(wo, n_samples), rng.random((n_samples, 3)))
    valid = s.pdf > 0.0
    wi = s.wi[valid]
    theta = np.arccos(np.clip(wi[:, 2], -1.0, 1.0))
    phi = np.mod(np.arctan2(wi[:, 1], wi[:, 0]), 2.0 * np.pi)
    it = np.minimum((theta / (0.5 * np.pi / n_theta)).astype(int), n_theta - 1)
    ip = np.minimum((phi / (2.0 * np.pi / n_phi)).astype(int), n_phi - 1)
    observed = np.zeros((n_theta, n_phi))
    np.add.at(observed, (it, ip), 1.0)

    mass = _cell_integrals(material, wo, n_theta, n_phi, order)
    expected = n_samples * mass
    n_invalid = n_samples - int(valid.sum())
    expected_invalid = n_samples * max(0.0, 1.0 - float(mass.sum()))

    obs = np.append(observed.ravel(), n_invalid)
    exp = np.append(expected.ravel(), expected_invalid)
    # A sample where the pdf says there is no mass at all is an outright failure.
    impossible = (exp == 0.0) & (obs > 0)
    if np.any(impossible):
        return Chi2Result(
            0.0,
            math.inf,
            0,
            int(valid.sum()),
            expected_invalid,
            f"{int(obs[impossible].sum())} samples fell where pdf_local integrates to 0",
        )
    small = exp < min_expected
    obs_c = np.append(obs[~small], obs[small].sum())
    exp_c = np.append(exp[~small], exp[small].sum())
    keep = exp_c > 0.0
    obs_c, exp_c = obs_c[keep], exp_c[keep]
    stat = float(np.sum((obs_c - exp_c) ** 2 / exp_c))
    dof = max(len(obs_c) - 1, 1)
    p = float(stats.chi2.sf(stat, dof))
    return Chi2Result(
        p,
        stat,
        dof,
        int(valid.sum()),
        expected_invalid,
        f"chi2 = {stat:.1f} with {dof} dof, p = {p:.3g}; invalid samples {n_invalid} vs "
        f"expected {expected_invalid:.1f}; pdf mass on hemisphere {mass.sum():.5f}",
    )


def check_chi2(
    material: Material, wo: np.ndarray, significance: float = 1e-3, **kwargs: int
) -> Chi2Result:
    """Assert that :func:`chi2_goodness_of_fit` does not reject at ``significance``."""
    result = chi2_goodness_of_fit(material, wo, **kwargs)
    assert result.passed(significance), f"{material!r} at wo={wo}: {result.message}"
    return result


def check_out_of_range_rejected(
    make: Callable[..., Material], params: dict[str, Any], field: str, value: float, allowed: str
) -> None:
    """Assert ``make(**params)`` with ``field = value`` raises an InvalidInputError naming the
    field, the value and the ``allowed`` range."""
    with pytest.raises(InvalidInputError) as excinfo:
        make(**{**params, field: value})
    assert excinfo.value.field == field
    assert f"{field} = {value!r} is outside {allowed}" in str(excinfo.value)
