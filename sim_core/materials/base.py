"""The contract every material (BRDF) fulfils, stated once.

Frames and directions
---------------------
All methods work in the local *shading frame* of a surface point: the surface normal is +z, so
``cos_theta = w[..., 2]``. Directions are unit vectors of shape ``(n, 3) float64`` pointing
*away* from the surface: ``wo`` towards the viewer (the previous path vertex), ``wi`` towards
the light (the next path vertex). World-frame wrappers (``evaluate``, ``pdf``, ``sample`` with an
explicit normal) build an orthonormal frame around ``n`` and call the local methods.

Contract
--------
- ``eval_local(wi, wo) -> (n,) float64``: the BRDF value f_r [1/sr], *without* the cosine
  factor. Zero wherever ``wi`` or ``wo`` lies at or below the horizon (z <= 0). Never negative,
  never NaN or inf, for any unit input (grazing, exactly tangent, coincident directions).
- ``pdf_local(wi, wo) -> (n,) float64``: the solid-angle density [1/sr] with which
  ``sample_local`` returns ``wi`` given ``wo``. Finite and >= 0; zero wherever ``wi`` or ``wo``
  lies at or below the horizon. Probability mass a sampler sends below the horizon (e.g. a
  specular lobe at grazing view) is returned as invalid samples, so ``pdf_local`` integrates
  over the hemisphere to the probability of a valid sample (at most 1). It is positive wherever
  ``eval_local`` is (up to float64 underflow), so the sampling estimator misses no energy.
- ``sample_local(wo, u) -> BSDFSample``: ``u`` is ``(n, 3) float64`` of uniform numbers in
  [0, 1) (the third one selects a lobe where there are several). Returns the sampled ``wi``,
  its ``pdf`` and ``weight = f(wi, wo) * cos_theta_i / pdf`` (0 where the sample is invalid,
  e.g. below the horizon or pdf == 0). ``weight`` is finite and >= 0, and
  ``pdf == pdf_local(wi, wo)`` exactly.
- ``albedo_bound``: an upper bound of the directional albedo
  ``a(wo) = integral f(wi, wo) cos_theta_i dwi`` over all ``wo``; at most 1 for every physical
  material. Tests check ``a(wo) <= 1`` numerically.

Consistency required of every implementation (and checked by the shared test harness in
``tests/sim_core/materials/harness.py``): the sampling estimator ``mean(weight)`` equals a
quadrature of ``eval_local * cos_theta_i`` over the hemisphere, and ``pdf_local`` agrees with
the histogram of ``sample_local`` (chi-square test).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BSDFSample:
    """A batch of sampled incident directions.

    Attributes
    ----------
    wi : (n, 3) float64
        Sampled directions in the shading frame, unit length.
    pdf : (n,) float64
        Solid-angle density of each sample [1/sr]; 0 marks an invalid sample.
    weight : (n,) float64
        ``f(wi, wo) * cos_theta_i / pdf``; 0 where the sample is invalid.
    """

    wi: np.ndarray
    pdf: np.ndarray
    weight: np.ndarray


def frame_from_normal(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent vectors ``(t, b)`` completing unit normals ``n`` to right-handed frames.

    Branchless construction of Duff et al. (2017), "Building an Orthonormal Basis, Revisited";
    exact for every unit normal including n = (0, 0, -1).

    Parameters
    ----------
    n : (m, 3) float
        Unit normals.
    """
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    # a is finite because sign + z has the magnitude 1 + |z| >= 1.
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=1)
    bt = np.stack([b, sign + y * y * a, -y], axis=1)
    return t, bt


def to_local(w: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Express world directions ``w`` in the frames ``(t, b, n)``; all ``(m, 3)``."""
    return np.stack(
        [np.einsum("ij,ij->i", w, t), np.einsum("ij,ij->i", w, b), np.einsum("ij,ij->i", w, n)],
        axis=1,
    )


def to_world(w: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_local`."""
    return w[:, 0:1] * t + w[:, 1:2] * b + w[:, 2:3] * n


class Material(ABC):
    """A reflectance model; see the module docstring for the contract."""

    #: short name used in scene files and error messages
    name: str = "material"

    @abstractmethod
    def eval_local(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """BRDF value f_r [1/sr] without the cosine, shading frame."""

    @abstractmethod
    def pdf_local(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Solid-angle pdf [1/sr] of ``sample_local`` returning ``wi``."""

    @abstractmethod
    def sample_local(self, wo: np.ndarray, u: np.ndarray) -> BSDFSample:
        """Importance-sample ``wi`` for ``wo`` from uniforms ``u`` (n, 3)."""

    @property
    @abstractmethod
    def albedo_bound(self) -> float:
        """Upper bound of the directional albedo over all ``wo`` (<= 1)."""

    # World-frame conveniences -------------------------------------------------------------
    def evaluate(self, wi: np.ndarray, wo: np.ndarray, n: np.ndarray) -> np.ndarray:
        """BRDF value for world directions ``wi``, ``wo`` and unit normals ``n``, (m, 3)."""
        t, b = frame_from_normal(n)
        return self.eval_local(to_local(wi, t, b, n), to_local(wo, t, b, n))

    def pdf(self, wi: np.ndarray, wo: np.ndarray, n: np.ndarray) -> np.ndarray:
        """Sampling pdf for world directions; see :meth:`pdf_local`."""
        t, b = frame_from_normal(n)
        return self.pdf_local(to_local(wi, t, b, n), to_local(wo, t, b, n))

    def sample(self, wo: np.ndarray, n: np.ndarray, u: np.ndarray) -> BSDFSample:
        """Sample world directions; see :meth:`sample_local`."""
        t, b = frame_from_normal(n)
        s = self.sample_local(to_local(wo, t, b, n), u)
        return BSDFSample(wi=to_world(s.wi, t, b, n), pdf=s.pdf, weight=s.weight)
