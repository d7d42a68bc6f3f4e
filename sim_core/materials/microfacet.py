"""Shared scattering formulas the reflectance models are built from.

One module of small, vectorised building blocks, in the spirit of pbrt-v4's
``util/scattering.h``: the Beckmann normal distribution and its sampling, the Schlick-type
power-law Fresnel term and the full unpolarised dielectric Fresnel equations, the V-cavity
shadowing-masking term, cosine-hemisphere sampling, the diffuse + microfacet sampling mixture,
and the parameter validation every material constructor uses.

Conventions are those of :mod:`sim_core.materials.base`: shading frame with the normal on +z,
``wi`` towards the light, ``wo`` towards the viewer, both pointing away from the surface, arrays
of shape ``(n, 3) float64``.

Numerical guards
----------------
Every clamp and epsilon is commented where it is used. Two constants are shared:

``COS_EPS`` (1e-9)
    Floor of cosines that appear in *denominators* of BRDF values and densities. The
    microfacet BRDF genuinely diverges like ``1 / (cos θi cos θo)`` in the mirror configuration
    at the horizon; without the floor a direction 1e-200 above the horizon returns ``inf``. With
    it, values stay finite (below ~1e29 even for the narrowest allowed lobe) and only directions
    within 1e-9 rad of the horizon are affected.
``U_MAX``
    The largest float64 below 1, the upper clamp of uniform numbers: ``u = 1`` would send
    ``log(1 - u)`` of the Beckmann sampler to ``-inf``.
"""

from __future__ import annotations

import math
import numbers
from abc import abstractmethod

import numpy as np

from sim_core.errors import InvalidInputError
from sim_core.materials.base import BSDFSample, Material

#: floor of cosines in denominators (see the module docstring)
COS_EPS = 1e-9
#: largest float64 below 1; upper clamp of the uniform numbers
U_MAX = float(np.nextafter(1.0, 0.0))

