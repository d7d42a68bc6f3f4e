"""A BRDF fit's own evidence, and the verdict of each parameter it writes (issue 27).

:func:`calibration.brdf.fit.fit_brdf` reports each free parameter's linearised 1-sigma and
whether the data determined it (:mod:`calibration.brdf.uncertainty`). That uncertainty assumes
the residual is noise and that the rows are independent; neither holds when the model does not
explain a slice, or when the rows of one view share its errors (the rig's rows of one turntable
angle share the plate's pose and the reference's scale). :func:`fit_evidence` gathers what the
fit itself shows beyond it, and :func:`brdf_verdicts` turns it into a
:class:`calibration.verdicts.Verdicts` keyed as the material file writes the parameters
(``params.kd``, ``params.m``, ...; :mod:`calibration.brdf.material_file`):

- **Goodness of fit** over the inliers: the reduced chi-square ``sum(r^2) / (m - p)`` when the
  table gives ``brdf_std_per_sr`` (``r = (f_model - f) / std``). Without it the noise level is
  estimated from the residual itself (the covariance is already scaled by it, relay-wall paper
  eq. (13)'s least squares), so the overall chi-square is 1 by construction and only the slices'
  agreement with each other can be judged.
- **Per slice** (a group of rows: one incidence angle of a goniometer, one slice of one view on
  the rig): its reduced chi-square ``sum(r^2) / n`` (residuals over the estimated noise level
  when the table has no standard deviations). A slice is *unexplained* when it is above
  :data:`calibration.verdicts.CHI2_UNEXPLAINED` and its chi-square's tail probability is below
  :data:`P_UNEXPLAINED` (a slice of 5 rows exceeds 2 by chance 8 % of the time). The fit is then
  repeated without it (least squares from the optimum): a parameter it moves by more than its
  standard deviation is driven by data the model cannot explain and is ``unexplained``.
- **Rows left out**: RANSAC's outliers are rows the model is not asked to explain. A few are
  gross errors of the instrument (the synthetic campaigns have 10 %); when more than
  :data:`MAX_OUTLIER_FRACTION` of the rows are left out, the model explains only its consensus
  set and every fitted parameter is ``unexplained``; a slice most of whose rows are left out is
  named as dropped (:attr:`FitEvidence.dropped`).
- **Spread over resamples**: the least-squares fit repeated from the optimum on
  :data:`N_RESAMPLES` bootstrap resamples of the slices (whole groups drawn with replacement,
  so a view's shared error shows; single rows when there are fewer than
  :data:`MIN_GROUPS` groups). RANSAC's consensus set is kept: the outliers it flagged stay out.
- **Identifiability**: parameters the fit held (``fixed``, a prior) or did not determine (an
  infinite uncertainty along a valley of equal fits, or a cost profile that does not exclude
  +-``determined_relative_uncertainty``) are ``not determined`` with the reason.

A determined parameter's ``std`` is the larger of its honest linearised one
(:func:`calibration.verdicts.honest_std`: scaled by the square root of the reduced chi-square
when above 1) and its bootstrap spread, and it must be within ``determined_relative_uncertainty``
of the parameter's scale (``max(|value|, resolution)``) to stay ``determined``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.stats import chi2 as chi2_dist

from calibration.brdf.fit import BrdfFit
from calibration.brdf.models import FreeParameters, fit_model
from calibration.brdf.problem import FitProblem
from calibration.verdicts import CHI2_UNEXPLAINED, Verdict, Verdicts, honest_std, judge
from sim_core.errors import InvalidInputError
from sim_core.json_safe import json_safe

__all__ = [
    "MAX_OUTLIER_FRACTION",
    "MIN_GROUPS",
    "N_RESAMPLES",
    "PARAMS_PREFIX",
    "P_UNEXPLAINED",
    "FitEvidence",
    "SliceGoodness",
    "brdf_verdicts",
    "fit_evidence",
    "incidence_groups",
]

#: bootstrap resamples of the slices
N_RESAMPLES = 40
#: fewer groups than this are resampled row by row (three views resampled give three values)
MIN_GROUPS = 5
#: a slice above CHI2_UNEXPLAINED is unexplained when its chi-square is this improbable
P_UNEXPLAINED = 1e-3
#: share of the rows RANSAC may leave out before the fit is read as explaining only a part
MAX_OUTLIER_FRACTION = 1.0 / 3.0
#: the material file's key of a parameter is this prefix and its name
PARAMS_PREFIX = "params."


@dataclass(frozen=True)
class SliceGoodness:
    """One slice's goodness of fit: its inlier rows, reduced chi-square and its tail
    probability under the noise, and the parameters the fit moves beyond their standard
    deviation when the slice is left out (only for an unexplained slice)."""

    name: str
    n_rows: int
    reduced_chi2: float
    p_value: float
    drives: tuple[str, ...] = ()

    @property
    def unexplained(self) -> bool:
        """Above the limit and improbable under the noise; an infinite chi-square is, a NaN
        one (no noise level to judge against) is not judged."""
        return self.reduced_chi2 == math.inf or (
            self.reduced_chi2 > CHI2_UNEXPLAINED and self.p_value < P_UNEXPLAINED)

    def reason(self) -> str:
        return (f"slice {self.name}: reduced chi-square {self.reduced_chi2:.3g} over "
                f"{self.n_rows} rows (probability {self.p_value:.2g} under the noise), above "
                f"{CHI2_UNEXPLAINED:g}: the model does not explain it")


@dataclass(frozen=True)
class FitEvidence:
    """What a fit shows of itself (module docstring).

    Attributes
    ----------
    reduced_chi2 : float or None
        Over the inliers; None when the table has no ``brdf_std_per_sr`` (the noise level is
        estimated from the residual, so the overall chi-square is 1 by construction).
    slices : tuple of SliceGoodness
    bootstrap_std : dict of str to float
        Spread of each free parameter over the resamples (inf when resamples fail).
    n_resamples : int
        Resamples whose fit converged.
    resampled : str
        ``"slices"`` or ``"rows"``.
    """

    reduced_chi2: float | None
    slices: tuple[SliceGoodness, ...]
    bootstrap_std: dict[str, float]
    n_resamples: int
    resampled: str
    analytic_std: dict[str, float] = field(default_factory=dict)
    n_rows: int = 0
    n_outliers: int = 0
    dropped: dict[str, str] = field(default_factory=dict)

    @property
    def outlier_fraction(self) -> float:
        return self.n_outliers / self.n_rows if self.n_rows else 0.0

    def outliers_reason(self) -> str | None:
        """Why the fit explains only a part of its rows (None when it does not)."""
        if self.outlier_fraction <= MAX_OUTLIER_FRACTION:
            return None
        return (f"the robust fit left {self.n_outliers} of {self.n_rows} rows out as outliers "
                f"({100 * self.outlier_fraction:.0f} %, more than "
                f"{100 * MAX_OUTLIER_FRACTION:.0f} %): the model explains only a part of the "
                "data")

    @property
    def unexplained_slices(self) -> list[SliceGoodness]:
        return [s for s in self.slices if s.unexplained]

    def to_dict(self) -> dict[str, Any]:
        return json_safe({
            "reduced_chi2": self.reduced_chi2,
            "slices": {s.name: {"rows": s.n_rows, "reduced_chi2": s.reduced_chi2,
                                "p_value": s.p_value, "unexplained": s.unexplained,
                                "drives": list(s.drives)} for s in self.slices},
            "bootstrap_std": self.bootstrap_std, "n_resamples": self.n_resamples,
            "resampled": self.resampled, "analytic_std": self.analytic_std,
            "rows": self.n_rows, "outliers": self.n_outliers, "dropped": self.dropped})


def incidence_groups(fit: BrdfFit) -> list[str]:
    """A goniometer's slices: one per incidence zenith (to 0.1 deg)."""
    return [f"θi {v:.1f} deg" for v in np.round(fit.table.incidence_zenith_deg, 1)]


