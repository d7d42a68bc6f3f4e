"""Compiled scalar kernels of the materials (numba): the one implementation of every BRDF formula.

A material is ``(kind, params)``: an integer model id and a float64 parameter vector of length
``N_PARAMS`` (unused entries 0). ``Material.kernel_kind`` and ``Material.kernel_params()``
give them; the ``*_params`` functions below build the vectors, so the layout is defined next to
the code that reads it. Three functions dispatch on ``kind`` and follow the contract of
:mod:`sim_core.materials.base` (shading frame, normal +z, both directions pointing away from
the surface, zero at or below the horizon):

- ``eval_brdf(kind, p, wix, wiy, wiz, wox, woy, woz) -> f`` [1/sr], without the cosine;
- ``pdf_brdf(kind, p, wix, wiy, wiz, wox, woy, woz) -> pdf`` [1/sr], solid angle;
- ``sample_brdf(kind, p, wox, woy, woz, u0, u1, u2) -> (wix, wiy, wiz, pdf, weight)`` with
  ``pdf == pdf_brdf(wi, wo)`` exactly and ``weight = f cos θi / pdf`` (0 if ``pdf == 0``).

The parameter vector of most models is ``N_PARAMS`` long; a measured (tabulated) material
carries its whole table, so a vector may be longer: its first ``N_PARAMS`` entries are the
*header* and the rest the model's data. The renderer keeps all vectors as rows of one
``(M, L)`` table (shorter rows padded with zeros) and calls the ``*_row`` forms of the
dispatchers, ``eval_brdf_row(kind, p, table, row, ...)`` and so on, with the header ``p``
unpacked by :func:`param_row` (eight loads, no array view per ray) and the table and row for
the models that read beyond the header. ``eval_brdf`` and friends are those forms for one 1-D
vector.

Directions are passed as separate x, y, z scalars so that the kernels inline into the
integrator's loops without allocating. The batch wrappers (``eval_batch``, ``pdf_batch``,
``sample_batch``, ``weight_batch``, ``hapke_batch``) run the same scalar kernels over arrays,
in parallel; the numpy API of the material classes is built on them.

The shared building blocks (Beckmann distribution and sampling, Fresnel terms, V-cavity
shadowing, cosine-hemisphere sampling) are public so that they can be tested on their own.

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

All functions are ``@njit(cache=True)`` without ``fastmath`` (results must be deterministic and
the guards must not be optimised away), with ``error_model="numpy"``: every division is
guarded, so numba's Python error model would only add a zero-divisor check and a
``ZeroDivisionError`` path to each one, which keeps the kernels out of line and unvectorised
(measured: Hapke 2.7x, Cook–Torrance 1.2x slower per call). IEEE results are identical. The
three dispatchers are ``inline="always"``, so that the branch on ``kind`` is resolved inside the
caller's loop instead of behind a call (Lambertian batch evaluation 3x faster).

Parameter layouts
-----------------
- Lambertian: ``[albedo, albedo/π]``.
- Seed microfacet: ``[α, w_spec, w_diff, kd/π, ks, F0, n, fresnel_lobes]``.
- Cook–Torrance: ``[α, w_spec, w_diff, kd/π, ks, n2, half, fresnel_lobes]`` with ``half`` 1.0
  for ``fresnel_angle="half"`` and 0.0 for ``"incidence"``.
- Both microfacet models: ``w_spec``, ``w_diff`` are the weights of the lobe choice and
  ``fresnel_lobes`` 1.0 scales ``w_spec`` by the Fresnel factor at ``wo``'s mirror direction
  (see :func:`lobe_probabilities`; the models use ``w = (ks, kd)`` with the factor, the
  albedo of each lobe, and :func:`fixed_lobes` makes a fixed-probability mixture of them).
- Hapke: ``[w, b0, h, b, √(1 - w), w/(4π), b0 h]`` (``b`` = ``phase_b``).
- Tabulated: header ``[n_i, n_r, n_φ, p_cos, L]`` (grid sizes, probability of cosine
  sampling, total length), then the blocks of :func:`tabulated_layout`: the node angles θi,
  θr, Δφ [rad], ``cos θi`` at the θi nodes, the BRDF values ``V[r, i, φ]`` [1/sr], and the
  sampling tables (per θr row a marginal CDF over θi cells, per θi cell a conditional CDF over
  Δφ cells, and the solid-angle density of each cell); built by :func:`tabulated_params`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange, types
from numba.extending import overload

# The batch wrappers below are parallel kernels: numba's threading layer must be chosen before
# any of them runs, and callers hold PARALLEL_KERNEL_LOCK (see sim_core.numba_runtime).
import sim_core.numba_runtime  # noqa: F401

N_PARAMS = 8
KIND_LAMBERTIAN = 0
KIND_SEED_MICROFACET = 1
KIND_COOK_TORRANCE = 2
KIND_HAPKE = 3
KIND_TABULATED = 4

#: floor of cosines in denominators (see the module docstring)
COS_EPS = 1e-9
#: largest float64 below 1; upper clamp of the uniform numbers
U_MAX = float(np.nextafter(1.0, 0.0))

# Parameter indices (see "Parameter layouts" in the module docstring).
_ALBEDO_OVER_PI = 1  # Lambertian
_ALPHA, _W_SPEC, _W_DIFF, _KD_OVER_PI, _KS = 0, 1, 2, 3, 4
_F0, _EXPONENT = 5, 6  # seed microfacet
_N2, _FRESNEL_HALF = 5, 6  # Cook–Torrance
_FRESNEL_LOBES = 7  # both microfacet models: 1.0 weighs the specular lobe by F at the mirror
_H, _PHASE_B, _GAMMA, _NORM, _B0_H = 2, 3, 4, 5, 6  # Hapke (w and b0 are folded into these)
_TAB_NI, _TAB_NR, _TAB_NP, _TAB_P_COS, _TAB_LENGTH = 0, 1, 2, 3, 4  # tabulated header
#: largest grid axis the tabulated kernels accept (keeps every block offset an exact int64)
TAB_MAX_AXIS = 100_000
#: smallest probability of the specular lobe of a microfacet mixture that has both lobes (see
#: :func:`lobe_probabilities`): the lobe's albedo estimate F(wo) ks can be 0 where its value
#: is not (Schlick's F with F0 = 0 at normal view), and a lobe never sampled is a biased one
P_SPEC_MIN = 0.05


# -------------------------------------------------------------------------------------------
# Parameter vectors
# -------------------------------------------------------------------------------------------
def _vector(*values: float) -> np.ndarray:
    p = np.zeros(N_PARAMS)
    p[: len(values)] = values
    return p


def lambertian_params(albedo: float) -> np.ndarray:
    """Parameter vector of a Lambertian reflector."""
    return _vector(albedo, albedo / math.pi)


def seed_microfacet_params(
    alpha: float, kd: float, ks: float, f0: float, exponent: float
) -> np.ndarray:
    """Parameter vector of the seed paper's microfacet model (Beckmann width ``alpha``); lobes
    chosen by their albedo at ``wo`` (:func:`lobe_probabilities`)."""
    return _vector(alpha, ks, kd, kd / math.pi, ks, f0, exponent, 1.0)


def cook_torrance_params(
    alpha: float, kd: float, ks: float, n2: float, half: bool
) -> np.ndarray:
    """Parameter vector of Cook–Torrance; ``half`` selects ``F(θ_half)`` over ``F(θi)``; lobes
    chosen by their albedo at ``wo`` (:func:`lobe_probabilities`)."""
    return _vector(alpha, ks, kd, kd / math.pi, ks, n2, 1.0 if half else 0.0, 1.0)


def fixed_lobes(params: np.ndarray, p_spec: float) -> np.ndarray:
    """A copy of a microfacet parameter vector whose sampler picks the specular lobe with the
    fixed probability ``p_spec`` in [:data:`P_SPEC_MIN`, 1) for every ``wo`` (the diffuse one
    with ``1 - p_spec``) instead of by the lobes' albedos: the naive mixture that variance is
    compared against (issue 16). The BRDF itself is unchanged.
    """
    if not P_SPEC_MIN <= p_spec < 1.0:
        raise ValueError(f"p_spec = {p_spec!r} is outside [{P_SPEC_MIN}, 1)")
    p = np.array(params, dtype=np.float64)
    p[_W_SPEC], p[_W_DIFF], p[_FRESNEL_LOBES] = p_spec, 1.0 - p_spec, 0.0
    return p


def hapke_params(w: float, b0: float, h: float, phase_b: float) -> np.ndarray:
    """Parameter vector of Hapke's model, with ``√(1 - w)``, ``w/(4π)`` and ``b0 h`` folded in."""
    gamma = math.sqrt(max(1.0 - w, 0.0))  # w <= 1, the max only guards rounding
    return _vector(w, b0, h, phase_b, gamma, w / (4.0 * math.pi), b0 * h)