__all__ = [
    "COS_EPS",
    "U_MAX",
    "MicrofacetMixture",
    "beckmann_d",
    "beckmann_pdf_wi",
    "check_parameter",
    "cos_theta",
    "cosine_hemisphere_pdf",
    "finish_sample",
    "fresnel_dielectric",
    "fresnel_schlick_power",
    "half_vector",
    "reflect",
    "safe_divide",
    "sample_beckmann_normal",
    "sample_cosine_hemisphere",
    "torrance_sparrow_dg",
    "vcavity_g",
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


# -------------------------------------------------------------------------------------------
# Elementary helpers
# -------------------------------------------------------------------------------------------
def cos_theta(w: np.ndarray) -> np.ndarray:
    """``w.z`` clipped to [-1, 1] (slightly non-unit inputs must not give arccos/sqrt NaN)."""
    return np.clip(w[:, 2], -1.0, 1.0)


def safe_divide(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """``num / den`` where ``den > 0``, else 0 (a zero density marks an invalid sample)."""
    num, den = np.broadcast_arrays(np.asarray(num, float), np.asarray(den, float))
    return np.divide(num, den, out=np.zeros_like(num), where=den > 0.0)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def half_vector(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Unit half vectors ``(wi + wo) / |wi + wo|``, (n, 3).

    For ``wi`` and ``wo`` both above the horizon ``|wi + wo| >= cos θi + cos θo > 0``, so the
    result is well defined there; where ``wi == -wo`` (only possible at or below the horizon)
    the normal (0, 0, 1) is returned instead of 0/0 and callers mask those pairs out.
    """
    s = wi + wo
    length = np.linalg.norm(s, axis=1)
    degenerate = length <= 1e-300  # wi == -wo: 0/0 without this guard
    h = s / np.where(degenerate, 1.0, length)[:, None]
    h[degenerate] = (0.0, 0.0, 1.0)
    return h


def reflect(wo: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Mirror ``wo`` about the microfacet normals ``h``: ``2 (wo·h) h - wo``."""
    return 2.0 * _dot(wo, h)[:, None] * h - wo


# -------------------------------------------------------------------------------------------
# Beckmann distribution of microfacet normals
# -------------------------------------------------------------------------------------------
def beckmann_d(h: np.ndarray, alpha: float) -> np.ndarray:
    """Beckmann normal distribution ``D(h) = exp(-tan²θh / α²) / (π α² cos⁴θh)`` [1/sr].

    Normalised over the hemisphere of normals in the projected-area sense,
    ``∫ D(h) cos θh dω_h = 1``. ``α`` is the width (``√2`` times the per-axis RMS slope in the
    standard convention; each model documents how its own parameter maps to ``α``). Zero for
    ``h`` at or below the horizon.
    """
    cz = np.clip(h[:, 2], 0.0, 1.0)
    c2 = np.maximum(cz * cz, 1e-12)  # cos²θh -> 0 gives tan² = x/0 and 1/cos⁴ = inf
    # tan² from sin² = x² + y² (not 1 - cos², which cancels catastrophically near the pole and
    # would turn a 1e-16 rounding error into a 1e-4 error of the exponent for α = 1e-6).
    t2 = (h[:, 0] ** 2 + h[:, 1] ** 2) / c2
    a2 = alpha * alpha
    # exp(-t2/a2) <= 1 and underflows to 0 long before 1/(c2*c2) <= 1e24 could overflow.
    d = np.exp(-t2 / a2) / (np.pi * a2 * c2 * c2)
    return np.where(cz > 0.0, d, 0.0)


def sample_beckmann_normal(u1: np.ndarray, u2: np.ndarray, alpha: float) -> np.ndarray:
    """Sample normals ``h`` with density ``D(h) cos θh`` (Walter et al. 2007, eqs. 28-29).

    ``tan²θh = -α² ln(1 - u1)``, ``φh = 2π u2``.
    """
    u1 = np.clip(u1, 0.0, U_MAX)  # u1 = 1 gives log(0) = -inf
    t2 = -(alpha * alpha) * np.log1p(-u1)
    cos_t = 1.0 / np.sqrt(1.0 + t2)
    sin_t = np.sqrt(t2) * cos_t
    phi = 2.0 * np.pi * u2
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)


def beckmann_pdf_wi(wi: np.ndarray, wo: np.ndarray, alpha: float) -> np.ndarray:
    """Solid-angle density of ``wi = reflect(wo, h)`` with ``h`` from
    :func:`sample_beckmann_normal`: ``D(h) cos θh / (4 |wo·h|)``; 0 unless both above horizon.
    """
    ci, co = cos_theta(wi), cos_theta(wo)
    h = half_vector(wi, wo)
    # |wo·h| -> 0 only for wi -> -wo at the horizon; the floor keeps the Jacobian 1/(4 wo·h)
    # finite there (the density is overestimated only within 1e-9 rad of that configuration).
    cg = np.maximum(_dot(wo, h), COS_EPS)
    pdf = beckmann_d(h, alpha) * h[:, 2] / (4.0 * cg)
    return np.where((ci > 0.0) & (co > 0.0), pdf, 0.0)


def torrance_sparrow_dg(
    wi: np.ndarray, wo: np.ndarray, alpha: float
) -> tuple[np.ndarray, np.ndarray]:
    """The Fresnel-free specular factor ``D(h) G / (4 cos θi cos θo)`` and ``cos γ = wi·h``.

    Zero unless both directions are above the horizon. Symmetric in ``wi``, ``wo``.
    """
    ci, co = cos_theta(wi), cos_theta(wo)
    h = half_vector(wi, wo)
    cos_gamma = np.clip(_dot(wi, h), 0.0, 1.0)
    g = vcavity_g(h[:, 2], ci, co, cos_gamma)
    # 1/(cos θi cos θo) diverges at the horizon (mirror configuration); COS_EPS keeps it finite.
    den = 4.0 * np.maximum(ci, COS_EPS) * np.maximum(co, COS_EPS)
    dg = beckmann_d(h, alpha) * g / den
    return np.where((ci > 0.0) & (co > 0.0), dg, 0.0), cos_gamma


# -------------------------------------------------------------------------------------------
# Fresnel terms
# -------------------------------------------------------------------------------------------
def fresnel_schlick_power(cos_gamma: np.ndarray, f0: float, exponent: float) -> np.ndarray:
    """Schlick-type Fresnel ``F = F0 + (1 - F0) (1 - cos γ)^n``; in [F0, 1] for cos γ in [0, 1].

    ``n = 5`` is Schlick's approximation; ``n = 0`` gives ``F = 1`` (numpy's ``0**0 = 1``).
    """
    base = 1.0 - np.clip(cos_gamma, 0.0, 1.0)  # keeps the base in [0, 1]: no NaN from x**n, x<0
    return f0 + (1.0 - f0) * base**exponent


def fresnel_dielectric(cos_i: np.ndarray, n2: float, n1: float = 1.0) -> np.ndarray:
    """Unpolarised Fresnel reflectance ``(r_s + r_p) / 2`` from medium ``n1`` into ``n2 >= n1``.

    ``r_s = [(n1 cos θi - n2 cos θt) / (n1 cos θi + n2 cos θt)]²``,
    ``r_p = [(n1 cos θt - n2 cos θi) / (n1 cos θt + n2 cos θi)]²``, ``n1 sin θi = n2 sin θt``.
    With ``n2 >= n1`` there is no total internal reflection. In [0, 1]; 1 at grazing incidence
    for ``n2 > n1``, 0 everywhere for ``n2 == n1``.
    """
    ci = np.clip(cos_i, 0.0, 1.0)  # reflectance of a back-facing direction is not defined
    eta = n1 / n2
    # cos²θt = 1 - η² sin²θi = (1 - η²) + η² cos²θi, evaluated with hypot: the naive
    # sqrt(1 - η²(1 - cos²θi)) loses cos θi entirely when cos²θi underflows or drowns in the
    # 1 - ..., which for n1 == n2 turned a grazing 0/0 into F = 1.
    cos_t = np.hypot(math.sqrt(max(1.0 - eta * eta, 0.0)), eta * ci)
    # Both denominators vanish only for n1 == n2 at exactly grazing incidence, where the
    # numerators vanish too (0/0); the limit there is 0 (index-matched: nothing reflected).
    den_s = n1 * ci + n2 * cos_t
    den_p = n1 * cos_t + n2 * ci
    rs = safe_divide(n1 * ci - n2 * cos_t, den_s) ** 2
    rp = safe_divide(n1 * cos_t - n2 * ci, den_p) ** 2
    return np.clip(0.5 * (rs + rp), 0.0, 1.0)  # clip only removes rounding above 1


# -------------------------------------------------------------------------------------------
# Shadowing-masking
# -------------------------------------------------------------------------------------------
def vcavity_g(
    cos_h: np.ndarray, cos_i: np.ndarray, cos_o: np.ndarray, cos_gamma: np.ndarray
) -> np.ndarray:
    """V-cavity shadowing-masking ``G = min(1, 2 cosθh cosθo / cosγ, 2 cosθh cosθi / cosγ)``.

    Torrance & Sparrow (1967) / Cook & Torrance (1982); ``γ`` is the angle between ``wi`` (or
    ``wo``) and the half vector. Symmetric in ``θi``, ``θo``. In [0, 1].
    """
    ci = np.clip(cos_i, 0.0, 1.0)
    co = np.clip(cos_o, 0.0, 1.0)
    ch = np.clip(cos_h, 0.0, 1.0)
    # cos γ -> 0 only for wi -> -wo at the horizon, where the numerator -> 0 too; the floor
    # avoids 0/0 (the min with 1 bounds the result either way).
    cg = np.maximum(cos_gamma, COS_EPS)
    return np.minimum(1.0, 2.0 * ch * np.minimum(ci, co) / cg)


# -------------------------------------------------------------------------------------------
# Cosine-weighted hemisphere
# -------------------------------------------------------------------------------------------
def sample_cosine_hemisphere(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Malley's method: density ``cos θ / π`` over the upper hemisphere."""
    u1 = np.clip(u1, 0.0, U_MAX)  # u1 = 1 would give an exactly tangent direction (pdf 0)
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - u1)], axis=1)


