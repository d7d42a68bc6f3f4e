"""What the models share outside the compiled kernels: parameter validation and the diffuse +
microfacet sampling mixture (``finish_sample``, defined in :mod:`sim_core.materials.base`, is
re-exported here).

The scattering formulas themselves (the Beckmann normal distribution and its sampling, the
Schlick-type power-law Fresnel term and the full unpolarised dielectric Fresnel equations, the
V-cavity shadowing-masking term, cosine-hemisphere sampling), in the spirit of pbrt-v4's
``util/scattering.h``, are scalar numba kernels in :mod:`sim_core.materials.kernels`, together
with their numerical guards (``COS_EPS``, ``U_MAX``; ``U_MAX`` is re-exported here).

Conventions are those of :mod:`sim_core.materials.base`: shading frame with the normal on +z,
``wi`` towards the light, ``wo`` towards the viewer, both pointing away from the surface, arrays
of shape ``(n, 3) float64``.
"""

from __future__ import annotations

import math
import numbers
from abc import abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from sim_core.errors import InvalidInputError
from sim_core.materials.base import Material, finish_sample
from sim_core.materials.kernels import P_SPEC_MIN, U_MAX, fixed_lobes

__all__ = [
    "U_MAX",
    "FixedLobeMixture",
    "MicrofacetMixture",
    "check_parameter",
    "finish_sample",
]


# -------------------------------------------------------------------------------------------
# Parameter validation
# -------------------------------------------------------------------------------------------
def check_parameter(field: str, value: object, lo: float, hi: float, *, model: str) -> float:
    """Return ``value`` as float if it is a real number in ``[lo, hi]``; raise otherwise.

    Raises
    ------
    InvalidInputError
        With ``field`` and a message naming the parameter, the value received and the allowed
        range, e.g. ``"ks = 1.3 is outside [0, 1] (seed-microfacet)"``.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InvalidInputError(
            field,
            f"{field} = {value!r} is not a real number; allowed range [{lo:g}, {hi:g}] ({model})",
        )
    v = float(value)
    if not (math.isfinite(v) and lo <= v <= hi):
        raise InvalidInputError(field, f"{field} = {value!r} is outside [{lo:g}, {hi:g}] ({model})")
    return v


class MicrofacetMixture(Material):
    """Sampling shared by diffuse + Beckmann microfacet models.

    ``sample_local`` picks the specular lobe with probability ``p_spec`` (``u[:, 2] < p_spec``)
    and the diffuse lobe with ``p_diff``, in proportion to each lobe's albedo at ``wo``: ``kd``
    for the diffuse lobe, ``ks F(θo)`` for the specular one (``F`` at the mirror direction),
    with ``p_spec`` at least ``kernels.P_SPEC_MIN`` when both lobes are present; a model with
    one lobe samples only that one, and both are 0 when ``ks = kd = 0`` (a black surface: every
    sample has weight 0). See ``kernels.lobe_probabilities``.

    - diffuse lobe: cosine-weighted hemisphere, density ``cos θi / π``;
    - specular lobe: half vector ``h`` from ``D(h) cos θh`` (Beckmann, width ``alpha``),
      ``wi = reflect(wo, h)``, density ``D(h) cos θh / (4 wo·h)``.

    ``pdf_local`` is the exact mixture ``p_spec pdf_spec + p_diff pdf_diffuse`` for both
    directions above the horizon and 0 otherwise; specular samples that land below the horizon
    are returned as invalid (``pdf = weight = 0``), so ``pdf_local`` integrates to the
    probability of a valid sample. The kernels are ``kernels.mixture_pdf`` and the microfacet
    branch of ``kernels.sample_brdf``; ``alpha``, ``ks``, ``kd`` and the model's Fresnel
    parameters go into ``kernel_params()``.
    """

    @property
    @abstractmethod
    def alpha(self) -> float:
        """Beckmann width ``α`` of the specular lobe."""


@dataclass(frozen=True)
class FixedLobeMixture(Material):
    """The BRDF of a microfacet model, sampled by a *fixed* choice of its lobes.

    The specular (Beckmann) lobe with probability ``p_spec`` for every ``wo``, the diffuse
    (cosine) one with ``1 - p_spec``, the pdf the exact mixture, no Fresnel factor in the
    choice (:func:`sim_core.materials.kernels.fixed_lobes`). ``p_spec = 0.5`` is the naive
    estimator issue 16 compares the renderer's variance against; ``ks / (ks + kd)`` is the
    renderer's former lobe choice. Same kernel and values as ``base`` (only the sampling
    differs), so a scene with it renders the same image with another noise. A reference for
    variance measurements, not a material of scene files.

    Parameters
    ----------
    base : MicrofacetMixture
        The model whose BRDF is sampled.
    p_spec : float, default 0.5
        Probability of the specular lobe, in [``kernels.P_SPEC_MIN``, 1).
    """

    base: MicrofacetMixture
    p_spec: float = 0.5

    name: ClassVar[str] = "fixed-lobe-mixture"

    def __post_init__(self) -> None:
        if not isinstance(self.base, MicrofacetMixture):
            raise InvalidInputError(
                "base", f"base = {self.base!r} is not a microfacet model (its lobes are fixed)")
        p = check_parameter("p_spec", self.p_spec, P_SPEC_MIN, math.nextafter(1.0, 0.0),
                            model=self.name)
        object.__setattr__(self, "p_spec", p)

    @property
    def kernel_kind(self) -> int:
        return self.base.kernel_kind

    def kernel_params(self) -> np.ndarray:
        return fixed_lobes(self.base.kernel_params(), self.p_spec)

    @property
    def albedo_bound(self) -> float:
        return self.base.albedo_bound
