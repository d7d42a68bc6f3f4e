"""Reflectance models (BRDFs) of the simulator.

The contract every model fulfils is stated in :mod:`sim_core.materials.base`. Every formula
lives once, as a scalar numba kernel in :mod:`sim_core.materials.kernels` (``eval_brdf``,
``pdf_brdf``, ``sample_brdf``, dispatching on ``Material.kernel_kind`` with the parameter vector
``Material.kernel_params()``), which the renderer calls per ray and the numpy methods
(``eval_local``, ``pdf_local``, ``sample_local``) call through batch wrappers; parameter
validation and the sampling mixture live in :mod:`sim_core.materials.microfacet`.

Models
------
- :class:`SeedMicrofacet` (``"seed-microfacet"``): Torrance–Sparrow + Lambert, seed paper
  eqs. (9)-(10).
- :class:`CookTorrance` (``"cook-torrance"``): Cook–Torrance with dielectric Fresnel, NLOS
  relay-wall paper eqs. (8)-(12).
- :class:`Lambertian` (``"lambertian"``).
- :class:`Hapke` (``"hapke"``): regolith reflectance, SLIM paper eq. (11).
- :class:`Tabulated` (``"tabulated"``): a measured goniometer table, interpolated by the AMCW
  ToF multipath paper's inverse distance weighting, eqs. (16)-(17).

Build them directly, with ``make_material(kind, **params)``, or by preset name with
``material_preset(name)``; ``PRESETS`` lists the presets as ``name -> (kind, params)``.
"""

from sim_core.materials.base import (
    BSDFSample,
    Material,
    frame_from_normal,
    to_local,
    to_world,
)
from sim_core.materials.cook_torrance import CookTorrance
from sim_core.materials.hapke import Hapke
from sim_core.materials.lambertian import Lambertian
from sim_core.materials.presets import MATERIAL_KINDS, PRESETS, make_material, material_preset
from sim_core.materials.seed_microfacet import SeedMicrofacet
from sim_core.materials.tabulated import Tabulated

__all__ = [
    "MATERIAL_KINDS",
    "PRESETS",
    "BSDFSample",
    "CookTorrance",
    "Hapke",
    "Lambertian",
    "Material",
    "SeedMicrofacet",
    "Tabulated",
    "frame_from_normal",
    "make_material",
    "material_preset",
    "to_local",
    "to_world",
]