def cosine_hemisphere_pdf(wi: np.ndarray) -> np.ndarray:
    """``max(cos θ, 0) / π`` [1/sr]."""
    return np.maximum(cos_theta(wi), 0.0) / np.pi


# -------------------------------------------------------------------------------------------
# Sampling glue shared by all models
# -------------------------------------------------------------------------------------------
def finish_sample(material: Material, wi: np.ndarray, wo: np.ndarray) -> BSDFSample:
    """Complete a batch of sampled ``wi`` into a :class:`BSDFSample`.

    ``pdf`` is computed with ``material.pdf_local`` so that it equals ``pdf_local(wi, wo)``
    exactly; ``weight = f cos θi / pdf`` where ``pdf > 0`` and 0 elsewhere (invalid samples:
    ``wi`` or ``wo`` at or below the horizon).
    """
    pdf = material.pdf_local(wi, wo)
    f = material.eval_local(wi, wo)
    weight = safe_divide(f * np.maximum(cos_theta(wi), 0.0), pdf)
    return BSDFSample(wi=wi, pdf=pdf, weight=weight)


class MicrofacetMixture(Material):
    """Sampling shared by diffuse + Beckmann microfacet models.

    ``sample_local`` picks the specular lobe with probability ``p_spec = ks / (ks + kd)``
    (``u[:, 2] < p_spec``) and the diffuse lobe with ``p_diff = kd / (ks + kd)``; both are 0
    when ``ks = kd = 0`` (a black surface: every sample has weight 0). ``p_diff`` is computed
    directly, not as ``1 - p_spec``, so that a tiny ``kd`` next to ``ks = 1`` keeps a positive
    density wherever its lobe is positive.

    - diffuse lobe: cosine-weighted hemisphere, density ``cos θi / π``;
    - specular lobe: half vector ``h`` from ``D(h) cos θh`` (Beckmann, width ``alpha``),
      ``wi = reflect(wo, h)``, density ``D(h) cos θh / (4 wo·h)``.

    ``pdf_local`` is the exact mixture ``p_spec pdf_spec + (1 - p_spec) pdf_diffuse`` for both
    directions above the horizon and 0 otherwise; specular samples that land below the horizon
    are returned as invalid (``pdf = weight = 0``), so ``pdf_local`` integrates to the
    probability of a valid sample.
    """

    @property
    @abstractmethod
    def alpha(self) -> float:
        """Beckmann width ``α`` of the specular lobe."""

    @property
    @abstractmethod
    def lobe_weights(self) -> tuple[float, float]:
        """``(ks, kd)``, the weights of the specular and the diffuse lobe."""

    @property
    def lobe_probabilities(self) -> tuple[float, float]:
        """``(p_spec, p_diff) = (ks, kd) / (ks + kd)``, or ``(0, 0)`` if ``ks = kd = 0``."""
        ks, kd = self.lobe_weights
        total = ks + kd
        if total <= 0.0:  # black surface: 0/0 otherwise
            return 0.0, 0.0
        return ks / total, kd / total

    def pdf_local(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        p_spec, p_diff = self.lobe_probabilities
        valid = (cos_theta(wi) > 0.0) & (cos_theta(wo) > 0.0)
        pdf = p_diff * cosine_hemisphere_pdf(wi)
        if p_spec > 0.0:
            pdf = pdf + p_spec * beckmann_pdf_wi(wi, wo, self.alpha)
        return np.where(valid, pdf, 0.0)

    def sample_local(self, wo: np.ndarray, u: np.ndarray) -> BSDFSample:
        spec = u[:, 2] < self.lobe_probabilities[0]
        wi = sample_cosine_hemisphere(u[:, 0], u[:, 1])
        if np.any(spec):
            h = sample_beckmann_normal(u[spec, 0], u[spec, 1], self.alpha)
            wi[spec] = reflect(wo[spec], h)
        return finish_sample(self, wi, wo)
