"""Fitting reflectance models (BRDFs) to goniometer measurements (issue 14, section 1).

- :mod:`calibration.brdf.models`: the fittable kinds, their free parameters and physical bounds;
  evaluation through the material's own ``eval_local``.
- :mod:`calibration.brdf.fit`: RANSAC, differential evolution, least-squares refinement,
  e_fit (seed eq. 11), outlier flags, uncertainties and the determinability check
  (:func:`fit_brdf`, :class:`BrdfFit`).
- :mod:`calibration.brdf.material_file`: writes the fit as a material file a scene's
  ``material: {file: ...}`` references.
- :mod:`calibration.brdf.table3`: the reproduction of the relay-wall paper's Table 3.
"""

from calibration.brdf.fit import BrdfFit, FitSettings, e_fit, fit_brdf
from calibration.brdf.models import FIT_MODELS, FitModel, ParameterSpec

__all__ = [
    "FIT_MODELS",
    "BrdfFit",
    "FitModel",
    "FitSettings",
    "ParameterSpec",
    "e_fit",
    "fit_brdf",
]
