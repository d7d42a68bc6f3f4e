"""Write a BRDF fit as a material file a scene's ``material: {file: ...}`` references.

The file is YAML: the scene's ``MaterialSpec`` at the top level (``kind`` and ``params``, read
by :func:`sim_core.materials.material_file.read_material_file`) and a ``fit`` section with the
fit's report (:meth:`calibration.brdf.fit.BrdfFit.report`: uncertainties, determination,
e_fit, per-sample relative errors and outlier flags), which the scene ignores::

    kind: cook-torrance
    params: {kd: 0.78, ks: 0.2, m: 0.08, n2: 1.67, fresnel_angle: incidence}
    fit:
      e_fit: 0.0026
      n_outliers: 20
      ...

The file is written atomically (a temporary file in the same folder, then renamed), so a
reader never sees half a file.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from calibration.brdf.fit import BrdfFit
from sim_core.files import atomic_write

__all__ = ["material_file_text", "write_material_file"]


def material_file_text(fit: BrdfFit) -> str:
    """The YAML text of the material file of ``fit``."""
    spec = fit.material_spec()
    body = {"kind": spec["kind"], "params": spec["params"], "fit": fit.report()}
    header = (f"# Material fitted by `toftwin calibrate brdf` ({fit.kind}) to {fit.table.source}.\n"
              "# A scene references it as `material: {file: THIS_FILE}`; only kind and params "
              "are read,\n# the fit section is the fit's report.\n")
    return header + yaml.safe_dump(body, sort_keys=False, allow_unicode=True, width=100)


def write_material_file(path: str | Path, fit: BrdfFit) -> Path:
    """Write the material file of ``fit`` to ``path`` atomically; returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(out, material_file_text(fit))
