"""Random draws of the sensor model that stay finite for any mean (seed eq. 16)."""

from __future__ import annotations

import numpy as np

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
