"""Fit a model to the rig's slices; what the slices determine, and the rest held at the prior.

Two slices of a BRDF do not determine every parameter of a model: Cook–Torrance's ``ks`` and
``n2``, for one, show in the retro-reflection slice only as the specular reflectance at normal
incidence ``ks F(0; n2)`` (the Fresnel term hardly changes below 40 deg, where a narrow lobe
lives). The procedure:

1. Fit every parameter (:func:`calibration.brdf.fit.fit_brdf`: RANSAC, differential evolution,
   least squares; its determination check: the linearised uncertainty and the cost's profile at
   +-:data:`DETERMINED_RELATIVE_UNCERTAINTY` of the value).
2. While a free parameter is not determined, hold the least determined one (the largest
   uncertainty relative to its scale) at the prior and fit again.
3. Move each held parameter's prior by :data:`PRIOR_SHIFT` and fit again: a fitted parameter
   that moves by more than :data:`DETERMINED_RELATIVE_UNCERTAINTY` of its value follows that
   prior.
4. Report each parameter as ``determined`` (determined in the final fit, and independent of the
   held ones' priors), ``conditional`` (determined only once the others were held: its value
   follows their prior) or ``prior`` (not determined by these slices; held at the prior), with
   the reason.

If nothing is determined the slices cannot calibrate the model and :func:`fit_slices` raises.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from calibration.brdf import BrdfFit, FitSettings, fit_brdf
from calibration.brdf.models import fit_model
from sim_core.errors import InvalidInputError
from sim_core.json_safe import json_safe
from sim_core.materials import Material, make_material, material_preset
from sim_core.materials.goniometer import GoniometerTable

#: a parameter is determined when its 1-sigma uncertainty is at most this share of its value
#: (2 %: a determined parameter lands within 5 % of the truth at 2.5 sigma)
DETERMINED_RELATIVE_UNCERTAINTY = 0.02
#: relative shift of a held parameter's prior that tells whether a fitted one follows it
PRIOR_SHIFT = 0.25
#: default model of the rig's fit
DEFAULT_MODEL = "cook-torrance"


@dataclass(frozen=True)
class ParameterStatus:
    """What the slices say about one parameter.

    Attributes
    ----------
    name : str
    status : {"determined", "conditional", "prior"}
    value : float
        The fitted value, or the prior's for ``"prior"``.
    uncertainty : float
        1-sigma uncertainty in the final fit (0 when held at the prior).
    free_uncertainty : float
        1-sigma uncertainty with every parameter free (inf: along a valley of equal fits).
    reason : str
        Why, in words.
    """

    name: str
    status: str
    value: float
    uncertainty: float
    free_uncertainty: float
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return json_safe({"status": self.status, "value": self.value,
                          "uncertainty": self.uncertainty,
                          "free_uncertainty": self.free_uncertainty, "reason": self.reason})


@dataclass(frozen=True)
class SliceFit:
    """The model fitted to the slices, and what they determine.

    Attributes
    ----------
    fit : BrdfFit
        The final fit (parameters held at the prior are its ``fixed``).
    free_fit : BrdfFit
        The fit with every parameter free.
    prior : dict
        The prior's parameters.
    parameters : dict of ParameterStatus
    """

    fit: BrdfFit
    free_fit: BrdfFit
    prior: dict[str, float]
    parameters: dict[str, ParameterStatus] = field(default_factory=dict)

    @property
    def determined(self) -> list[str]:
        """Parameters the slices determine with every parameter free."""
        return [n for n, p in self.parameters.items() if p.status == "determined"]

    @property
    def at_prior(self) -> list[str]:
        """Parameters held at the prior: not determined by these slices."""
        return [n for n, p in self.parameters.items() if p.status == "prior"]

    def report(self) -> dict[str, Any]:
        """Plain JSON: each parameter's status, value and reason, the fit's figures."""
        return json_safe({
            "kind": self.fit.kind,
            "parameters": {n: p.to_dict() for n, p in self.parameters.items()},
            "prior": self.prior,
            "e_fit": self.fit.e_fit,
            "n_samples": len(self.fit.outlier),
            "n_outliers": self.fit.n_outliers,
            "free_fit": {"params": self.free_fit.params,
                         "uncertainty": self.free_fit.uncertainty,
                         "correlation": self.free_fit.correlation,
                         "e_fit": self.free_fit.e_fit},
        })


def prior_material(model: str, prior: str | Mapping[str, Any] | Material | None) -> Material:
    """The prior as a material of kind ``model``.

    ``prior`` is a preset name, a ``{kind, params}`` / ``{preset, params}`` mapping, a
    material, or None for the model's own defaults (for Cook–Torrance the relay-wall paper's
    base set).

    Raises
    ------
    InvalidInputError
        Unknown preset or model, or a prior of another kind than ``model``.
    """
    fit_model(model)  # the kind must be fittable
    if prior is None:
        mat = make_material(model)
    elif isinstance(prior, Material):
        mat = prior
    elif isinstance(prior, str):
        mat = material_preset(prior)
    else:
        data = dict(prior)
        if "preset" in data:
            base = material_preset(data["preset"])
            mat = make_material(base.name, **{**_numeric(base, fit_model(base.name).names),
                                              **dict(data.get("params", {}))})
        else:
            mat = make_material(str(data.get("kind")), **dict(data.get("params", {})))
    if mat.name != model:
        raise InvalidInputError("prior", f"is a {mat.name} material; the model fitted is "
                                f"{model}: give a prior of that kind")
    return mat


def fit_slices(table: GoniometerTable, model: str = DEFAULT_MODEL,
               prior: str | Mapping[str, Any] | Material | None = None, seed: int = 0,
               settings: FitSettings | None = None) -> SliceFit:
    """Fit ``model`` to the slices and sort its parameters (module docstring).

    Raises
    ------
    InvalidInputError
        From :func:`calibration.brdf.fit.fit_brdf` (too few distinct directions, ...), a bad
        prior, or slices that determine none of the model's parameters.
    """
    fm = fit_model(model)
    prior_params = _numeric(prior_material(model, prior), fm.names)
    settings = settings or FitSettings(
        determined_relative_uncertainty=DETERMINED_RELATIVE_UNCERTAINTY)
    free_fit = fit_brdf(table, model, seed=seed, settings=settings)
    fit, held = free_fit, {}
    while True:
        undetermined = [n for n in fm.names if n not in held and not fit.determined[n]]
        if not undetermined:
            break
        worst = max(undetermined, key=lambda n: _relative(fit, n))
        held[worst] = prior_params[worst]
        if len(held) == len(fm.names):
            raise InvalidInputError(
                "slices", f"the slices determine none of the {model} parameters "
                          f"({', '.join(fm.names)}): {_weakness(free_fit, fm.names)}")
        fit = fit_brdf(table, model, fixed=held, seed=seed, settings=settings)
    follows = _prior_dependence(table, model, fit, held, seed, settings)
    statuses = {}
    for n in fm.names:
        free_sigma = free_fit.uncertainty[n]
        if n in held:
            statuses[n] = ParameterStatus(
                n, "prior", prior_params[n], 0.0, free_sigma,
                f"not determined by these slices: {_why(free_fit, n)}; held at the prior "
                f"{prior_params[n]:.4g}")
        elif not follows.get(n):
            statuses[n] = ParameterStatus(
                n, "determined", fit.params[n], fit.uncertainty[n], free_sigma,
                f"determined: 1-sigma {_percent(fit, n)} of its value")
        else:
            statuses[n] = ParameterStatus(
                n, "conditional", fit.params[n], fit.uncertainty[n], free_sigma,
                f"not determined by these slices on its own ({_why(free_fit, n)}); fitted with "
                f"{', '.join(held)} held at the prior, and its value follows that prior: "
                f"{follows[n]} (1-sigma {_percent(fit, n)} given the prior)")
    return SliceFit(fit, free_fit, prior_params, statuses)


def _prior_dependence(table: GoniometerTable, model: str, fit: BrdfFit,
                      held: Mapping[str, float], seed: int, settings: FitSettings
                      ) -> dict[str, str]:
    """The fitted parameters that follow a held one's prior, each with how far it moved when
    that prior moved by :data:`PRIOR_SHIFT` (empty when nothing is held)."""
    out: dict[str, str] = {}
    for h, value in held.items():
        moved = None
        for factor in (1.0 + PRIOR_SHIFT, 1.0 - PRIOR_SHIFT):
            try:
                moved = fit_brdf(table, model, fixed={**held, h: value * factor}, seed=seed,
                                 settings=settings)
            except InvalidInputError:
                continue  # outside the bounds or the sum constraint: the other side
            break
        if moved is None:
            continue
        for n, p in fit.params.items():
            if n in held:
                continue
            shift = abs(moved.params[n] - p) / _scale(fit, n)
            if shift > DETERMINED_RELATIVE_UNCERTAINTY:
                note = (f"it moves by {100 * shift:.2g} % when the prior of {h} moves by "
                        f"{100 * PRIOR_SHIFT:g} %")
                out[n] = f"{out[n]}; {note}" if n in out else note
    return out


def _numeric(material: Material, names) -> dict[str, float]:
    return {n: float(getattr(material, n)) for n in names}


def _scale(fit: BrdfFit, name: str) -> float:
    return max(abs(fit.params[name]), fit_model(fit.kind).spec(name).resolution)


def _relative(fit: BrdfFit, name: str) -> float:
    s = fit.uncertainty[name]
    return math.inf if not math.isfinite(s) else s / _scale(fit, name)


def _percent(fit: BrdfFit, name: str) -> str:
    r = _relative(fit, name)
    return "infinite" if not math.isfinite(r) else f"{100 * r:.2g} %"


def _why(fit: BrdfFit, name: str) -> str:
    """The parameter's uncertainty with every parameter free, and what it trades against."""
    text = f"with every parameter free its 1-sigma uncertainty is {_percent(fit, name)}"
    row = {k: v for k, v in fit.correlation.get(name, {}).items()
           if k != name and math.isfinite(v)}
    if row:
        other = max(row, key=lambda k: abs(row[k]))
        if abs(row[other]) >= 0.9:
            text += f" and it trades against {other} (correlation {row[other]:+.3f})"
    elif not math.isfinite(fit.uncertainty[name]):
        text += " (a direction of parameter space the slices do not see)"
    return text


def _weakness(fit: BrdfFit, names) -> str:
    return "; ".join(f"{n}: {_percent(fit, n)}" for n in names)
