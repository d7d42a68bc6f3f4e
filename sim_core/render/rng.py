"""Counter-based random numbers for the renderer (numba).

Every uniform number is a hash of (seed, sample pass, pixel, bounce, dimension) through the
splitmix64 finaliser (Steele, Lea & Flood 2014). No generator state travels between rays, so a
path's numbers never depend on which other paths are alive, how passes are batched, or how the
work is spread over threads: the same seed gives the same image bit for bit. This plays the role
ARCHITECTURE.md gives ``numpy.random.Generator`` (explicit seed, reproducible) inside compiled
kernels, where a shared Generator would serialise the work.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S32 = np.uint64(32)
_LOW32 = np.uint64(0xFFFFFFFF)
_INV_2_32 = 1.0 / 4294967296.0


@njit(cache=True, inline="always")
def mix64(z):
    """splitmix64 finaliser: a bijective avalanche hash of a uint64."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True, inline="always")
def seed_key(seed):
    """Hash of the render seed; computed once per render."""
    return mix64(np.uint64(seed) + _GOLDEN)


@njit(cache=True, inline="always")
def path_key(seed_hash, sample_pass, pixel):
    """Key of one pixel's path in one sample pass: one hash of (pass, pixel) under the seed.

    ``sample_pass * 2^32 + pixel`` is unique for images below 2^32 pixels, and mix64 is a
    bijection, so different paths get different keys.
    """
    return mix64(seed_hash ^ ((np.uint64(sample_pass) << _S32) + np.uint64(pixel)))


@njit(cache=True, inline="always")
def uniform_pair(key, bounce, pair):
    """Two uniforms in [0, 1) (the high and low 32 bits of one hash), dims 2*pair, 2*pair+1.

    32-bit resolution (2.3e-10) is far below any Monte Carlo error of this renderer.
    """
    h = mix64(key + np.uint64(bounce * 8 + pair + 1) * _GOLDEN)
    return float(h >> _S32) * _INV_2_32, float(h & _LOW32) * _INV_2_32

