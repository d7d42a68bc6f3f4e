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

from sim_core.errors import InvalidInputError
from sim_core.materials.base import Material, finish_sample
from sim_core.materials.kernels import U_MAX

__all__ = [
    "U_MAX",
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
