"""The ideal diffuse (Lambertian) reflector."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from sim_core.materials.base import BSDFSample, Material
from sim_core.materials.microfacet import (
    check_parameter,
    cos_theta,
    cosine_hemisphere_pdf,
    finish_sample,
    sample_cosine_hemisphere,
)

__all__ = ["Lambertian"]

_MODEL = "lambertian"


@dataclass(frozen=True)
class Lambertian(Material):
    """Ideal diffuse reflector, ``f = albedo / π``.

    Models matte surfaces whose radiance does not depend on the viewing direction, e.g. the
    black light-absorbing flannel background of the seed paper's ground test (preset
    ``black-flannel``), or diffuse reference targets.

    Parameters
    ----------
    albedo : float, default 0.5
        Directional-hemispherical reflectance, dimensionless, in [0, 1]; it is the exact albedo
        for every ``wo``.

    Sampling
    --------
    Cosine-weighted hemisphere, ``pdf = cos θi / π``, so every valid sample has
    ``weight = albedo``.

    Reciprocity
    -----------
    Reciprocal (constant).
    """

    albedo: float = 0.5

    name: ClassVar[str] = _MODEL

    def __post_init__(self) -> None:
        value = check_parameter("albedo", self.albedo, 0.0, 1.0, model=_MODEL)
        object.__setattr__(self, "albedo", value)

    @property
    def albedo_bound(self) -> float:
        return self.albedo

    def eval_local(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        valid = (cos_theta(wi) > 0.0) & (cos_theta(wo) > 0.0)
        return np.where(valid, self.albedo / np.pi, 0.0)

    def pdf_local(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return np.where(cos_theta(wo) > 0.0, cosine_hemisphere_pdf(wi), 0.0)

    def sample_local(self, wo: np.ndarray, u: np.ndarray) -> BSDFSample:
        return finish_sample(self, sample_cosine_hemisphere(u[:, 0], u[:, 1]), wo)