def _problem(fit: BrdfFit) -> tuple[FitProblem, np.ndarray]:
    free = FreeParameters(fit_model(fit.kind), fit.fixed)
    return FitProblem(free, fit.table), np.array([fit.params[n] for n in free.names])


def _noise_level(problem: FitProblem, r_in: np.ndarray, p: int) -> float:
    """The residual's noise level: 1 for chi residuals, else the RMS residual over the dof
    (NaN without degrees of freedom: nothing can be judged then)."""
    if not problem.relative:
        return 1.0
    dof = len(r_in) - p
    return math.sqrt(float(np.sum(r_in * r_in)) / dof) if dof > 0 else math.nan


def fit_evidence(fit: BrdfFit, groups: Sequence[str] | None = None, *,
                 n_resamples: int = N_RESAMPLES, seed: int = 0) -> FitEvidence:
    """The evidence of ``fit`` (module docstring).

    Parameters
    ----------
    fit : BrdfFit
    groups : sequence of str, optional
        Each row's slice (same length as the table); default :func:`incidence_groups`.
    n_resamples : int
        Bootstrap resamples, 0-1000 (0: no bootstrap, the linearised std alone; resamples
        that cannot be fitted leave the spread unknown: inf).
    seed : int

    Raises
    ------
    InvalidInputError
        ``groups``: not one per row; ``n_resamples``: outside 0-1000.
    """
    labels = list(incidence_groups(fit) if groups is None else groups)
    if len(labels) != len(fit.table):
        raise InvalidInputError("groups", f"{len(labels)} labels for {len(fit.table)} rows: one "
                                "slice name per row is needed")
    if isinstance(n_resamples, bool) or not 0 <= n_resamples <= 1000:
        raise InvalidInputError("n_resamples", f"{n_resamples!r} is outside 0-1000")
    problem, x = _problem(fit)
    names = problem.free.names
    p = len(names)
    inlier = ~np.asarray(fit.outlier, dtype=bool)
    idx = np.flatnonzero(inlier)
    r = problem.residuals(x)
    assert r is not None  # the fit's optimum is feasible
    noise = _noise_level(problem, r[idx], p)
    dof = len(idx) - p
    overall = None
    if not problem.relative:
        # no dof cannot happen (fit_brdf refuses fewer distinct inliers than p + 1); if it
        # did, nothing would be explained: inf, judged unexplained
        overall = float(np.sum(r[idx] ** 2) / dof) if dof > 0 else math.inf
    analytic = {n: honest_std(fit.uncertainty[n], overall if overall is not None else 1.0)
                for n in names}
    label_arr = np.asarray(labels, dtype=object)
    order = list(dict.fromkeys(labels))
    slices = []
    dropped = {}
    for name in order:
        rows = idx[label_arr[idx] == name]
        n_all = int(np.sum(label_arr == name))
        if 2 * len(rows) < n_all:
            dropped[name] = (f"{n_all - len(rows)} of its {n_all} rows left out as outliers "
                             "(beyond the robust fit's threshold)")
        if not len(rows):
            continue
        if math.isfinite(noise) and noise > 0:
            z = r[rows] / noise
            chi2_sum = float(np.sum(z * z))
            red = chi2_sum / len(rows)
            pval = float(chi2_dist.sf(chi2_sum, len(rows))) if math.isfinite(chi2_sum) else 0.0
        else:  # no noise level (a residual of exactly 0, no dof): nothing to judge against
            red, pval = math.nan, math.nan
        g = SliceGoodness(name, len(rows), red, pval)
        if g.unexplained:
            g = SliceGoodness(name, len(rows), red, pval,
                              _driven(problem, x, idx[label_arr[idx] != name], analytic))
        slices.append(g)
    boot, n_ok, how = _bootstrap(problem, x, idx, label_arr, n_resamples, seed)
    return FitEvidence(overall, tuple(slices), boot, n_ok, how, analytic, len(labels),
                       int(np.sum(~inlier)), dropped)


