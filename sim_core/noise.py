"""Random draws of the sensor model that stay finite for any mean (seed eq. 16), and the mean
of a readout that clips its noise at 0."""

from __future__ import annotations

import numpy as np
from scipy import special

#: above this mean the Poisson distribution is replaced by its normal approximation; numpy's
#: Poisson sampler rejects means above ~9.2e18 (int64) and is slow for huge means, while the
#: relative error of the normal approximation at 1e7 is below 1e-4 in every moment we use.
NORMAL_APPROX_MEAN = 1e7
#: standard deviations above 0 beyond which a clipped readout's mean is its charge's
#: (:func:`clipped_normal_mean`)
CENSORED_T = 8.5


def safe_poisson(rng: np.random.Generator, mean: np.ndarray) -> np.ndarray:
    """Poisson draws (float64) for means of any size.

    Means <= 0 give exactly 0 (no signal, no noise); means above :data:`NORMAL_APPROX_MEAN`
    use ``mean + sqrt(mean) * N(0, 1)``, clipped at 0. Non-finite means are an error.

    >>> rng = np.random.default_rng(0)
    >>> safe_poisson(rng, np.array([0.0, -1.0, 1e12])).shape
    (3,)
    """
    m = np.asarray(mean, dtype=np.float64)
    if not np.all(np.isfinite(m)):
        raise ValueError("Poisson means must be finite")
    m = np.maximum(m, 0.0)
    out = np.empty_like(m)
    small = m <= NORMAL_APPROX_MEAN
    out[small] = rng.poisson(m[small])
    big = ~small
    if big.any():
        mb = m[big]
        out[big] = np.maximum(mb + np.sqrt(mb) * rng.standard_normal(mb.shape), 0.0)
    return out


def clipped_normal_mean(mean: np.ndarray, std: np.ndarray) -> np.ndarray:
    """``E[max(X, 0)]`` for ``X ~ N(mean, std^2)``: what a tap reads on average when its noise
    is added before the readout clips negative charge at 0 (:func:`sim_core.sensor.expose`).

        E[max(X, 0)] = mu Phi(mu / s) + s phi(mu / s)

    (the mean of a normal distribution censored at 0; ``Phi`` and ``phi`` the standard normal
    distribution and density). It is at least ``max(mu, 0)``, equals ``s / sqrt(2 pi)`` at
    ``mu = 0`` and is ``mu`` to double precision once ``mu`` is :data:`CENSORED_T` ``s`` above 0.
    ``std`` 0 gives ``max(mu, 0)``; a negative or non-finite ``std`` is an error.

    >>> float(clipped_normal_mean(np.array(0.0), np.array(1.0)))  # 1 / sqrt(2 pi)
    0.3989422804014327
    """
    mu, s = np.broadcast_arrays(np.asarray(mean, dtype=np.float64),
                                np.asarray(std, dtype=np.float64))
    if not (np.all(np.isfinite(s)) and np.all(s >= 0.0)):
        raise ValueError("standard deviations must be finite and >= 0")
    out = np.array(np.maximum(mu, 0.0), dtype=np.float64)  # an array, 0-d too
    # Only where mu is less than CENSORED_T standard deviations above 0 does the clipping show
    # (beyond, s phi(t) - mu (1 - Phi(t)) < 1e-16 mu). There s = 0 only below 0: t = -inf.
    near = mu < CENSORED_T * s
    if np.any(near):
        mu_n, s_n = mu[near], s[near]
        with np.errstate(over="ignore", divide="ignore"):  # t = -inf, t^2 = inf: Phi, phi 0
            t = mu_n / s_n
            density = np.exp(-0.5 * t * t) / np.sqrt(2.0 * np.pi)
        out[near] = np.maximum(mu_n * special.ndtr(t) + s_n * density, out[near])
    return out
