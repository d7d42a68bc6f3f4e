"""The microfacet BRDF of the seed paper (TOF imaging of space targets), eqs. (9)-(10)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from sim_core.errors import InvalidInputError
from sim_core.materials.kernels import KIND_SEED_MICROFACET, seed_microfacet_params
from sim_core.materials.microfacet import MicrofacetMixture, check_parameter

__all__ = ["SeedMicrofacet"]

_MODEL = "seed-microfacet"


@dataclass(frozen=True)
class SeedMicrofacet(MicrofacetMixture):
    r"""Torrance–Sparrow specular lobe plus Lambertian term, as fitted in the seed paper.

    Models the space-target materials of the seed paper (yellow thermal-control film, silicon
    solar cells) measured at 850 nm and fitted with

    .. math::

        f_r = \frac{k_s}{4\cos\theta_i\cos\theta_r} D\,F\,G + \frac{k_d}{\pi}

        D = \frac{\exp(-\tan^2\theta_h/\alpha^2)}{\pi\alpha^2\cos^4\theta_h},\quad
        F = F_0 + (1-F_0)(1-\cos\gamma)^n,\quad
        G = \min\Big(1, \frac{2\cos\theta_h\cos\theta_r}{\cos\gamma},
                        \frac{2\cos\theta_h\cos\theta_i}{\cos\gamma}\Big)

    with ``θh`` the angle between the half vector and the normal and ``γ`` the angle between
    ``wi`` and the half vector (equal to that between ``wo`` and the half vector).

    Source: Z. Yan, H. Wang, X. Liu, Q. Ning, Y. Lu, "Physics-Based TOF Imaging Simulation for
    Space Targets Based on Improved Path Tracing", Remote Sens. 14, 2868 (2022); eqs. (9)-(10),
    parameters of its Table 1 (850 nm).

    Parameters
    ----------
    ks : float, default 0.649
        Specular coefficient, dimensionless, in [0, 1].
    kd : float, default 0.081
        Diffuse coefficient (the diffuse albedo), dimensionless, in [0, 1]; ``ks + kd <= 1``
        (the specular lobe alone can reflect everything when ``F0 = 1``, so the sum bounds the
        albedo).
    fresnel_exponent : float, default 8.51
        The exponent ``n`` of the Fresnel term, dimensionless, in [0, 100]. ``n = 5`` is
        Schlick's approximation, ``n = 0`` gives ``F = 1``. Any finite ``n >= 0`` is numerically
        safe; the cap only catches typos (the paper's fits are 2.22 and 8.51).
    sigma : float, default 0.014
        RMS slope ``σ`` of the microfacets, dimensionless, in [1e-6, 1]. ``σ = 0`` (a mirror) is
        a delta distribution this model cannot evaluate; ``σ = 1`` gives ``α = √2``.
    f0 : float, default 0.775
        Fresnel reflectance at normal incidence ``F0``, in [0, 1].

    The defaults are the paper's thermal-control film.

    Width convention
    ----------------
    The paper prints ``α = √(2σ)`` with ``σ`` the RMS slope, and this class uses that literal
    relation. In the standard Beckmann convention the printed ``D`` is a Gaussian slope
    distribution with per-axis variance ``α²/2``, so ``α = √2·σ`` for a per-axis RMS slope
    ``σ`` (``√(2σ)`` is also dimensionally odd: a square root of a slope). We follow the print
    because the ``σ`` values of Table 1 were fitted with the printed formula: read with the
    standard relation, ``σ = 0.014`` would give ``α = 0.020`` instead of ``0.167``, a lobe ~8x
    narrower with a ~70x higher peak that no longer reproduces the paper's fits (its Fig. 4).

    Sampling
    --------
    Mixture of cosine-hemisphere sampling (diffuse) and Beckmann half-vector sampling
    (specular), each lobe chosen in proportion to its albedo at ``wo`` (``kd`` against
    ``ks F(θo)``); the pdf is the exact mixture (see
    :class:`~sim_core.materials.microfacet.MicrofacetMixture`).

    Reciprocity
    -----------
    Reciprocal: ``D``, ``G`` and the cosine product are symmetric in ``wi``, ``wo``, and
    ``cos γ = wi·h = wo·h`` is too.

    Kernel
    ------
    ``kernels.seed_microfacet_eval``; parameters ``kernels.seed_microfacet_params``.
    """

    ks: float = 0.649
    kd: float = 0.081
    fresnel_exponent: float = 8.51
    sigma: float = 0.014
    f0: float = 0.775

    name: ClassVar[str] = _MODEL
    kernel_kind: ClassVar[int] = KIND_SEED_MICROFACET

    def __post_init__(self) -> None:
        for field, lo, hi in (
            ("ks", 0.0, 1.0),
            ("kd", 0.0, 1.0),
            ("fresnel_exponent", 0.0, 100.0),
            ("sigma", 1e-6, 1.0),
            ("f0", 0.0, 1.0),
        ):
            value = check_parameter(field, getattr(self, field), lo, hi, model=_MODEL)
            object.__setattr__(self, field, value)
        # 1e-12 absorbs rounding of decimal inputs such as 0.7 + 0.3.
        if self.ks + self.kd > 1.0 + 1e-12:
            raise InvalidInputError(
                "kd",
                f"ks + kd = {self.ks!r} + {self.kd!r} = {self.ks + self.kd:.6g} exceeds 1; "
                f"allowed: ks + kd <= 1 for energy conservation ({_MODEL})",
            )

    @property
    def alpha(self) -> float:
        """Beckmann width ``α = √(2σ)`` (the paper's printed relation)."""
        return math.sqrt(2.0 * self.sigma)

    @property
    def albedo_bound(self) -> float:
        """``ks + kd``: the V-cavity specular lobe reflects at most a fraction 1 (``F <= 1``)."""
        return min(self.ks + self.kd, 1.0)

    def kernel_params(self) -> np.ndarray:
        return seed_microfacet_params(
            self.alpha, self.kd, self.ks, self.f0, self.fresnel_exponent
        )
