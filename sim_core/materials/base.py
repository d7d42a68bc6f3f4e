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

Compiled kernels
----------------
The formulas exist once, as scalar numba kernels in :mod:`sim_core.materials.kernels`, which
the renderer calls per ray. A model states which kernel it is (``kernel_kind``, one of
``kernels.KIND_*``) and its parameters (``kernel_params()``, a float64 vector of length
``kernels.N_PARAMS``, or longer for a model with data, e.g. a measured table: the first
``N_PARAMS`` entries are then its header); ``eval_local``, ``pdf_local`` and
``sample_local`` are implemented here, once, by the kernels' batch wrappers, so the numpy API
and the renderer cannot disagree.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from sim_core.materials import kernels
from sim_core.numba_runtime import PARALLEL_KERNEL_LOCK


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

    The branchless construction of Duff et al. (2017), the same compiled
    :func:`~sim_core.materials.kernels.duff_frame` the renderer uses.

    Parameters
    ----------
    n : (m, 3) float
        Unit normals.
    """
    with PARALLEL_KERNEL_LOCK:
        return kernels.frame_batch(np.ascontiguousarray(n, dtype=np.float64))


def to_local(w: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Express world directions ``w`` in the frames ``(t, b, n)``; all ``(m, 3)``."""
    return np.stack(
        [np.einsum("ij,ij->i", w, t), np.einsum("ij,ij->i", w, b), np.einsum("ij,ij->i", w, n)],
        axis=1,
    )


def to_world(w: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_local`."""
    return w[:, 0:1] * t + w[:, 1:2] * b + w[:, 2:3] * n


def _directions(w: np.ndarray, name: str) -> np.ndarray:
    """``w`` as a C-contiguous float64 array of shape (n, 3), the layout the kernels take."""
    w = np.ascontiguousarray(w, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {w.shape}")
    return w


def _pair(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    wi, wo = _directions(wi, "wi"), _directions(wo, "wo")
    if wi.shape != wo.shape:
        raise ValueError(f"wi and wo must have the same shape, got {wi.shape} and {wo.shape}")
    return wi, wo


class Material(ABC):
    """A reflectance model; see the module docstring for the contract."""

    #: short name used in scene files and error messages
    name: str = "material"

    @property
    @abstractmethod
    def kernel_kind(self) -> int:
        """Model id of the compiled kernels, one of ``kernels.KIND_*``.

        A class constant in every model (``kernel_kind: ClassVar[int] = KIND_...``).
        """

    @abstractmethod
    def kernel_params(self) -> np.ndarray:
        """The model's parameters as the kernels read them: shape ``(kernels.N_PARAMS,)``,
        float64, unused entries 0; or longer, a header of ``N_PARAMS`` entries followed by the
        model's data (the tabulated material).

        Built by the ``kernels.*_params`` function of the model, which also folds in derived
        constants (Beckmann width, lobe probabilities, normalisations) so that the kernels do
        not recompute them per ray.
        """

    @property
    @abstractmethod
    def albedo_bound(self) -> float:
        """Upper bound of the directional albedo over all ``wo`` (<= 1)."""

    def _kernel(self) -> tuple[int, np.ndarray]:
        p = np.ascontiguousarray(self.kernel_params(), dtype=np.float64)
        if p.ndim != 1 or p.shape[0] < kernels.N_PARAMS:  # the kernels index the header
            raise ValueError(                              # without bounds checks
                f"kernel_params() must have shape (L,) with L >= {kernels.N_PARAMS}, "
                f"not {p.shape}"
            )
        return int(self.kernel_kind), p

    def eval_local(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """BRDF value f_r [1/sr] without the cosine, shading frame; ``kernels.eval_brdf``."""
        wi, wo = _pair(wi, wo)
        with PARALLEL_KERNEL_LOCK:
            return kernels.eval_batch(*self._kernel(), wi, wo)

    def pdf_local(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Solid-angle pdf [1/sr] of ``sample_local`` returning ``wi``; ``kernels.pdf_brdf``."""
        wi, wo = _pair(wi, wo)
        with PARALLEL_KERNEL_LOCK:
            return kernels.pdf_batch(*self._kernel(), wi, wo)

    def sample_local(self, wo: np.ndarray, u: np.ndarray) -> BSDFSample:
        """Importance-sample ``wi`` for ``wo`` from uniforms ``u`` (n, 3); ``kernels.sample_brdf``.

        A subclass that overrides :meth:`eval_local` or :meth:`pdf_local` in Python (invisible to
        the kernels, and to the renderer) gets its samples completed by :func:`finish_sample`
        with its own methods, so that ``pdf == pdf_local(wi, wo)`` holds for it too.
        """
        wo, u = _directions(wo, "wo"), _directions(u, "u")
        if u.shape != wo.shape:
            raise ValueError(f"u must have the shape of wo, got {u.shape} and {wo.shape}")
        with PARALLEL_KERNEL_LOCK:
            wi, pdf, weight = kernels.sample_batch(*self._kernel(), wo, u)
        cls = type(self)
        if cls.eval_local is not Material.eval_local or cls.pdf_local is not Material.pdf_local:
            return finish_sample(self, wi, wo)
        return BSDFSample(wi=wi, pdf=pdf, weight=weight)

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


def finish_sample(material: Material, wi: np.ndarray, wo: np.ndarray) -> BSDFSample:
    """Complete a batch of sampled ``wi`` into a :class:`BSDFSample` with the numpy methods.

    ``pdf`` is computed with ``material.pdf_local`` and ``f`` with ``material.eval_local`` (so
    that a subclass overriding them, e.g. a deliberately broken model in the tests, is honoured);
    ``weight = f cos θi / pdf`` where ``pdf > 0`` and 0 elsewhere (``kernels.sample_weight``).
    """
    wi = np.ascontiguousarray(wi, dtype=np.float64)
    pdf = np.ascontiguousarray(material.pdf_local(wi, wo), dtype=np.float64)
    f = np.ascontiguousarray(material.eval_local(wi, wo), dtype=np.float64)
    return BSDFSample(wi=wi, pdf=pdf, weight=kernels.weight_batch(f, wi, pdf))
