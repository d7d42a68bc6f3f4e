"""Fit a material model to goniometer data: RANSAC, differential evolution, least squares.

The method follows the relay-wall paper (Section 3: RANSAC removes the "bad points", then a
genetic algorithm searches the model's characteristic parameters inside physical bounds), with
scipy's differential evolution as the global optimiser and a least-squares refinement after it:

1. **Determinability of the angle set.** The table must hold more distinct direction pairs
   ``(θi, θr, Δφ)`` than the model has free parameters; otherwise no fit can determine them
   and :func:`fit_brdf` raises.
2. **RANSAC** (:mod:`calibration.brdf.ransac`) on random minimal subsets with the relative-error
   threshold ``FitSettings.outlier_relative_error`` (25 %; ``outlier_sigmas`` = 5 standard
   deviations when the table gives ``brdf_std_per_sr``).
3. **Differential evolution** over RANSAC's inliers inside the bounds of
   :mod:`calibration.brdf.models` with the linear constraint ``kd + ks <= 1``, minimising the
   soft-L1 loss of the residuals (robust to an outlier RANSAC let through), started from a
   Latin hypercube population that includes RANSAC's hypothesis.
4. **Refinement** by ``scipy.optimize.least_squares`` (trf, plain squares) on the inliers;
   then every sample is flagged again against the threshold with the refined model and the
   refinement repeats on the new inliers until the flags stop changing (at most
   ``refine_rounds`` times).
5. **Uncertainties and determination** from the Jacobian at the optimum
   (:mod:`calibration.brdf.uncertainty`): every free parameter gets a 1-sigma uncertainty and
   a flag whether the data determined it; a model the data do not constrain at all raises.

Errors reported: ``e_fit`` of seed eq. (11) over the inliers (and over all samples), and each
sample's relative error ``(f_model - f_measured) / f_measured``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from scipy.optimize import LinearConstraint, differential_evolution

from calibration.brdf.models import FreeParameters, fit_model
from calibration.brdf.problem import FitProblem, distinct_configurations
from calibration.brdf.ransac import ransac
from calibration.brdf.uncertainty import estimate_uncertainty
from sim_core.errors import InvalidInputError
from sim_core.json_safe import json_safe
from sim_core.materials import Material
from sim_core.materials.goniometer import GoniometerTable

__all__ = ["BrdfFit", "FitSettings", "e_fit", "fit_brdf"]

#: DE objective of a parameter set the material rejects
_INFEASIBLE_COST = 1e12


def e_fit(measured_per_sr: np.ndarray, model_per_sr: np.ndarray,
          reflection_zenith_deg: np.ndarray) -> float:
    r"""Fitting error of seed eq. (11), a fraction (0.026 = the paper's "2.6 %").

    .. math::

        e_{fit} = \frac{\sum [f_{model}\cos\theta_r - f_{measured}\cos\theta_r]^2}
                       {\sum [f_{measured}\cos\theta_r]^2}

    >>> round(e_fit(np.array([1.0, 2.0]), np.array([1.1, 2.0]), np.array([0.0, 60.0])), 12)
    0.005
    """
    c = np.cos(np.radians(np.asarray(reflection_zenith_deg, dtype=np.float64)))
    meas = np.asarray(measured_per_sr, dtype=np.float64) * c
    model = np.asarray(model_per_sr, dtype=np.float64) * c
    den = float(np.sum(meas * meas))
    if den <= 0.0:
        return math.nan
    return float(np.sum((model - meas) ** 2) / den)


@dataclass(frozen=True)
class FitSettings:
    """Settings of :func:`fit_brdf` (the defaults are those the tests and the CLI use).

    Attributes
    ----------
    outlier_relative_error : float
        Largest ``|f_model - f_measured| / f_measured`` of an inlier, in (0, 10].
    outlier_sigmas : float
        Largest ``|f_model - f_measured| / std`` of an inlier when the table gives
        ``brdf_std_per_sr``, in (0, 100].
    ransac_min_trials, ransac_max_trials : int
        Trials of RANSAC (the number adapts to the inlier ratio in between), 1-10000.
    ransac_confidence : float
        In (0, 1).
    de_popsize : int
        Population of differential evolution per free parameter (scipy's ``popsize``), 2-100.
    de_maxiter : int
        Generations of differential evolution, 1-10000.
    de_tol : float
        Relative convergence tolerance of differential evolution, > 0.
    refine_rounds : int
        Re-flag-and-refine rounds after differential evolution, 1-20.
    determined_relative_uncertainty : float
        A parameter is determined when its 1-sigma uncertainty is at most this fraction of
        ``max(|value|, resolution)``, in (0, 10].
    """

    outlier_relative_error: float = 0.25
    outlier_sigmas: float = 5.0
    ransac_min_trials: int = 20
    ransac_max_trials: int = 200
    ransac_confidence: float = 0.999
    de_popsize: int = 10
    de_maxiter: int = 200
    de_tol: float = 1e-7
    refine_rounds: int = 4
    determined_relative_uncertainty: float = 0.1

    def __post_init__(self) -> None:
        for name, lo, hi, lo_open in (
            ("outlier_relative_error", 0.0, 10.0, True),
            ("outlier_sigmas", 0.0, 100.0, True),
            ("ransac_min_trials", 1, 10000, False),
            ("ransac_max_trials", 1, 10000, False),
            ("ransac_confidence", 0.0, 1.0, True),
            ("de_popsize", 2, 100, False),
            ("de_maxiter", 1, 10000, False),
            ("de_tol", 0.0, 1.0, True),
            ("refine_rounds", 1, 20, False),
            ("determined_relative_uncertainty", 0.0, 10.0, True),
        ):
            v = getattr(self, name)
            inside = (lo < v if lo_open else lo <= v) and v <= hi
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) \
                    or not inside or (name == "ransac_confidence" and v >= 1.0):
                bracket = "(" if lo_open else "["
                raise InvalidInputError(f"settings.{name}",
                                        f"{v!r} is outside {bracket}{lo:g}, {hi:g}]")
        if self.ransac_min_trials > self.ransac_max_trials:
            raise InvalidInputError("settings.ransac_min_trials",
                                    "must not exceed settings.ransac_max_trials")


@dataclass(frozen=True)
class BrdfFit:
    """The result of :func:`fit_brdf`.

    Attributes
    ----------
    kind : str
        The material kind fitted.
    params : dict
        Every numeric parameter of the model (fitted and pinned).
    uncertainty : dict
        1-sigma uncertainty of each parameter (``inf``: the data do not constrain it; 0 for
        pinned ones).
    determined : dict of bool
        Whether the data determined each parameter (pinned ones: False; see
        :mod:`calibration.brdf.uncertainty`).
    fixed : dict
        The pinned parameters.
    options : dict
        Non-numeric constructor arguments the fit used (e.g. ``fresnel_angle``).
    correlation : dict of dict
        Correlations between the free parameters (NaN where undetermined).
    e_fit : float
        Seed eq. (11) over the inliers, a fraction.
    e_fit_all : float
        Seed eq. (11) over all samples.
    relative_error : (n,) float64
        ``(f_model - f_measured) / f_measured`` per sample.
    outlier : (n,) bool
        Samples flagged as outliers.
    model_brdf_per_sr : (n,) float64
        The fitted model at each sample.
    table : GoniometerTable
    settings : FitSettings
    seed : int
    diagnostics : dict
        Trials, evaluations, rank, singular values, timings.
    """

    kind: str
    params: dict[str, float]
    uncertainty: dict[str, float]
    determined: dict[str, bool]
    fixed: dict[str, float]
    options: dict[str, Any]
    correlation: dict[str, dict[str, float]]
    e_fit: float
    e_fit_all: float
    relative_error: np.ndarray = field(repr=False)
    outlier: np.ndarray = field(repr=False)
    model_brdf_per_sr: np.ndarray = field(repr=False)
    table: GoniometerTable = field(repr=False)
    settings: FitSettings = field(repr=False)
    seed: int = 0
    diagnostics: dict[str, Any] = field(default_factory=dict, repr=False)

    def material_spec(self) -> dict[str, Any]:
        """The scene's ``MaterialSpec`` form: ``{"kind": ..., "params": {...}}``."""
        return {"kind": self.kind, "params": {**self.params, **self.options}}

    def material(self) -> Material:
        """The fitted material."""
        return fit_model(self.kind).build(self.params)

    @property
    def n_outliers(self) -> int:
        return int(np.sum(self.outlier))

    def report(self) -> dict[str, Any]:
        """The fit as strict-JSON-ready data (non-finite numbers as "inf"/"nan")."""
        t = self.table
        samples = [
            {"incidence_zenith_deg": float(a), "reflection_zenith_deg": float(b),
             "azimuth_difference_deg": float(c), "brdf_per_sr": float(y),
             "model_brdf_per_sr": float(f), "relative_error": float(r), "outlier": bool(o)}
            for a, b, c, y, f, r, o in zip(t.incidence_zenith_deg, t.reflection_zenith_deg,
                                           t.azimuth_difference_deg, t.brdf_per_sr,
                                           self.model_brdf_per_sr, self.relative_error,
                                           self.outlier, strict=True)
        ]
        return json_safe({
            "kind": self.kind,
            "params": self.params,
            "uncertainty": self.uncertainty,
            "determined": self.determined,
            "fixed": self.fixed,
            "options": self.options,
            "correlation": self.correlation,
            "e_fit": self.e_fit,
            "e_fit_all": self.e_fit_all,
            "n_samples": len(self.outlier),
            "n_outliers": self.n_outliers,
            "source": t.source,
            "wavelength_nm": t.wavelength_nm,
            "seed": self.seed,
            "settings": {f.name: getattr(self.settings, f.name) for f in fields(self.settings)},
            "diagnostics": self.diagnostics,
            "samples": samples,
        })


def fit_brdf(table: GoniometerTable, model: str, *, fixed: Mapping[str, float] | None = None,
             seed: int = 0, settings: FitSettings | None = None) -> BrdfFit:
    """Fit the material ``model`` to a goniometer table (method: the module docstring).

    Parameters
    ----------
    table : GoniometerTable
        Measured BRDF values (read from a CSV or built in memory).
    model : {"seed-microfacet", "cook-torrance", "lambertian", "hapke"}
    fixed : mapping, optional
        Parameters pinned at the given values (e.g. priors of parameters the data cannot
        determine).
    seed : int
        Seed of RANSAC's subsets and of differential evolution; the fit is deterministic.
    settings : FitSettings, optional

    Raises
    ------
    InvalidInputError
        ``model``: not a fittable kind; ``fixed``: unknown parameter or value out of range;
        ``angles``: the table holds too few distinct direction pairs for the free parameters
        (before or after removing the outliers), or the model does not depend on its free
        parameters at these angles; ``brdf_per_sr``: a zero measurement without
        ``brdf_std_per_sr``.
    """
    started = time.perf_counter()
    settings = settings or FitSettings()
    fm = fit_model(model)
    free = FreeParameters(fm, fixed)
    p = len(free)
    _check_configurations(table, None, p, fm.kind, "")
    problem = FitProblem(free, table)
    threshold = problem.threshold(settings.outlier_relative_error, settings.outlier_sigmas)
    rng = np.random.default_rng(seed)

    rs = ransac(problem, threshold, rng, min_trials=settings.ransac_min_trials,
                max_trials=settings.ransac_max_trials, confidence=settings.ransac_confidence)
    inlier = rs.inlier if rs.inlier.sum() > p else np.ones(problem.n, dtype=bool)
    t_ransac = time.perf_counter() - started

    de = _global_search(problem, np.flatnonzero(inlier), rs.x, threshold, settings, rng)
    x = de.x
    t_de = time.perf_counter() - started - t_ransac

    lsq_nfev, rounds = 0, 0
    for rounds in range(1, settings.refine_rounds + 1):  # noqa: B007 (reported)
        _check_configurations(table, inlier, p, fm.kind, " after removing the outliers")
        x, res = problem.refine(x, np.flatnonzero(inlier))
        lsq_nfev += int(res.nfev)
        r_all = problem.residuals(x)
        new = np.abs(r_all) <= threshold
        if np.array_equal(new, inlier):
            break
        inlier = new
    _check_configurations(table, inlier, p, fm.kind, " after removing the outliers")
    idx = np.flatnonzero(inlier)
    unc = estimate_uncertainty(problem, x, idx, settings.determined_relative_uncertainty)
    if unc.rank == 0:
        raise InvalidInputError(
            "angles", f"{table.source}: the {fm.kind} model does not depend on its free "
                      f"parameters ({', '.join(free.names)}) at these angles; no parameter can "
                      f"be determined")
    values = free.values(x)
    f_model = problem.predict(x)
    assert f_model is not None  # the optimum is feasible
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        rel = (f_model - problem.measured) / problem.measured
    sigma = dict(zip(free.names, (float(s) for s in unc.sigma), strict=True))
    det = dict(zip(free.names, (bool(d) for d in unc.determined), strict=True))
    corr = {a: {b: float(unc.correlation[i, j]) for j, b in enumerate(free.names)}
            for i, a in enumerate(free.names)}
    elapsed = time.perf_counter() - started
    return BrdfFit(
        kind=fm.kind,
        params=values,
        uncertainty={n: sigma.get(n, 0.0) for n in fm.names},
        determined={n: det.get(n, False) for n in fm.names},
        fixed=dict(free.fixed),
        options=dict(fm.options),
        correlation=corr,
        e_fit=e_fit(problem.measured[idx], f_model[idx], table.reflection_zenith_deg[idx]),
        e_fit_all=e_fit(problem.measured, f_model, table.reflection_zenith_deg),
        relative_error=rel,
        outlier=~inlier,
        model_brdf_per_sr=f_model,
        table=table,
        settings=settings,
        seed=seed,
        diagnostics={
            "residuals": "relative error" if problem.relative else "chi (brdf_std_per_sr)",
            "threshold": threshold,
            "ransac_trials": rs.trials,
            "ransac_inliers": int(rs.inlier.sum()),
            "de_generations": int(de.nit),
            "de_evaluations": int(de.nfev),
            "lsq_evaluations": lsq_nfev,
            "refine_rounds": rounds,
            "rank": unc.rank,
            "singular_values": unc.singular_values,
            "noise_scale": unc.noise_scale,
            "seconds": {"ransac": t_ransac, "differential_evolution": t_de, "total": elapsed},
        },
    )


def _global_search(problem: FitProblem, idx: np.ndarray, x0: np.ndarray, threshold: float,
                   settings: FitSettings, rng: np.random.Generator):
    """Differential evolution over the rows ``idx`` inside the bounds and the constraint."""
    free = problem.free

    def cost(x: np.ndarray) -> float:
        r = problem.residuals(free.clip(x), idx)
        if r is None:
            return _INFEASIBLE_COST
        z = r / threshold
        return float(np.sum(2.0 * (np.sqrt(1.0 + z * z) - 1.0)))  # soft-L1

    a = free.constraint_matrix()
    constraints = () if a is None else (LinearConstraint(a, -np.inf, 1.0),)
    return differential_evolution(
        cost, free.bounds(), constraints=constraints, popsize=settings.de_popsize,
        maxiter=settings.de_maxiter, tol=settings.de_tol, polish=False,
        seed=int(rng.integers(2**31)), x0=free.clip(x0), init="latinhypercube")


def _check_configurations(table: GoniometerTable, keep: np.ndarray | None, p: int, kind: str,
                          when: str) -> None:
    k = distinct_configurations(table, keep)
    if k <= p:
        raise InvalidInputError(
            "angles", f"{table.source}: {k} distinct direction pair(s) (θi, θr, Δφ){when} "
                      f"cannot determine the {p} free parameter(s) of {kind}; at least {p + 1} "
                      f"are needed (better many more, spread over incidence angles, reflection "
                      f"zeniths and azimuths, denser near the specular peak)")