def tabulated_params(
    theta_i_rad: np.ndarray,
    theta_r_rad: np.ndarray,
    phi_rad: np.ndarray,
    values_per_sr: np.ndarray,
    marginal_cdf: np.ndarray,
    conditional_cdf: np.ndarray,
    density_per_sr: np.ndarray,
    p_cos: float,
) -> np.ndarray:
    """Parameter vector of a tabulated material (layout: :func:`tabulated_layout`).

    Parameters
    ----------
    theta_i_rad, theta_r_rad, phi_rad : (n_i,), (n_r,), (n_φ,) float
        Strictly increasing grid nodes of θi, θr in [0, π/2] and Δφ in [0, π], each >= 2.
    values_per_sr : (n_r, n_i, n_φ) float
        BRDF values at the nodes, >= 0, indexed ``[θr, θi, Δφ]``.
    marginal_cdf : (n_r, n_i) float
        Per θr row, the CDF over θi cells (0 first, 1 last, non-decreasing).
    conditional_cdf : (n_r, n_i - 1, n_φ) float
        Per θr row and θi cell, the CDF over Δφ cells.
    density_per_sr : (n_r, n_i - 1, n_φ - 1) float
        Solid-angle density of the tabulated sampler in each cell (both azimuth signs).
    p_cos : float
        Probability of cosine-hemisphere sampling in the mixture, in (0, 1].
    """
    n_i, n_r, n_p = len(theta_i_rad), len(theta_r_rad), len(phi_rad)
    *_, length = tabulated_layout(n_i, n_r, n_p)
    head = _vector(n_i, n_r, n_p, p_cos, length)
    blocks = [theta_i_rad, theta_r_rad, phi_rad, np.cos(theta_i_rad), values_per_sr,
              marginal_cdf, conditional_cdf, density_per_sr]
    p = np.concatenate([head, *(np.asarray(b, dtype=np.float64).ravel() for b in blocks)])
    if p.shape != (length,):
        raise ValueError(f"tabulated blocks have {p.size} entries, the layout {length}")
    return p


# -------------------------------------------------------------------------------------------
# Elementary helpers
# -------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def clamp(x, lo, hi):
    """``x`` limited to ``[lo, hi]``."""
    return min(max(x, lo), hi)


@njit(cache=True, error_model="numpy")
def cos_theta(z):
    """``w.z`` clipped to [-1, 1] (slightly non-unit inputs must not give sqrt/acos NaN)."""
    return min(max(z, -1.0), 1.0)


@njit(cache=True, error_model="numpy")
def safe_divide(num, den):
    """``num / den`` where ``den > 0``, else 0 (a zero density marks an invalid sample)."""
    return num / den if den > 0.0 else 0.0


# Taylor coefficients of sin and cos; on |x| <= pi/4 the first omitted terms are below 5e-17.
_SIN_C = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(8))
_COS_C = tuple((-1.0) ** k / math.factorial(2 * k) for k in range(9))
_S1, _S3, _S5, _S7, _S9, _S11, _S13, _S15 = _SIN_C
_C0, _C2, _C4, _C6, _C8, _C10, _C12, _C14, _C16 = _COS_C


@njit(cache=True, inline="always", error_model="numpy")
def sincos_turns(t):
    """``(sin 2πt, cos 2πt)`` of an angle ``t`` given in turns, to ~1e-16 absolute.

    Measured 6 ns for both against 29 ns for ``math.sin`` + ``math.cos`` (one call each, not
    inlined): the renderer needs one pair per sampled azimuth and one per path and modulation
    frequency. In turns the argument reduction is exact: ``t - floor(t + 1/2)`` and the
    quarter-turn ``q/4`` are exact binary operations for |t| < 2^52, so only the final
    ``x = 2π r`` rounds (relative 1e-16), and a long path (many turns) loses nothing beyond the
    rounding of ``t`` itself. Then a Taylor polynomial on |x| <= π/4 and the quadrant swap.
    Beyond 2^52 turns every float is a whole number of turns: (0, 1). NaN or inf give NaN.
    """
    # np.floor stays float (math.floor is an int64 in numba and overflows beyond 2^63 turns)
    r = t - np.floor(t + 0.5)  # in [-1/2, 1/2]
    q = np.floor(4.0 * r + 0.5)  # quadrant, -2..2
    x = (r - 0.25 * q) * (2.0 * math.pi)  # |x| <= π/4
    # Estrin's scheme in y = x^2: half the dependency depth of Horner's rule (the polynomial's
    # latency, not its arithmetic, is what a ray loop waits for).
    y = x * x
    y2 = y * y
    y4 = y2 * y2
    s = x * ((_S1 + _S3 * y) + (_S5 + _S7 * y) * y2
             + ((_S9 + _S11 * y) + (_S13 + _S15 * y) * y2) * y4)
    c = ((_C0 + _C2 * y) + (_C4 + _C6 * y) * y2
         + ((_C8 + _C10 * y) + (_C12 + _C14 * y) * y2) * y4 + _C16 * (y4 * y4))
    k = int(q) & 3
    # sin(x + k π/2), cos(x + k π/2): k odd swaps the pair; selects, not branches on k.
    odd = k & 1
    a = c if odd else s
    b = s if odd else c
    sign_a = -1.0 if k >= 2 else 1.0
    sign_b = -1.0 if k == 1 or k == 2 else 1.0
    return sign_a * a, sign_b * b