def _driven(problem: FitProblem, x: np.ndarray, keep: np.ndarray,
            std: Mapping[str, float]) -> tuple[str, ...]:
    """The parameters that move beyond their standard deviation when the fit is repeated on
    the rows ``keep`` (all of them when too few rows remain to fit)."""
    names = problem.free.names
    if len(keep) <= len(names):
        return tuple(names)
    x_new, _ = problem.refine(x, keep)
    return tuple(n for n, a, b in zip(names, x, x_new, strict=True)
                 # beyond an infinite std nothing moves; against an unknown (NaN) one it does
                 if not (abs(b - a) <= std[n]))


def _bootstrap(problem: FitProblem, x: np.ndarray, idx: np.ndarray, labels: np.ndarray,
               n_resamples: int, seed: int) -> tuple[dict[str, float], int, str]:
    """Spread of the least-squares optimum over resamples of the slices (or rows)."""
    names = problem.free.names
    groups = [idx[labels[idx] == g] for g in dict.fromkeys(labels[idx].tolist())]
    how = "slices"
    if len(groups) < MIN_GROUPS:
        groups, how = [np.array([i]) for i in idx], "rows"
    if n_resamples == 0:  # no bootstrap asked for: the linearised std alone
        return {n: 0.0 for n in names}, 0, how
    if len(groups) < 2:  # one slice resampled is itself: no spread to be had
        return {n: math.inf for n in names}, 0, how
    rng = np.random.default_rng([seed, 27])
    draws = []
    for _ in range(n_resamples):
        pick = rng.integers(len(groups), size=len(groups))
        rows = np.concatenate([groups[k] for k in pick])
        if len(np.unique(rows)) <= len(names):
            continue  # too few distinct rows to fit: this resample says nothing
        x_b, res = problem.refine(x, rows, max_nfev=50 * (len(names) + 1))
        if res.status >= 0:  # converged, or stopped at its budget (-1: improper input)
            draws.append(x_b)
    if len(draws) < 2:
        return {n: math.inf for n in names}, len(draws), how
    spread = np.std(np.array(draws), axis=0, ddof=1)
    return dict(zip(names, (float(s) for s in spread), strict=True)), len(draws), how


