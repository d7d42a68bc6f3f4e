"""The Cook–Torrance BRDF as fitted to relay-wall materials for NLOS imaging, eqs. (8)-(12)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np

from sim_core.errors import InvalidInputError
from sim_core.materials.kernels import KIND_COOK_TORRANCE, cook_torrance_params
from sim_core.materials.microfacet import MicrofacetMixture, check_parameter

__all__ = ["FRESNEL_ANGLES", "CookTorrance"]

_MODEL = "cook-torrance"

#: allowed values of ``CookTorrance.fresnel_angle``
FRESNEL_ANGLES: tuple[str, ...] = ("incidence", "half")


@dataclass(frozen=True)
class CookTorrance(MicrofacetMixture):
    r"""Cook–Torrance BRDF: Lambertian term plus a Beckmann / V-cavity / dielectric-Fresnel lobe.

    Models building materials used as relay walls (black protective shield, white matte tile,
    black glossy tile) fitted by RANSAC + a genetic algorithm:

    .. math::

        f_r = \frac{k_d}{\pi} + k_s \frac{D\,G\,F(\theta)}{4\cos\theta_i\cos\theta_r}

        D = \frac{P(\tan^2\alpha)}{\cos^4\alpha},\quad
        P(x) = \frac{e^{-x/m^2}}{\pi m^2},\quad
        G = \min\Big(1, \frac{2\cos\alpha\cos\theta_r}{\cos\theta_o},
                        \frac{2\cos\alpha\cos\theta_i}{\cos\theta_o}\Big)

    and ``F`` the unpolarised Fresnel reflectance ``(r_s + r_p)/2`` from air (``n1 = 1``) into
    a medium of index ``n2``. In the paper's notation ``α`` is the angle between the half vector
    and the normal and ``θo`` the angle between the light and the half vector (``γ`` elsewhere
    in this package); ``θi`` is the incidence angle (``wi``, towards the light), ``θr`` the
    reflection angle (``wo``, towards the viewer).

    Source: "Study on BRDF Scattering Characteristics of Relay Wall in Non-Line-of-Sight Imaging
    Based on Time-gated SPAD Array" (in Chinese), eqs. (5) and (8)-(12); parameter bounds of
    its GA fit (kd, ks, m in [0, 1], n2 in [1, 3], kd + ks <= 1); presets from the averages
    below its Table 2.

    Parameters
    ----------
    kd : float, default 0.05
        Diffuse coefficient (the diffuse albedo), in [0, 1].
    ks : float, default 0.90
        Specular coefficient, in [0, 1]; ``kd + ks <= 1`` as in the paper (energy conservation;
        the specular lobe reflects at most everything).
    m : float, default 0.08
        RMS slope of the microfacets, used directly as the Beckmann width; in [1e-6, 1]. The
        paper allows ``m = 0``, a mirror (delta distribution) this model cannot evaluate.
    n2 : float, default 1.60
        Refractive index of the surface medium, in [1, 3] (the paper's GA bounds; ``n2 = 1``
        reflects nothing specularly).
    fresnel_angle : {"incidence", "half"}, default "incidence"
        Angle at which ``F`` is evaluated. ``"incidence"``: ``F(θi)`` as printed in eqs. (7),
        (8) and (12). ``"half"``: ``F(θo)``, the angle between ``wi`` and the half vector, the
        usual microfacet choice.

    The defaults are the paper's base parameter set of its Fig. 10,
    ``[m, n2, kd, ks] = [0.08, 1.60, 0.05, 0.90]``.

    Normal distribution
    -------------------
    Eq. (9) as printed, ``P(x) = exp(-x/m²)/(π m²)`` with ``x = tan²α``, is the Beckmann *slope*
    density; as a distribution of normals it needs the factor ``1/cos⁴α`` of eq. (5) to be
    normalised (``∫ D cos α dω = 1``; eq. (5)'s stated condition ``∫ D dα = 1`` is loose). We use
    the normalised form ``D = exp(-tan²α/m²) / (π m² cos⁴α)``.

    Sampling
    --------
    Mixture of cosine-hemisphere sampling (diffuse) and Beckmann half-vector sampling
    (specular), each lobe chosen in proportion to its albedo at ``wo`` (``kd`` against
    ``ks F(θo)``); the pdf is the exact mixture (see
    :class:`~sim_core.materials.microfacet.MicrofacetMixture`). The Fresnel factor is not
    importance-sampled within the specular lobe.

    Reciprocity
    -----------
    Only ``fresnel_angle="half"`` is reciprocal (``wi·h = wo·h``). The paper's default
    ``"incidence"`` evaluates ``F`` at ``θi`` only, so ``f(wi, wo) != f(wo, wi)`` whenever
    ``θi != θr``, ``ks > 0`` and ``n2 > 1``. Energy is conserved either way (``F <= 1``).

    Kernel
    ------
    ``kernels.cook_torrance_eval``; parameters ``kernels.cook_torrance_params``
    (``fresnel_angle`` encoded as 1.0 for ``"half"``, 0.0 for ``"incidence"``).
    """

    kd: float = 0.05
    ks: float = 0.90
    m: float = 0.08
    n2: float = 1.60
    fresnel_angle: Literal["incidence", "half"] = "incidence"

    name: ClassVar[str] = _MODEL
    kernel_kind: ClassVar[int] = KIND_COOK_TORRANCE

    def __post_init__(self) -> None:
        for field, lo, hi in (
            ("kd", 0.0, 1.0),
            ("ks", 0.0, 1.0),
            ("m", 1e-6, 1.0),
            ("n2", 1.0, 3.0),
        ):
            value = check_parameter(field, getattr(self, field), lo, hi, model=_MODEL)
            object.__setattr__(self, field, value)
        # 1e-12 absorbs rounding of decimal inputs such as 0.78 + 0.22.
        if self.ks + self.kd > 1.0 + 1e-12:
            raise InvalidInputError(
                "ks",
                f"kd + ks = {self.kd!r} + {self.ks!r} = {self.kd + self.ks:.6g} exceeds 1; "
                f"allowed: kd + ks <= 1 for energy conservation ({_MODEL})",
            )
        if self.fresnel_angle not in FRESNEL_ANGLES:
            raise InvalidInputError(
                "fresnel_angle",
                f"fresnel_angle = {self.fresnel_angle!r} is not one of "
                f"{', '.join(repr(a) for a in FRESNEL_ANGLES)} ({_MODEL})",
            )

    @property
    def alpha(self) -> float:
        """Beckmann width: the RMS slope ``m`` itself."""
        return self.m

    @property
    def albedo_bound(self) -> float:
        """``kd + ks``: the V-cavity specular lobe reflects at most a fraction 1 (``F <= 1``)."""
        return min(self.kd + self.ks, 1.0)

    def kernel_params(self) -> np.ndarray:
        return cook_torrance_params(
            self.alpha, self.kd, self.ks, self.n2, self.fresnel_angle == "half"
        )