@njit(cache=True, error_model="numpy")
def half_vector(wix, wiy, wiz, wox, woy, woz):
    """Unit half vector ``(wi + wo) / |wi + wo|``.

    For ``wi`` and ``wo`` both above the horizon ``|wi + wo| >= cos θi + cos θo > 0``, so the
    result is well defined there; where ``wi == -wo`` (only possible at or below the horizon)
    the normal (0, 0, 1) is returned instead of 0/0 and callers mask those pairs out.
    """
    sx, sy, sz = wix + wox, wiy + woy, wiz + woz
    length = math.sqrt(sx * sx + sy * sy + sz * sz)
    if length <= 1e-300:  # wi == -wo: 0/0 without this guard
        return 0.0, 0.0, 1.0
    return sx / length, sy / length, sz / length


@njit(cache=True, error_model="numpy")
def reflect(wox, woy, woz, hx, hy, hz):
    """Mirror ``wo`` about the microfacet normal ``h``: ``2 (wo·h) h - wo``."""
    c = 2.0 * (wox * hx + woy * hy + woz * hz)
    return c * hx - wox, c * hy - woy, c * hz - woz


# -------------------------------------------------------------------------------------------
# Beckmann distribution of microfacet normals
# -------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def beckmann_d(hx, hy, hz, alpha):
    """Beckmann normal distribution ``D(h) = exp(-tan²θh / α²) / (π α² cos⁴θh)`` [1/sr].

    Normalised over the hemisphere of normals in the projected-area sense,
    ``∫ D(h) cos θh dω_h = 1``. ``α`` is the width (``√2`` times the per-axis RMS slope in the
    standard convention; each model documents how its own parameter maps to ``α``); the models
    keep ``α >= 1e-6``, so ``α² > 0`` below. Zero for ``h`` at or below the horizon.
    """
    cz = clamp(hz, 0.0, 1.0)
    if not cz > 0.0:
        return 0.0
    c2 = max(cz * cz, 1e-12)  # cos²θh -> 0 gives tan² = x/0 and 1/cos⁴ = inf
    # tan² from sin² = x² + y² (not 1 - cos², which cancels catastrophically near the pole and
    # would turn a 1e-16 rounding error into a 1e-4 error of the exponent for α = 1e-6).
    t2 = (hx * hx + hy * hy) / c2
    a2 = alpha * alpha
    # exp(-t2/a2) <= 1 and underflows to 0 long before 1/(c2*c2) <= 1e24 could overflow.
    return math.exp(-t2 / a2) / (math.pi * a2 * c2 * c2)


@njit(cache=True, error_model="numpy")
def sample_beckmann_normal(u1, u2, alpha):
    """Sample a normal ``h`` with density ``D(h) cos θh`` (Walter et al. 2007, eqs. 28-29).

    ``tan²θh = -α² ln(1 - u1)``, ``φh = 2π u2``.
    """
    u1 = clamp(u1, 0.0, U_MAX)  # u1 = 1 gives log(0) = -inf
    t2 = -(alpha * alpha) * math.log1p(-u1)  # >= 0: log1p(-u1) <= 0
    cos_t = 1.0 / math.sqrt(1.0 + t2)  # 1 + t2 >= 1
    sin_t = math.sqrt(t2) * cos_t
    sin_phi, cos_phi = sincos_turns(u2)  # φh = 2π u2
    return sin_t * cos_phi, sin_t * sin_phi, cos_t


@njit(cache=True, error_model="numpy")
def beckmann_pdf_wi(wix, wiy, wiz, wox, woy, woz, alpha):
    """Solid-angle density of ``wi = reflect(wo, h)`` with ``h`` from
    :func:`sample_beckmann_normal`: ``D(h) cos θh / (4 |wo·h|)``; 0 unless both above horizon.
    """
    if not (cos_theta(wiz) > 0.0 and cos_theta(woz) > 0.0):
        return 0.0
    hx, hy, hz = half_vector(wix, wiy, wiz, wox, woy, woz)
    # |wo·h| -> 0 only for wi -> -wo at the horizon; the floor keeps the Jacobian 1/(4 wo·h)
    # finite there (the density is overestimated only within 1e-9 rad of that configuration).
    cg = max(wox * hx + woy * hy + woz * hz, COS_EPS)
    return beckmann_d(hx, hy, hz, alpha) * hz / (4.0 * cg)


@njit(cache=True, error_model="numpy")
def torrance_sparrow_dg(wix, wiy, wiz, wox, woy, woz, alpha):
    """The Fresnel-free specular factor ``D(h) G / (4 cos θi cos θo)`` and ``cos γ = wi·h``.

    The factor is zero unless both directions are above the horizon. Symmetric in ``wi``, ``wo``.
    """
    ci, co = cos_theta(wiz), cos_theta(woz)
    hx, hy, hz = half_vector(wix, wiy, wiz, wox, woy, woz)
    cos_gamma = clamp(wix * hx + wiy * hy + wiz * hz, 0.0, 1.0)
    if not (ci > 0.0 and co > 0.0):
        return 0.0, cos_gamma
    g = vcavity_g(hz, ci, co, cos_gamma)
    # 1/(cos θi cos θo) diverges at the horizon (mirror configuration); COS_EPS keeps it finite.
    den = 4.0 * max(ci, COS_EPS) * max(co, COS_EPS)
    return beckmann_d(hx, hy, hz, alpha) * g / den, cos_gamma


# -------------------------------------------------------------------------------------------
# Fresnel terms
# -------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def fresnel_schlick_power(cos_gamma, f0, exponent):
    """Schlick-type Fresnel ``F = F0 + (1 - F0) (1 - cos γ)^n``; in [F0, 1] for cos γ in [0, 1].

    ``n = 5`` is Schlick's approximation; ``n = 0`` gives ``F = 1`` (``0**0 = 1``).
    """
    base = 1.0 - clamp(cos_gamma, 0.0, 1.0)  # keeps the base in [0, 1]: no NaN from x**n, x<0
    return f0 + (1.0 - f0) * base**exponent


@njit(cache=True, error_model="numpy")
def fresnel_dielectric(cos_i, n2, n1=1.0):
    """Unpolarised Fresnel reflectance ``(r_s + r_p) / 2`` from medium ``n1`` into ``n2 >= n1``.

    ``r_s = [(n1 cos θi - n2 cos θt) / (n1 cos θi + n2 cos θt)]²``,
    ``r_p = [(n1 cos θt - n2 cos θi) / (n1 cos θt + n2 cos θi)]²``, ``n1 sin θi = n2 sin θt``.
    With ``n2 >= n1`` there is no total internal reflection. In [0, 1]; 1 at grazing incidence
    for ``n2 > n1``, 0 everywhere for ``n2 == n1``.
    """
    ci = clamp(cos_i, 0.0, 1.0)  # reflectance of a back-facing direction is not defined
    eta = n1 / n2  # n2 >= n1 >= 1 > 0
    # cos²θt = 1 - η² sin²θi = (1 - η²) + η² cos²θi, evaluated with hypot: the naive
    # sqrt(1 - η²(1 - cos²θi)) loses cos θi entirely when cos²θi underflows or drowns in the
    # 1 - ..., which for n1 == n2 turned a grazing 0/0 into F = 1.
    cos_t = math.hypot(math.sqrt(max(1.0 - eta * eta, 0.0)), eta * ci)
    # Both denominators vanish only for n1 == n2 at exactly grazing incidence, where the
    # numerators vanish too (0/0); the limit there is 0 (index-matched: nothing reflected).
    rs = safe_divide(n1 * ci - n2 * cos_t, n1 * ci + n2 * cos_t)
    rp = safe_divide(n1 * cos_t - n2 * ci, n1 * cos_t + n2 * ci)
    return clamp(0.5 * (rs * rs + rp * rp), 0.0, 1.0)  # clamp only removes rounding above 1


