"""A material's BRDF measured on the rig: a sample plate swept by the turntable (issue 14, §2).

- :mod:`~calibration.rig_material.plan`: the sweep's plan and the sample plate in its fixture;
- :mod:`~calibration.rig_material.sweep`: the captures' plan (camera's light alone; with the
  solar simulator) and the captures grouped by angle;
- :mod:`~calibration.rig_material.reference`: the twin's reference Lambertian of each view and
  the plate's pixel geometry;
- :mod:`~calibration.rig_material.slices`: the retro-reflection and solar slices as a
  goniometer table, and the flat-uniform check;
- :mod:`~calibration.rig_material.fit`: the model fitted, what the slices determine, the rest
  held at the prior;
- :mod:`~calibration.rig_material.procedure`: all of it as a plan and a fit (``toftwin
  calibrate material``; the service runs the plan on the rig:
  :func:`service.lab.acquisition.run_material_calibration`).
"""

from calibration.rig_material.fit import (
    DEFAULT_MODEL,
    ParameterStatus,
    SliceFit,
    fit_slices,
    prior_material,
)
from calibration.rig_material.plan import (
    SAMPLE_NAME,
    MaterialSweepPlan,
    sample_angles,
    sample_object,
)
from calibration.rig_material.procedure import (
    MaterialCalibration,
    fit_material_sweep,
    material_capture_plan,
)
from calibration.rig_material.slices import Slices, extract_slices

__all__ = [
    "DEFAULT_MODEL",
    "SAMPLE_NAME",
    "MaterialCalibration",
    "MaterialSweepPlan",
    "ParameterStatus",
    "SliceFit",
    "Slices",
    "extract_slices",
    "fit_material_sweep",
    "fit_slices",
    "material_capture_plan",
    "prior_material",
    "sample_angles",
    "sample_object",
]
