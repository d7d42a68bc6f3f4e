"""The verdict of every parameter ``toftwin calibrate material`` writes (issue 27).

The slices' fit (:mod:`calibration.rig_material.fit`) sorts the parameters into ``determined``,
``conditional`` and ``prior``; the verdicts (:mod:`calibration.verdicts`) add the fit's own
evidence (:mod:`calibration.brdf.evidence`), with the rig's slices as its groups: one group per
slice of one view (``retro@+30``, ``solar@-10``), since a view's rows share the plate's pose and
the reference's scale. So the bootstrap resamples views, and a view the model cannot explain
is named.

- ``prior``: ``not determined`` (the file keeps the prior), the reason from the fit;
- ``conditional``: ``not determined``: its value follows the held parameters' prior (its std
  is the one given that prior);
- ``determined``: judged on the evidence; it stays ``determined`` only when the fit explains
  the slices and its honest std is within :data:`calibration.rig_material.fit.
  DETERMINED_RELATIVE_UNCERTAINTY` of its value.
"""

from __future__ import annotations

from calibration.brdf.evidence import PARAMS_PREFIX, FitEvidence, brdf_verdicts, fit_evidence
from calibration.rig_material.fit import SliceFit
from calibration.rig_material.slices import Slices
from calibration.verdicts import Verdict, Verdicts

__all__ = ["slice_groups", "sweep_evidence", "sweep_verdicts"]


def slice_groups(slices: Slices) -> list[str]:
    """Each table row's group, in the table's order (:meth:`Slices.table`): its slice and the
    turntable angle of its view (``retro@+30``)."""
    return [f"{part.slice_name}@{angle:+g}" for part in slices.parts
            for angle in part.turntable_angle_deg]


def sweep_evidence(result: SliceFit, slices: Slices, seed: int = 0) -> FitEvidence:
    """The final fit's evidence with the views as its groups."""
    return fit_evidence(result.fit, slice_groups(slices), seed=seed)


def sweep_verdicts(result: SliceFit, slices: Slices, seed: int = 0,
                   evidence: FitEvidence | None = None) -> Verdicts:
    """Every parameter of the material file judged (module docstring), ``params.NAME``."""
    ev = evidence if evidence is not None else sweep_evidence(result, slices, seed)
    held = {n: p.reason for n, p in result.parameters.items() if p.status == "prior"}
    judged = brdf_verdicts(result.fit, held_reasons=held, evidence=ev)
    out = Verdicts()
    for key, verdict in judged.items():
        status = result.parameters[key.removeprefix(PARAMS_PREFIX)]
        if status.status == "conditional" and verdict.verdict != "unexplained":
            verdict = Verdict("not determined", verdict.std, status.reason)
        out.add(key, verdict)
    return out