# -------------------------------------------------------------------------------------------
# Shadowing-masking
# -------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def vcavity_g(cos_h, cos_i, cos_o, cos_gamma):
    """V-cavity shadowing-masking ``G = min(1, 2 cosθh cosθo / cosγ, 2 cosθh cosθi / cosγ)``.

    Torrance & Sparrow (1967) / Cook & Torrance (1982); ``γ`` is the angle between ``wi`` (or
    ``wo``) and the half vector. Symmetric in ``θi``, ``θo``. In [0, 1].
    """
    ci = clamp(cos_i, 0.0, 1.0)
    co = clamp(cos_o, 0.0, 1.0)
    ch = clamp(cos_h, 0.0, 1.0)
    # cos γ -> 0 only for wi -> -wo at the horizon, where the numerator -> 0 too; the floor
    # avoids 0/0 (the min with 1 bounds the result either way).
    cg = max(cos_gamma, COS_EPS)
    return min(1.0, 2.0 * ch * min(ci, co) / cg)


# -------------------------------------------------------------------------------------------
# Cosine-weighted hemisphere
# -------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def sample_cosine_hemisphere(u1, u2):
    """Malley's method: density ``cos θ / π`` over the upper hemisphere."""
    u1 = clamp(u1, 0.0, U_MAX)  # u1 = 1 would give an exactly tangent direction (pdf 0)
    r = math.sqrt(u1)
    sin_phi, cos_phi = sincos_turns(u2)  # φ = 2π u2
    return r * cos_phi, r * sin_phi, math.sqrt(1.0 - u1)  # 1 - u1 >= 1.1e-16


@njit(cache=True, error_model="numpy")
def cosine_hemisphere_pdf(wiz):
    """``max(cos θ, 0) / π`` [1/sr]."""
    return max(cos_theta(wiz), 0.0) / math.pi


@njit(cache=True, error_model="numpy")
def sample_weight(f, wiz, pdf):
    """``f cos θi / pdf`` where ``pdf > 0``, else 0 (an invalid sample)."""
    return safe_divide(f * max(cos_theta(wiz), 0.0), pdf)


# -------------------------------------------------------------------------------------------
# Models
# -------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _both_above(wiz, woz):
    return cos_theta(wiz) > 0.0 and cos_theta(woz) > 0.0


@njit(cache=True, error_model="numpy")
def lambertian_eval(p, wiz, woz):
    """``albedo / π`` above the horizon."""
    return p[_ALBEDO_OVER_PI] if _both_above(wiz, woz) else 0.0


@njit(cache=True, error_model="numpy")
def cosine_pdf(wiz, woz):
    """Density of cosine-hemisphere sampling (Lambertian, Hapke); 0 for ``wo`` below horizon."""
    return cosine_hemisphere_pdf(wiz) if cos_theta(woz) > 0.0 else 0.0


@njit(cache=True, error_model="numpy")
def seed_microfacet_eval(p, wix, wiy, wiz, wox, woy, woz):
    """``kd/π + ks D F G / (4 cos θi cos θo)``, F Schlick-type (seed paper eqs. 9-10)."""
    if not _both_above(wiz, woz):
        return 0.0
    f = p[_KD_OVER_PI]
    if p[_KS] > 0.0:
        dg, cos_gamma = torrance_sparrow_dg(wix, wiy, wiz, wox, woy, woz, p[_ALPHA])
        f = f + p[_KS] * dg * fresnel_schlick_power(cos_gamma, p[_F0], p[_EXPONENT])
    return f


@njit(cache=True, error_model="numpy")
def cook_torrance_eval(p, wix, wiy, wiz, wox, woy, woz):
    """``kd/π + ks D G F / (4 cos θi cos θo)``, F dielectric at θi or θ_half (NLOS eq. 8)."""
    if not _both_above(wiz, woz):
        return 0.0
    f = p[_KD_OVER_PI]
    if p[_KS] > 0.0:
        dg, cos_gamma = torrance_sparrow_dg(wix, wiy, wiz, wox, woy, woz, p[_ALPHA])
        cos_f = cos_gamma if p[_FRESNEL_HALF] != 0.0 else cos_theta(wiz)
        f = f + p[_KS] * dg * fresnel_dielectric(cos_f, p[_N2])
    return f


@njit(cache=True, error_model="numpy")
def mirror_fresnel(kind, p, woz):
    """The model's Fresnel factor for ``wi`` the mirror direction of ``wo`` (``h`` the normal):
    ``F(θo)``, dielectric (Cook–Torrance) or Schlick-type (seed microfacet, eq. 10), in [0, 1].

    At the mirror direction ``θi = θo`` and ``γ = θo``, so this is the lobe's Fresnel factor
    at its peak whichever angle the model evaluates ``F`` at.
    """
    c = clamp(woz, 0.0, 1.0)  # below the horizon nothing is sampled; F of a valid cosine
    if kind == KIND_COOK_TORRANCE:
        return fresnel_dielectric(c, p[_N2])
    return fresnel_schlick_power(c, p[_F0], p[_EXPONENT])


@njit(cache=True, error_model="numpy")
def lobe_probabilities(kind, p, woz):
    """``(p_spec, p_diff)``: the probabilities with which a microfacet model samples its
    specular (Beckmann) and its diffuse (cosine) lobe for the view direction ``wo``.

    Proportional to each lobe's directional albedo at ``wo`` (the seed paper's ``p_ω`` of eq.
    31 then follows ``f cos θi`` across both lobes, as in pbrt's and Mitsuba's rough plastic):
    the diffuse lobe reflects ``kd``, the specular one about ``ks F(θo)``, its Fresnel factor
    at the mirror direction (:func:`mirror_fresnel`; for the narrow lobes of the presets
    within 8 % of the lobe's albedo up to θo = 70°; for rough lobes (α 0.5 to 1) and grazing
    views an overestimate by up to 4x, ``docs/performance.md``). An estimate is all the choice
    needs: any probabilities give an unbiased estimator, only its variance depends on them.
    With ``w = (w_spec, w_diff)`` from the parameter vector (``(ks, kd)``, or
    fixed probabilities without the Fresnel factor, :func:`fixed_lobes`):
    ``p_spec = w_spec F / (w_spec F + w_diff)``, at least :data:`P_SPEC_MIN` when both lobes
    are present, ``p_diff = 1 - p_spec``; a model with one lobe samples only that one, a black
    one neither (``(0, 0)``: every sample is invalid). ``p_diff`` is computed as
    ``w_diff / (w_spec F + w_diff)``, not as ``1 - p_spec``, which would round to 0 next to
    a tiny ``kd`` although that lobe's value is positive.

    Choosing by ``ks / (ks + kd)`` instead sent 78 % of the black glossy tile's samples into a
    lobe that reflects ~1 % (F = 0.035 at normal view) against its diffuse 7 %: 2.7x the range
    variance of a 50/50 mixture on the glossy corner's floor, 5x that of this choice (issue 16,
    ``docs/performance.md``).
    """
    w_spec, w_diff = p[_W_SPEC], p[_W_DIFF]
    if not w_spec > 0.0:
        return 0.0, (1.0 if w_diff > 0.0 else 0.0)
    if not w_diff > 0.0:
        return 1.0, 0.0
    if p[_FRESNEL_LOBES] != 0.0:
        w_spec = w_spec * mirror_fresnel(kind, p, woz)
    total = w_spec + w_diff  # >= w_diff > 0
    p_spec = w_spec / total
    if p_spec < P_SPEC_MIN:
        return P_SPEC_MIN, 1.0 - P_SPEC_MIN
    return p_spec, w_diff / total


