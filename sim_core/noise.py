"""Random draws of the sensor model that stay finite for any mean (seed eq. 16), and the mean
of a readout that clips its noise at 0."""

from __future__ import annotations

import numpy as np
from scipy import special

#: above this mean the Poisson distribution is replaced by its normal approximation; numpy's
#: Poisson sampler rejects means above ~9.2e18 (int64) and is slow for huge means, while the
#: relative error of the normal approximation at 1e7 is below 1e-4 in every moment we use.
NORMAL_APPROX_MEAN = 1e7


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
    ``mu = 0`` and tends to ``mu`` once ``mu`` is a few ``s`` above 0. ``std`` 0 gives
    ``max(mu, 0)`` (no division by it); a negative or non-finite ``std`` is an error.

    >>> float(clipped_normal_mean(np.array(0.0), np.array(1.0)))  # 1 / sqrt(2 pi)
    0.3989422804014327
    """
    mu = np.asarray(mean, dtype=np.float64)
    s = np.asarray(std, dtype=np.float64)
    if not (np.all(np.isfinite(s)) and np.all(s >= 0.0)):
        raise ValueError("standard deviations must be finite and >= 0")
    positive = s > 0.0
    with np.errstate(over="ignore"):  # t = +-inf, t^2 = inf far from 0: Phi 0 or 1, phi 0
        t = np.where(positive, mu / np.where(positive, s, 1.0), 0.0)
        density = np.exp(-0.5 * t * t) / np.sqrt(2.0 * np.pi)
    censored = mu * special.ndtr(t) + s * density
    return np.where(positive, np.maximum(censored, np.maximum(mu, 0.0)), np.maximum(mu, 0.0))