def _scale(fit: BrdfFit, name: str) -> float:
    return max(abs(fit.params[name]), fit_model(fit.kind).spec(name).resolution)


def brdf_verdicts(fit: BrdfFit, groups: Sequence[str] | None = None, *,
                  held_reasons: Mapping[str, str] | None = None,
                  evidence: FitEvidence | None = None, n_resamples: int = N_RESAMPLES,
                  seed: int = 0) -> Verdicts:
    """Every numeric parameter of ``fit``'s material file judged (module docstring), keyed
    ``params.NAME``.

    Parameters
    ----------
    fit : BrdfFit
    groups : sequence of str, optional
        Each row's slice (default: its incidence angle).
    held_reasons : mapping, optional
        Why a pinned parameter was pinned (default: "held at the given value").
    evidence : FitEvidence, optional
        Already gathered (:func:`fit_evidence`); gathered here otherwise.
    """
    ev = evidence if evidence is not None else fit_evidence(fit, groups, n_resamples=n_resamples,
                                                            seed=seed)
    held_reasons = held_reasons or {}
    limit_rel = fit.settings.determined_relative_uncertainty
    bad = ev.unexplained_slices
    out = Verdicts()
    for name in fit_model(fit.kind).names:
        key = PARAMS_PREFIX + name
        if name in fit.fixed:
            out.add(key, Verdict("not determined", None, held_reasons.get(
                name, f"held at the given value {fit.fixed[name]:.4g}, not fitted")))
            continue
        limit = limit_rel * _scale(fit, name)
        analytic = ev.analytic_std.get(name, math.inf)
        if not fit.determined[name]:
            shown = analytic if math.isfinite(analytic) else None
            why = (f"1-sigma {analytic:.3g} against the limit {limit:.3g} "
                   f"({100 * limit_rel:g} % of its value)" if math.isfinite(analytic) else
                   "a direction of parameter space these data do not see")
            out.add(key, Verdict("not determined", shown, "the data do not determine it: "
                                 f"{why}, or the cost's profile does not exclude moving it by "
                                 f"{100 * limit_rel:g} %; the file keeps the fitted value"))
            continue
        std = max(analytic, ev.bootstrap_std.get(name, math.inf))
        if ev.reduced_chi2 is not None and not ev.reduced_chi2 <= CHI2_UNEXPLAINED:
            # judge scales the statistical std by the chi-square itself: give it unscaled
            stat = max(fit.uncertainty[name], ev.bootstrap_std.get(name, math.inf))
            out.add(key, judge(stat, limit, reduced_chi2=ev.reduced_chi2,
                               where=f"all slices ({len(ev.slices)})"))
            continue
        partial = ev.outliers_reason()
        if partial:
            out.add(key, Verdict("unexplained", std, partial))
            continue
        drivers = [s for s in bad if name in s.drives]
        if drivers:
            out.add(key, Verdict("unexplained", std, "; ".join(s.reason() for s in drivers)
                                 + f"; leaving it out moves {name} beyond its standard "
                                   "deviation"))
            continue
        v = judge(std, limit)  # std is honest already: no second scaling by the chi-square
        if not v.determined:
            v = Verdict(v.verdict, v.std, f"{v.reason} (the larger of the linearised "
                        f"{analytic:.3g} and the spread {ev.bootstrap_std.get(name, math.inf):.3g}"
                        f" over {ev.n_resamples} resamples of the {ev.resampled})")
        out.add(key, v)
    return out