@njit(cache=True, error_model="numpy")
def lobe_mixture_pdf(p, p_spec, p_diff, wix, wiy, wiz, wox, woy, woz):
    """``p_spec pdf_Beckmann + p_diff cos θi / π`` [1/sr] for both directions above the
    horizon, 0 otherwise: the density of the one-sample mixture of the two lobes (Veach's
    one-sample balance heuristic, so each sample is weighted by the whole mixture's pdf)."""
    if not _both_above(wiz, woz):
        return 0.0
    pdf = p_diff * cosine_hemisphere_pdf(wiz)
    if p_spec > 0.0:
        pdf = pdf + p_spec * beckmann_pdf_wi(wix, wiy, wiz, wox, woy, woz, p[_ALPHA])
    return pdf


@njit(cache=True, error_model="numpy")
def mixture_pdf(kind, p, wix, wiy, wiz, wox, woy, woz):
    """Density [1/sr] with which a microfacet model ``kind`` samples ``wi`` for ``wo``:
    :func:`lobe_mixture_pdf` with the :func:`lobe_probabilities` of ``wo``."""
    if not _both_above(wiz, woz):
        return 0.0
    p_spec, p_diff = lobe_probabilities(kind, p, woz)
    return lobe_mixture_pdf(p, p_spec, p_diff, wix, wiy, wiz, wox, woy, woz)


@njit(cache=True, error_model="numpy")
def chandrasekhar_h(x, gamma):
    """Hapke's (1981) approximation ``H(x) = (1 + 2x) / (1 + 2x γ)``, ``γ = √(1 - w)``."""
    return (1.0 + 2.0 * x) / (1.0 + 2.0 * x * gamma)  # denominator >= 1, no guard needed


@njit(cache=True, error_model="numpy")
def hapke_f(p, mu_i, mu_o, cos_g):
    """Hapke BRDF ``f = w / (4π) [P(g)(1 + B(g)) + H(μi) H(μo) - 1] / (μi + μo)`` [1/sr].

    No horizon masking: callers pass ``μi, μo`` in [0, 1]. Symmetric in ``μi``, ``μo``.
    """
    mu_i = clamp(mu_i, 0.0, 1.0)
    mu_o = clamp(mu_o, 0.0, 1.0)
    cos_g = clamp(cos_g, -1.0, 1.0)  # |wi·wo| may exceed 1 by rounding: sqrt(1 - cos g) NaN
    # B(g) = B0 / (1 + tan(g/2) / h) = B0 h / (h + tan(g/2)), tan(g/2) = sqrt((1-c)/(1+c)),
    # written without tan so that g = π (tan = inf) gives 0 instead of inf/inf.
    s_plus = math.sqrt(1.0 + cos_g)
    s_minus = math.sqrt(1.0 - cos_g)
    # The denominator vanishes only for h = 0 at g = 0 (0/0); h = 0 means "no surge": B = 0.
    surge = safe_divide(p[_B0_H] * s_plus, p[_H] * s_plus + s_minus)
    phase = 1.0 + p[_PHASE_B] * cos_g  # >= 0 because |phase_b| <= 1
    gamma = p[_GAMMA]
    bracket = (
        phase * (1.0 + surge) + chandrasekhar_h(mu_i, gamma) * chandrasekhar_h(mu_o, gamma) - 1.0
    )
    # 1/(μi + μo) diverges when both directions graze the horizon; COS_EPS keeps it finite.
    return p[_NORM] * bracket / max(mu_i + mu_o, COS_EPS)


@njit(cache=True, error_model="numpy")
def hapke_eval(p, wix, wiy, wiz, wox, woy, woz):
    """:func:`hapke_f` with ``cos g = wi·wo``, zero unless both directions are above horizon."""
    if not _both_above(wiz, woz):
        return 0.0
    cos_g = wix * wox + wiy * woy + wiz * woz
    return hapke_f(p, cos_theta(wiz), cos_theta(woz), cos_g)


# -------------------------------------------------------------------------------------------
# Tabulated (measured) material
# -------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy", inline="always")
def tabulated_layout(n_i, n_r, n_p):
    """Offsets of the blocks of a tabulated parameter vector, and its total length.

    Returns ``(θi nodes, θr nodes, Δφ nodes, cos θi nodes, values V[r, i, φ], marginal CDFs
    [r, i], conditional CDFs [r, i-cell, φ], cell densities [r, i-cell, φ-cell], length)``.
    """
    o_ti = N_PARAMS
    o_tr = o_ti + n_i
    o_ph = o_tr + n_r
    o_mu = o_ph + n_p
    o_val = o_mu + n_i
    o_marg = o_val + n_r * n_i * n_p
    o_cond = o_marg + n_r * n_i
    o_dens = o_cond + n_r * (n_i - 1) * n_p
    end = o_dens + n_r * (n_i - 1) * (n_p - 1)
    return o_ti, o_tr, o_ph, o_mu, o_val, o_marg, o_cond, o_dens, end


@njit(cache=True, error_model="numpy", inline="always")
def _tabulated_sizes(table, row):
    """``(ok, n_i, n_r, n_φ)`` from the header of ``table[row]``.

    ``ok`` is False unless every axis has 2 to ``TAB_MAX_AXIS`` nodes and the stated length
    matches the layout and fits in the row: the kernels then read nothing (a vector that is not
    a tabulated one, e.g. a short one with the wrong kind, reflects nothing instead of reading
    past its end).
    """
    if table.shape[1] < N_PARAMS:  # no header to read
        return False, 0, 0, 0
    a, b, c = table[row, _TAB_NI], table[row, _TAB_NR], table[row, _TAB_NP]
    lim = float(TAB_MAX_AXIS)
    if not (2.0 <= a <= lim and 2.0 <= b <= lim and 2.0 <= c <= lim):  # NaN fails too
        return False, 0, 0, 0
    n_i, n_r, n_p = int(a), int(b), int(c)
    end = tabulated_layout(n_i, n_r, n_p)[8]
    ok = float(end) == table[row, _TAB_LENGTH] and end <= table.shape[1]
    return ok, n_i, n_r, n_p


