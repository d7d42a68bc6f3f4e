"""``toftwin calibrate material``: a material's BRDF from a sample plate on the rig (issue 14, §2).

1. The operator mounts the sample plate (:func:`calibration.rig_material.plan.sample_object`);
   the rig sweeps it and the test object goes back: :func:`material_capture_plan` plans it
   (:mod:`calibration.rig_material.sweep`), the service runs the plan on the rig
   (:func:`service.lab.acquisition.run_material_calibration`) and :func:`fit_material_sweep`
   does 2-4 with the captures it is handed.
2. The twin, with the calibration applied and the plate nominally mounted, renders the same
   views with a reference Lambertian (:mod:`calibration.rig_material.reference`).
3. Measured over reference gives the retro-reflection and the solar slice
   (:mod:`calibration.rig_material.slices`), one goniometer table.
4. The model is fitted to the table; parameters the slices do not determine are held at the
   prior (:mod:`calibration.rig_material.fit`).
5. Every parameter of the material file is judged on the fit's own evidence: the slices'
   chi-square against their noise, the spread over resampled views, what the slices determine
   (:mod:`calibration.rig_material.verdicts`).

The procedure sees frames and the rig's reported states only; the sample's true material is
whatever the operator mounted.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from calibration.brdf.evidence import FitEvidence
from calibration.capture_plan import CapturePlan, Captures
from calibration.captures import Progress, no_progress
from calibration.rig_material.fit import DEFAULT_MODEL, SliceFit, fit_slices, prior_material
from calibration.rig_material.plan import MaterialSweepPlan, sample_object
from calibration.rig_material.reference import reference_view
from calibration.rig_material.slices import Slices, extract_slices
from calibration.rig_material.sweep import sample_captures, sweep_capture_plan
from calibration.rig_material.verdicts import sweep_evidence, sweep_verdicts
from calibration.twin_prediction import CameraUseCase, mounted_spec
from calibration.verdicts import Verdicts
from sim_core.json_safe import json_safe
from sim_core.materials import Material
from sim_core.scene import build_camera
from sim_core.scene_spec import SceneSpec
from sim_core.twin_file import TwinParameters, twin_hash


@dataclass
class MaterialCalibration:
    """The procedure's outcome.

    Attributes
    ----------
    slices : Slices
        The two slices and the plate's check.
    result : SliceFit
        The fit and what the slices determine.
    plan : MaterialSweepPlan
    frames_used : int
    calibration_hash : str or None
        :func:`sim_core.twin_file.twin_hash` of the calibration the references used.
    seconds : dict of str to float
        Wall time of the sweep, the references and the fit.
    verdicts : Verdicts
        Every parameter of the material file judged (``params.kd``, ...).
    evidence : FitEvidence or None
        What the verdicts are judged on (chi-square per view, the spread over views).
    """

    slices: Slices
    result: SliceFit
    plan: MaterialSweepPlan
    frames_used: int
    calibration_hash: str | None
    seconds: dict[str, float] = field(default_factory=dict)
    verdicts: Verdicts = field(default_factory=Verdicts)
    evidence: FitEvidence | None = None

    def report(self) -> dict[str, Any]:
        """Plain JSON: the parameters' statuses, the fit, the slices' sizes and check."""
        p = self.plan
        return json_safe({
            **self.result.report(),
            "slices": {part.slice_name: {"rows": len(part)} for part in self.slices.parts},
            "check": self.slices.check.to_dict(),
            "plan": {"angles_deg": list(p.angles_deg), "size_m": p.size_m,
                     "frames_per_state": p.frames_per_state, "solar_suns": p.solar_suns,
                     "bin_deg": p.bin_deg, "edge_margin_px": p.edge_margin_px,
                     "reference_albedo": p.reference_albedo},
            "frames_used": self.frames_used,
            "calibration_hash": self.calibration_hash,
            "seconds": self.seconds,
            "verdicts": self.verdicts.to_json(),
            "evidence": self.evidence.to_dict() if self.evidence is not None else None,
        })


def material_capture_plan(
    spec: SceneSpec,
    plan: MaterialSweepPlan,
    model: str = DEFAULT_MODEL,
    prior: str | Mapping[str, Any] | Material | None = None,
) -> CapturePlan:
    """What the procedure captures (step 1 of the module docstring): the sample plate (its
    prior as its material in the scene) mounted, swept, and the test object mounted again.

    Raises
    ------
    InvalidInputError
        A bad model or prior (before the rig moves).
    """
    sample = sample_object(spec, plan.size_m, _spec_of(prior_material(model, prior)))
    return sweep_capture_plan(plan, sample)


def fit_material_sweep(
    captures: Captures,
    spec: SceneSpec,
    base_dir: str | Path,
    calibration: TwinParameters | None,
    plan: MaterialSweepPlan,
    use_case: CameraUseCase,
    model: str = DEFAULT_MODEL,
    prior: str | Mapping[str, Any] | Material | None = None,
    progress: Progress = no_progress,
    seed: int = 0,
) -> MaterialCalibration:
    """Steps 2-4 of the module docstring from the captures of :func:`material_capture_plan`.

    Parameters
    ----------
    captures : Captures
        The plan's captures (:func:`service.lab.acquisition.acquire`).
    spec : SceneSpec
        The nominal scene (camera, illumination, turntable, solar simulator).
    base_dir : path
    calibration : TwinParameters or None
        The rig's calibration (``toftwin calibrate rig``); None: the nominal twin.
    plan : MaterialSweepPlan
    use_case : CameraUseCase
        The camera's use case the frames were taken in.
    model : str
        The material kind fitted.
    prior : preset name, material spec, Material or None
        Values of the parameters the slices do not determine (None: the model's defaults).
    progress : callable
        Reported as steps :attr:`MaterialSweepPlan.n_captures` on of
        :attr:`MaterialSweepPlan.n_steps`.
    seed : int
        Seed of the fit.

    Raises
    ------
    InvalidInputError
        A bad model or prior; no usable plate pixels or retro rows
        (:func:`calibration.rig_material.slices.extract_slices`); slices that determine nothing
        (:func:`calibration.rig_material.fit.fit_slices`).
    """
    prior_mat = prior_material(model, prior)
    twin = calibration if calibration is not None else TwinParameters()
    total = plan.n_steps
    t1 = time.perf_counter()
    sweep = sample_captures(captures, plan)
    reference = sample_object(spec, plan.size_m, {"kind": "lambertian",
                                                  "params": {"albedo": plan.reference_albedo}})
    ref_spec = mounted_spec(spec, [reference], use_case)
    references = []
    for i, cap in enumerate(sweep):
        progress(plan.n_captures + i, total, f"twin's reference at {cap.turntable_angle_deg:+.0f}"
                 " deg")
        references.append(reference_view(ref_spec, base_dir, twin, cap.turntable_angle_deg,
                                         plan))
    t2 = time.perf_counter()
    progress(total - 1, total, "slices and fit")
    slices = extract_slices(sweep, references, plan.bin_deg, plan.min_pixels_per_bin)
    table = slices.table(source="rig slices",
                         wavelength_nm=float(build_camera(spec).wavelength_m * 1e9))
    result = fit_slices(table, model, prior_mat, seed=seed)
    evidence = sweep_evidence(result, slices, seed)
    verdicts = sweep_verdicts(result, slices, seed, evidence)
    t3 = time.perf_counter()
    progress(total, total, "done")
    n_frames = plan.n_captures * plan.frames_per_state
    return MaterialCalibration(slices, result, plan, n_frames,
                               twin_hash(calibration) if calibration is not None else None,
                               {"references": t2 - t1, "fit": t3 - t2}, verdicts, evidence)


def _spec_of(material: Material) -> dict[str, Any]:
    from dataclasses import fields

    params = {f.name: getattr(material, f.name) for f in fields(material)}
    return {"kind": material.name, "params": params}
