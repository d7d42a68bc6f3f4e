"""Hapke's bidirectional reflectance of particulate (regolith) surfaces, as used by SLIM."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from sim_core.errors import InvalidInputError
from sim_core.materials.base import Material
from sim_core.materials.kernels import KIND_HAPKE, hapke_batch, hapke_params
from sim_core.materials.microfacet import check_parameter

__all__ = ["ALWAYS_ALLOWED_W", "Hapke", "hapke_brdf", "hapke_max_albedo", "hapke_max_w"]

_MODEL = "hapke"

#: relative safety margin on the quadrature of the directional albedo (its measured error is
#: below 1e-5 for every allowed parameter set)
_QUADRATURE_MARGIN = 1e-3
#: every w up to this value is allowed whatever b0, h and phase_b are (worst case b0 = 2,
#: h = 1, phase_b = 1, maximum at grazing view: w_max = 0.7838)
ALWAYS_ALLOWED_W = 0.78


def hapke_brdf(
    mu_i: np.ndarray,
    mu_o: np.ndarray,
    cos_g: np.ndarray,
    w: float,
    b0: float,
    h: float,
    phase_b: float,
) -> np.ndarray:
    """Hapke BRDF ``f = w / (4π) [P(g)(1 + B(g)) + H(μi) H(μo) - 1] / (μi + μo)`` [1/sr].

    No horizon masking: callers pass ``μi, μo`` in [0, 1] (``μo = 0`` is the grazing limit the
    albedo quadrature needs). Symmetric in ``μi``, ``μo``. The arrays broadcast against each
    other; the formula is the kernel ``kernels.hapke_f``.
    """
    mu_i, mu_o, cos_g = np.broadcast_arrays(
        *(np.asarray(x, dtype=np.float64) for x in (mu_i, mu_o, cos_g))
    )
    flat = [np.ascontiguousarray(x).ravel() for x in (mu_i, mu_o, cos_g)]
    return hapke_batch(hapke_params(w, b0, h, phase_b), *flat).reshape(mu_i.shape)


# Quadrature of the directional albedo a(μo) = ∫ f μi dωi: Gauss-Legendre in μi on [0, 1] and
# in the relative azimuth φ on [0, π] (f is even in φ, hence the factor 2).
_N_QUAD = 64
_x, _wx = np.polynomial.legendre.leggauss(_N_QUAD)
_MU_NODES = 0.5 * (_x + 1.0)
_MU_WEIGHTS = 0.5 * _wx
_PHI_NODES = 0.5 * np.pi * (_x + 1.0)
_PHI_WEIGHTS = np.pi * _wx  # 2 * (π/2) * weights
_MU_O_GRID = np.linspace(0.0, 1.0, 21)  # the maximum lies at μo = 0 or 1 in all cases studied


@functools.lru_cache(maxsize=512)
def hapke_max_albedo(w: float, b0: float, h: float, phase_b: float) -> float:
    """Maximum over ``μo`` of the directional albedo of :func:`hapke_brdf`, by quadrature."""
    mu_i = _MU_NODES[None, :, None]
    phi = _PHI_NODES[None, None, :]
    mu_o = _MU_O_GRID[:, None, None]
    sin_i = np.sqrt(1.0 - mu_i * mu_i)
    sin_o = np.sqrt(1.0 - mu_o * mu_o)
    cos_g = mu_i * mu_o + sin_i * sin_o * np.cos(phi)
    f = hapke_brdf(mu_i, mu_o, cos_g, w, b0, h, phase_b)
    weights = (_MU_NODES * _MU_WEIGHTS)[None, :, None] * _PHI_WEIGHTS[None, None, :]
    return float(np.max(np.sum(f * weights, axis=(1, 2))))


def hapke_max_w(b0: float, h: float, phase_b: float) -> float:
    """Largest single-scattering albedo ``w`` allowed for the given ``b0, h, phase_b``.

    The albedo increases with ``w`` (both the prefactor and ``H`` do), so bisection applies.
    """

    def ok(w: float) -> bool:
        return hapke_max_albedo(w, b0, h, phase_b) * (1.0 + _QUADRATURE_MARGIN) <= 1.0

    if ok(1.0):
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


@dataclass(frozen=True)
class Hapke(Material):
    r"""Hapke bidirectional reflectance for regolith-covered, airless bodies.

    Models the surface of the Moon, Mercury and small bodies (Phobos, Vesta, Ceres): low
    single-scattering albedo, mild anisotropy and an opposition surge ("hot spot") near zero
    phase. Source: "An Efficient and Lightweight Illumination Model for Planetary Bodies
    Including Direct and Diffuse Radiation" (SLIM), J. Imaging 6, 84 (2020), Section 6.2,
    eq. (11), after Hapke, J. Geophys. Res. 86, 3039 (1981):

    .. math::

        r(\mu_0, \mu, g) = \frac{w}{4\pi}\,\frac{\mu_0}{\mu_0 + \mu}
            \big[P(g)\,(1 + B(g)) + H(\mu_0) H(\mu) - 1\big]

        H(x) = \frac{1 + 2x}{1 + 2x\sqrt{1 - w}},\qquad
        B(g) = \frac{B_0}{1 + \tan(g/2)/h}

    with ``μ0 = cos θi`` (towards the light), ``μ = cos θr`` (towards the viewer) and ``g`` the
    phase angle between the directions to the light and to the viewer (``cos g = wi·wo``;
    ``g = 0`` at opposition). As a BRDF, ``f = r / cos θi``:

    .. math::

        f = \frac{w}{4\pi}\,\frac{P(g)(1 + B(g)) + H(\mu_0)H(\mu) - 1}{\mu_0 + \mu}

    Reading of eq. (11): the paper prints ``ω/(4(μ0 + μ)) [P(Ω)(1 + B(Ω)) + H(μ)H(μ0) - 1]``
    (calling it the "scattering phase function P(μ, μ0, Ω)"). That is ``π f``, Hapke's ``r``
    in the reflectance-factor normalisation ``π r / μ0``; taken literally as a BRDF it would
    be π times too bright (albedo > 1 already for ``w`` ≈ 0.3). We use Hapke's ``r`` and
    ``f = r / μ0`` as above.

    Parameters
    ----------
    w : float, default 0.45
        Single-scattering albedo ``ω``, dimensionless, in [0, 1] (the paper's search range),
        subject to the energy condition below.
    b0 : float, default 1.83
        Opposition-surge amplitude ``B0`` (the paper's ``B``), dimensionless, in [0, 2] (the
        paper's search range).
    h : float, default 0.53
        Opposition-surge angular width, dimensionless, in [0, 1] (the paper's search range);
        ``h = 0`` switches the surge off.
    phase_b : float, default 0.0
        The paper leaves the particle phase function ``P(Ω)`` unspecified and fits only
        ``B, ω, h``; we offer the first-order Legendre form ``P(g) = 1 + b cos g``, ``b`` in
        [-1, 1] (so ``P >= 0``; ``b > 0`` scatters back towards the light). The default
        ``b = 0`` is isotropic scattering.

    The defaults are the paper's own fit (its Table 5, "this study", 4 Vesta:
    ``B = 1.83, ω = 0.45, h = 0.53``), also available as the preset ``vesta-regolith``.

    Energy condition
    ----------------
    Eq. (11) can reflect more than it receives, for two reasons: Hapke's approximate
    ``H``-function overestimates Chandrasekhar's (with ``w = 1``, ``B0 = 0`` the albedo at
    normal view is 1.04), and the opposition term adds energy that nothing balances (with
    ``w = 1, B0 = 2, h = 1`` the albedo at grazing view is 1.50). The constructor therefore
    computes the maximum directional albedo over ``wo`` by quadrature (64 x 64 Gauss-Legendre
    points, 21 viewing angles, relative margin 1e-3) and rejects parameter sets for which it
    exceeds 1, naming the largest allowed ``w`` for the given ``b0, h, phase_b``. Every
    ``w <= 0.78`` is allowed; for ``b0 = 0, phase_b = 0`` the limit is ``w <= 0.9998``; for the
    defaults' ``b0 = 1.83, h = 0.53`` it is ``w <= 0.914``.

    Sampling
    --------
    Cosine-weighted hemisphere, ``pdf = cos θi / π``, ``weight = π f``.

    Reciprocity
    -----------
    Reciprocal: ``f`` is symmetric in ``μ0`` and ``μ`` and ``g`` is symmetric in ``wi``, ``wo``.

    Kernel
    ------
    ``kernels.hapke_eval`` (``kernels.hapke_f`` with horizon masking) and ``kernels.cosine_pdf``;
    parameters ``kernels.hapke_params``.
    """

    w: float = 0.45
    b0: float = 1.83
    h: float = 0.53
    phase_b: float = 0.0

    name: ClassVar[str] = _MODEL
    kernel_kind: ClassVar[int] = KIND_HAPKE

    def __post_init__(self) -> None:
        for field, lo, hi in (
            ("w", 0.0, 1.0),
            ("b0", 0.0, 2.0),
            ("h", 0.0, 1.0),
            ("phase_b", -1.0, 1.0),
        ):
            value = check_parameter(field, getattr(self, field), lo, hi, model=_MODEL)
            object.__setattr__(self, field, value)
        bound = hapke_max_albedo(self.w, self.b0, self.h, self.phase_b)
        bound *= 1.0 + _QUADRATURE_MARGIN
        if bound > 1.0:
            w_max = hapke_max_w(self.b0, self.h, self.phase_b)
            raise InvalidInputError(
                "w",
                f"w = {self.w!r} with b0 = {self.b0!r}, h = {self.h!r}, phase_b = "
                f"{self.phase_b!r} reflects up to {bound:.4f} > 1 of the incident light; "
                f"for these b0, h, phase_b the allowed range is w in [0, {w_max:.4f}] "
                f"(w <= {ALWAYS_ALLOWED_W} is always allowed) ({_MODEL})",
            )

    @property
    def albedo_bound(self) -> float:
        """Maximum directional albedo by quadrature, times (1 + 1e-3); at most 1."""
        bound = hapke_max_albedo(self.w, self.b0, self.h, self.phase_b)
        return bound * (1.0 + _QUADRATURE_MARGIN)

    def kernel_params(self) -> np.ndarray:
        return hapke_params(self.w, self.b0, self.h, self.phase_b)