@njit(cache=True, error_model="numpy", inline="always")
def _grid_cell(table, row, offset, n, x):
    """Cell ``k`` of the increasing nodes ``table[row, offset:offset + n]`` holding ``x`` and
    the fraction ``t`` in [0, 1] of ``x`` across it; ``x`` outside the nodes is clamped.
    """
    lo, hi = 0, n - 2  # cells 0 .. n-2; find the largest k with node[k] <= x
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if table[row, offset + mid] <= x:
            lo = mid
        else:
            hi = mid - 1
    x0, x1 = table[row, offset + lo], table[row, offset + lo + 1]
    # nodes strictly increase, so x1 - x0 > 0; safe_divide only guards a corrupt table
    return lo, clamp(safe_divide(x - x0, x1 - x0), 0.0, 1.0)


@njit(cache=True, error_model="numpy", inline="always")
def _cdf_cell(table, row, offset, n, u):
    """Cell ``k`` of the CDF ``table[row, offset:offset + n]`` (0 first, 1 last) that ``u`` in
    [0, 1) falls in, i.e. the largest ``k <= n - 2`` with ``cdf[k] <= u``, and ``u`` rescaled
    to [0, 1) within that cell (cells of zero probability are never chosen).
    """
    lo, hi = 0, n - 2
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if table[row, offset + mid] <= u:
            lo = mid
        else:
            hi = mid - 1
    c0, c1 = table[row, offset + lo], table[row, offset + lo + 1]
    # c1 > u >= c0 for u < 1 = cdf[n-1]; the guard covers a zero-width last cell (u clamped)
    return lo, clamp(safe_divide(u - c0, c1 - c0), 0.0, U_MAX)


@njit(cache=True, error_model="numpy")
def zenith_angle(x, y, z):
    """Polar angle of ``(x, y, z)`` [rad], ``atan2(√(x² + y²), z)``: accurate at the pole
    (``acos`` of a rounded cosine is off by ~1e-8 rad there) and defined for any length."""
    return math.atan2(math.hypot(x, y), z)


@njit(cache=True, error_model="numpy")
def azimuth_difference(wix, wiy, wox, woy):
    """Angle in [0, π] between the projections of ``wi`` and ``wo`` onto the surface [rad];
    0 where either is at the zenith (``atan2(0, 0) = 0``), the goniometer table's convention."""
    return math.atan2(abs(wix * woy - wiy * wox), wix * wox + wiy * woy)


@njit(cache=True, error_model="numpy", inline="always")
def _nearest_row(table, row, o_tr, n_r, theta_o):
    """The θr node nearest to ``theta_o``: the row the sampler draws from for this ``wo``."""
    k, t = _grid_cell(table, row, o_tr, n_r, theta_o)
    return k + 1 if t > 0.5 else k


@njit(cache=True, error_model="numpy")
def tabulated_eval(table, row, wix, wiy, wiz, wox, woy, woz):
    """Measured BRDF: trilinear interpolation of the node values in (θi, θr, Δφ) [1/sr].

    At a node the interpolation weights are exactly 0 and 1, so the value there is the node's
    (the goniometer's own value at measured angles). Zero unless both directions are above the
    horizon or when the header is not a valid tabulated layout.
    """
    if not _both_above(wiz, woz):
        return 0.0
    ok, n_i, n_r, n_p = _tabulated_sizes(table, row)
    if not ok:
        return 0.0
    o_ti, o_tr, o_ph, _, o_val, _, _, _, _ = tabulated_layout(n_i, n_r, n_p)
    a, ta = _grid_cell(table, row, o_ti, n_i, zenith_angle(wix, wiy, wiz))
    r, tr = _grid_cell(table, row, o_tr, n_r, zenith_angle(wox, woy, woz))
    b, tb = _grid_cell(table, row, o_ph, n_p, azimuth_difference(wix, wiy, wox, woy))
    f = 0.0
    for dr in range(2):
        wr = tr if dr else 1.0 - tr
        for da in range(2):
            wa = ta if da else 1.0 - ta
            base = o_val + ((r + dr) * n_i + a + da) * n_p + b
            f += wr * wa * ((1.0 - tb) * table[row, base] + tb * table[row, base + 1])
    return max(f, 0.0)  # values are >= 0; max only removes a rounding -0.0


@njit(cache=True, error_model="numpy")
def tabulated_pdf(table, row, wix, wiy, wiz, wox, woy, woz):
    """Density of :func:`tabulated_sample_direction` [1/sr]: the mixture
    ``p_cos cos θi / π + (1 - p_cos) D[r, a, b]``, ``r`` the θr row nearest to ``wo`` and
    ``D`` the constant density of the (θi, Δφ) cell ``(a, b)`` holding ``wi``."""
    if not _both_above(wiz, woz):
        return 0.0
    ok, n_i, n_r, n_p = _tabulated_sizes(table, row)
    if not ok:
        return 0.0
    o_ti, o_tr, o_ph, _, _, _, _, o_dens, _ = tabulated_layout(n_i, n_r, n_p)
    p_cos = clamp(table[row, _TAB_P_COS], 0.0, 1.0)
    pdf = p_cos * cosine_hemisphere_pdf(wiz)
    if p_cos < 1.0:
        r = _nearest_row(table, row, o_tr, n_r, zenith_angle(wox, woy, woz))
        a, _ = _grid_cell(table, row, o_ti, n_i, zenith_angle(wix, wiy, wiz))
        b, _ = _grid_cell(table, row, o_ph, n_p, azimuth_difference(wix, wiy, wox, woy))
        pdf += (1.0 - p_cos) * table[row, o_dens + (r * (n_i - 1) + a) * (n_p - 1) + b]
    return pdf


