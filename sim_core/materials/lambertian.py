"""The ideal diffuse (Lambertian) reflector."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from sim_core.materials.base import Material
from sim_core.materials.kernels import KIND_LAMBERTIAN, lambertian_params
from sim_core.materials.microfacet import check_parameter

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

    Kernel
    ------
    ``kernels.lambertian_eval`` and ``kernels.cosine_pdf``; parameters
    ``kernels.lambertian_params``.
    """

    albedo: float = 0.5

    name: ClassVar[str] = _MODEL
    kernel_kind: ClassVar[int] = KIND_LAMBERTIAN

    def __post_init__(self) -> None:
        value = check_parameter("albedo", self.albedo, 0.0, 1.0, model=_MODEL)
        object.__setattr__(self, "albedo", value)

    @property
    def albedo_bound(self) -> float:
        return self.albedo

    def kernel_params(self) -> np.ndarray:
        return lambertian_params(self.albedo)