@njit(cache=True, error_model="numpy")
def tabulated_sample_direction(table, row, wox, woy, woz, u0, u1, u2):
    """A direction ``wi`` from the mixture of :func:`tabulated_pdf`.

    ``u2 < p_cos``: cosine-hemisphere sampling with ``(u0, u1)``. Otherwise, in the θr row
    nearest to ``wo``: a θi cell from the marginal CDF (``u0``), a Δφ cell from that cell's
    conditional CDF (``u1``), a point uniform in solid angle within the cell (the rescaled
    ``u0``, ``u1``: uniform in ``cos θi`` and in ``Δφ``), and the side of ``wo``'s plane from
    the rescaled ``u2``. An invalid header gives the zenith (whose pdf is then 0).
    """
    ok, n_i, n_r, n_p = _tabulated_sizes(table, row)
    if not ok:
        return 0.0, 0.0, 1.0
    p_cos = clamp(table[row, _TAB_P_COS], 0.0, 1.0)
    if u2 < p_cos:
        return sample_cosine_hemisphere(u0, u1)
    _, o_tr, o_ph, o_mu, _, o_marg, o_cond, _, _ = tabulated_layout(n_i, n_r, n_p)
    r = _nearest_row(table, row, o_tr, n_r, zenith_angle(wox, woy, woz))
    a, v0 = _cdf_cell(table, row, o_marg + r * n_i, n_i, clamp(u0, 0.0, U_MAX))
    b, v1 = _cdf_cell(table, row, o_cond + (r * (n_i - 1) + a) * n_p, n_p,
                      clamp(u1, 0.0, U_MAX))
    mu0, mu1 = table[row, o_mu + a], table[row, o_mu + a + 1]
    mu = mu0 + v0 * (mu1 - mu0)  # uniform in cos θi: uniform in solid angle over the cell
    sin_t = math.sqrt(max(1.0 - mu * mu, 0.0))  # |mu| <= 1 up to rounding
    p0, p1 = table[row, o_ph + b], table[row, o_ph + b + 1]
    dphi = p0 + v1 * (p1 - p0)
    # u2 in [p_cos, 1): its rescaled value picks the side (the table is isotropic)
    side = safe_divide(u2 - p_cos, 1.0 - p_cos)
    sign = 1.0 if side < 0.5 else -1.0
    rho = math.hypot(wox, woy)
    co, so = (wox / rho, woy / rho) if rho > 0.0 else (1.0, 0.0)  # zenith wo: azimuth 0
    if 0.0 < rho < 1e-300:
        # subnormal components keep a few bits: their ratios to rho are no longer a unit
        # vector (found by hypothesis: wo 5e-324 rad from the zenith gave |wi| = 1.41)
        n = math.hypot(co, so)  # >= ~0.7: one of the two ratios is at least 1/sqrt(2)
        co, so = co / n, so / n
    sd, cd = sincos_turns(dphi * (0.5 / math.pi))
    sd = sign * sd
    # azimuth of wi = azimuth of wo ± Δφ
    return sin_t * (co * cd - so * sd), sin_t * (so * cd + co * sd), mu


# The table's helpers above are inline="always": passing the table array into a call costs a
# reference count increment and decrement each (measured 15 % of a tabulated eval + sample).
# The dispatchers reach the tabulated kernels through these three, which compile to "reflects
# nothing" when ``table`` is None: the renderer passes None for scenes without a tabulated
# material, so that their ray loops carry no code of it. (A branch that hands the table array
# to a kernel costs the loop reference counting and an opaque call even where the branch is
# never taken: measured +30 % per Lambertian eval + sample in a bare loop, 30 -> 40 ns.)
def tabulated_eval_in(table, row, wix, wiy, wiz, wox, woy, woz):
    """:func:`tabulated_eval`, or 0 for ``table`` None. Compiled code only."""
    raise NotImplementedError("compiled code only")


def tabulated_pdf_in(table, row, wix, wiy, wiz, wox, woy, woz):
    """:func:`tabulated_pdf`, or 0 for ``table`` None. Compiled code only."""
    raise NotImplementedError("compiled code only")


def tabulated_sample_in(table, row, wox, woy, woz, u0, u1, u2):
    """:func:`tabulated_sample_direction`, or the zenith for ``table`` None. Compiled code
    only."""
    raise NotImplementedError("compiled code only")


@overload(tabulated_eval_in, inline="always")
def _tabulated_eval_in(table, row, wix, wiy, wiz, wox, woy, woz):
    if isinstance(table, types.NoneType):
        return lambda table, row, wix, wiy, wiz, wox, woy, woz: 0.0
    return lambda table, row, wix, wiy, wiz, wox, woy, woz: tabulated_eval(
        table, row, wix, wiy, wiz, wox, woy, woz)


@overload(tabulated_pdf_in, inline="always")
def _tabulated_pdf_in(table, row, wix, wiy, wiz, wox, woy, woz):
    if isinstance(table, types.NoneType):
        return lambda table, row, wix, wiy, wiz, wox, woy, woz: 0.0
    return lambda table, row, wix, wiy, wiz, wox, woy, woz: tabulated_pdf(
        table, row, wix, wiy, wiz, wox, woy, woz)


@overload(tabulated_sample_in, inline="always")
def _tabulated_sample_in(table, row, wox, woy, woz, u0, u1, u2):
    if isinstance(table, types.NoneType):
        return lambda table, row, wox, woy, woz, u0, u1, u2: (0.0, 0.0, 1.0)
    return lambda table, row, wox, woy, woz, u0, u1, u2: tabulated_sample_direction(
        table, row, wox, woy, woz, u0, u1, u2)


# -------------------------------------------------------------------------------------------
# Dispatch
# -------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy", inline="always")
def eval_brdf_row(kind, p, table, row, wix, wiy, wiz, wox, woy, woz):
    """BRDF value f_r [1/sr] without the cosine of material ``row`` of ``table``.

    ``p`` is the row's header (:func:`param_row`, or the row itself as an array); ``table``
    (M, L) holds the full rows, read only by models with data beyond the header (tabulated),
    or is None where no material has such data (a tabulated kind then reflects nothing, and
    the compiled code has no branch for it). 0 for an unknown ``kind``.
    """
    if kind == KIND_LAMBERTIAN:
        return lambertian_eval(p, wiz, woz)
    if kind == KIND_SEED_MICROFACET:
        return seed_microfacet_eval(p, wix, wiy, wiz, wox, woy, woz)
    if kind == KIND_COOK_TORRANCE:
        return cook_torrance_eval(p, wix, wiy, wiz, wox, woy, woz)
    if kind == KIND_HAPKE:
        return hapke_eval(p, wix, wiy, wiz, wox, woy, woz)
    if kind == KIND_TABULATED:
        return tabulated_eval_in(table, row, wix, wiy, wiz, wox, woy, woz)
    return 0.0


@njit(cache=True, error_model="numpy", inline="always")
def pdf_brdf_row(kind, p, table, row, wix, wiy, wiz, wox, woy, woz):
    """Solid-angle density of ``sample_brdf_row`` returning wi for wo; 0 for an unknown
    ``kind``. Arguments as :func:`eval_brdf_row`."""
    if kind in (KIND_SEED_MICROFACET, KIND_COOK_TORRANCE):
        return mixture_pdf(kind, p, wix, wiy, wiz, wox, woy, woz)
    if kind in (KIND_LAMBERTIAN, KIND_HAPKE):
        return cosine_pdf(wiz, woz)
    if kind == KIND_TABULATED:
        return tabulated_pdf_in(table, row, wix, wiy, wiz, wox, woy, woz)
    return 0.0


@njit(cache=True, error_model="numpy", inline="always")
def sample_brdf_row(kind, p, table, row, wox, woy, woz, u0, u1, u2):
    """Importance-sample wi; returns (wi_x, wi_y, wi_z, pdf, weight = f cos / pdf).

    Microfacet models pick the Beckmann lobe (``wi = reflect(wo, h)``) when ``u2 < p_spec`` and
    the cosine lobe otherwise (:func:`lobe_probabilities`); Lambertian and Hapke sample the
    cosine lobe; a tabulated material samples its table (:func:`tabulated_sample_direction`).
    ``pdf`` is :func:`pdf_brdf_row` at the sampled direction (so invalid samples, e.g. a
    reflection below the horizon, get ``pdf = weight = 0``), for microfacet models with the
    lobe probabilities computed once. An unknown ``kind`` gives invalid samples. Arguments as
    :func:`eval_brdf_row`.
    """
    if kind in (KIND_SEED_MICROFACET, KIND_COOK_TORRANCE):
        p_spec, p_diff = lobe_probabilities(kind, p, woz)
        if u2 < p_spec:
            hx, hy, hz = sample_beckmann_normal(u0, u1, p[_ALPHA])
            x, y, z = reflect(wox, woy, woz, hx, hy, hz)
        else:
            x, y, z = sample_cosine_hemisphere(u0, u1)
        # == mixture_pdf(kind, p, x, y, z, wo): the same operations on the same inputs
        pdf = lobe_mixture_pdf(p, p_spec, p_diff, x, y, z, wox, woy, woz)
    else:
        if kind == KIND_TABULATED:
            x, y, z = tabulated_sample_in(table, row, wox, woy, woz, u0, u1, u2)
        else:
            x, y, z = sample_cosine_hemisphere(u0, u1)
        pdf = pdf_brdf_row(kind, p, table, row, x, y, z, wox, woy, woz)
    if not pdf > 0.0:
        return x, y, z, pdf, 0.0
    f = eval_brdf_row(kind, p, table, row, x, y, z, wox, woy, woz)
    return x, y, z, pdf, sample_weight(f, z, pdf)


def as_table(p):
    """A 1-D parameter vector as a one-row table (a view), the ``table`` of the ``*_row``
    dispatchers with ``row = 0``; ``None`` for a header given as a tuple (:func:`param_row`),
    which has no data behind it. Compiled code only.
    """
    raise NotImplementedError("as_table is only available inside compiled kernels")


@overload(as_table, inline="always")
def _as_table_compiled(p):
    if isinstance(p, types.Array):
        return lambda p: p.reshape((1, p.shape[0]))
    return lambda p: None


@njit(cache=True, error_model="numpy", inline="always")
def eval_brdf(kind, p, wix, wiy, wiz, wox, woy, woz):
    """:func:`eval_brdf_row` of one 1-D parameter vector ``p`` (any length >= N_PARAMS)."""
    return eval_brdf_row(kind, p, as_table(p), 0, wix, wiy, wiz, wox, woy, woz)


@njit(cache=True, error_model="numpy", inline="always")
def pdf_brdf(kind, p, wix, wiy, wiz, wox, woy, woz):
    """:func:`pdf_brdf_row` of one 1-D parameter vector ``p``."""
    return pdf_brdf_row(kind, p, as_table(p), 0, wix, wiy, wiz, wox, woy, woz)


@njit(cache=True, error_model="numpy", inline="always")
def sample_brdf(kind, p, wox, woy, woz, u0, u1, u2):
    """:func:`sample_brdf_row` of one 1-D parameter vector ``p``."""
    return sample_brdf_row(kind, p, as_table(p), 0, wox, woy, woz, u0, u1, u2)


@njit(cache=True, inline="always", error_model="numpy")
def param_row(table, m):
    """Row ``m`` of an (M, N_PARAMS) parameter table as a tuple, the ``p`` of the dispatchers.

    Inside a loop over rays this is eight loads; an array row ``table[m]`` would be a new view
    per ray, whose reference counting kept the whole loop from being optimised (measured 3.6x
    slower next-event estimation on the corner scene).
    """
    return (table[m, 0], table[m, 1], table[m, 2], table[m, 3], table[m, 4], table[m, 5],
            table[m, 6], table[m, 7])


assert N_PARAMS == 8, "param_row spells out N_PARAMS entries"


@njit(cache=True, inline="always", error_model="numpy")
def duff_frame(nx, ny, nz):
    """Tangent and bitangent completing a unit normal to a right-handed frame.

    Branchless construction of Duff et al. (2017), "Building an Orthonormal Basis, Revisited";
    exact for every unit normal including (0, 0, -1). Returns (t0, t1, t2, b0, b1, b2).
    """
    sign = 1.0 if nz >= 0.0 else -1.0
    # sign + nz has magnitude >= 1, so a is finite.
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx, b, sign + ny * ny * a, -ny)


@njit(cache=True, error_model="numpy", parallel=True)
def frame_batch(n):
    """:func:`duff_frame` over rows of ``n`` (m, 3): tangents and bitangents, each (m, 3)."""
    m = n.shape[0]
    t = np.empty((m, 3))
    b = np.empty((m, 3))
    for i in prange(m):
        t[i, 0], t[i, 1], t[i, 2], b[i, 0], b[i, 1], b[i, 2] = duff_frame(n[i, 0], n[i, 1],
                                                                          n[i, 2])
    return t, b


# -------------------------------------------------------------------------------------------
# Batch wrappers for the numpy API
# -------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy", parallel=True)
def eval_batch(kind, p, wi, wo):
    """:func:`eval_brdf` over rows of ``wi``, ``wo`` (n, 3)."""
    n = wi.shape[0]
    out = np.empty(n)
    t = as_table(p)
    for i in prange(n):
        out[i] = eval_brdf_row(kind, p, t, 0, wi[i, 0], wi[i, 1], wi[i, 2], wo[i, 0], wo[i, 1],
                               wo[i, 2])
    return out


@njit(cache=True, error_model="numpy", parallel=True)
def pdf_batch(kind, p, wi, wo):
    """:func:`pdf_brdf` over rows of ``wi``, ``wo`` (n, 3)."""
    n = wi.shape[0]
    out = np.empty(n)
    t = as_table(p)
    for i in prange(n):
        out[i] = pdf_brdf_row(kind, p, t, 0, wi[i, 0], wi[i, 1], wi[i, 2], wo[i, 0], wo[i, 1],
                              wo[i, 2])
    return out


@njit(cache=True, error_model="numpy", parallel=True)
def sample_batch(kind, p, wo, u):
    """:func:`sample_brdf` over rows of ``wo``, ``u`` (n, 3): ``(wi, pdf, weight)``."""
    n = wo.shape[0]
    wi = np.empty((n, 3))
    pdf = np.empty(n)
    weight = np.empty(n)
    t = as_table(p)
    for i in prange(n):
        x, y, z, q, w = sample_brdf_row(
            kind, p, t, 0, wo[i, 0], wo[i, 1], wo[i, 2], u[i, 0], u[i, 1], u[i, 2]
        )
        wi[i, 0], wi[i, 1], wi[i, 2], pdf[i], weight[i] = x, y, z, q, w
    return wi, pdf, weight


@njit(cache=True, error_model="numpy", parallel=True)
def weight_batch(f, wi, pdf):
    """:func:`sample_weight` over arrays ``f`` (n,), ``wi`` (n, 3), ``pdf`` (n,)."""
    n = f.shape[0]
    out = np.empty(n)
    for i in prange(n):
        out[i] = sample_weight(f[i], wi[i, 2], pdf[i])
    return out


@njit(cache=True, error_model="numpy", parallel=True)
def hapke_batch(p, mu_i, mu_o, cos_g):
    """:func:`hapke_f` (no horizon masking) over 1-d arrays of equal length."""
    n = mu_i.shape[0]
    out = np.empty(n)
    for i in prange(n):
        out[i] = hapke_f(p, mu_i[i], mu_o[i], cos_g[i])
    return out
