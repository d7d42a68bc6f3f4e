"""Parameter uncertainties of a BRDF fit and whether the data determined each parameter.

At the optimum the residuals are linearised, ``r(x + dx) ≈ r(x) + J dx``, with ``J`` the
Jacobian with respect to the native free parameters (central differences; one-sided where a
bound or the sum constraint is in the way). The covariance is ``s² (JᵀJ)⁻¹`` with
``s² = Σ r² / (m - p)`` when the residuals are relative errors (the noise level is estimated
from the fit), and ``(JᵀJ)⁻¹`` when they are in units of the table's ``brdf_std_per_sr``.

The inverse is taken through the singular value decomposition of ``J`` with its columns scaled
by each parameter's scale (``max(|x|, resolution)``). Directions of parameter space whose
singular value is below ``RANK_RTOL`` times the largest do not change the residuals at all:
every parameter with a component along one gets an infinite uncertainty.

Determination
-------------
A parameter is *determined* when the data exclude moving it by ``relative_tolerance`` (10 %)
of its scale, judged twice:

- linearly: its 1-sigma uncertainty is at most ``relative_tolerance`` times its scale;
- by the profile of the cost (the nonlinear check the linearisation cannot replace, because
  valleys of equally good fits are curved and often end at a bound): the parameter is pinned
  at ``x ± relative_tolerance * scale``, the others are refitted by least squares, and the
  cost must rise by more than one noise variance (``Δ Σr² / s² > 1``, i.e. the shifted value is
  excluded at one sigma) on each side that lies inside the bounds.

A parameter the data leave free along a valley of equally good fits (the Fresnel exponent when
``F0`` is near 1, or ``ks`` and ``F0`` of which only the product shows) fails the profile check
and is reported as not determined, whatever its linearised uncertainty says.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.brdf.models import FreeParameters
from calibration.brdf.problem import FitProblem
from sim_core.errors import InvalidInputError

__all__ = ["RANK_RTOL", "Uncertainty", "estimate_uncertainty", "jacobian"]

#: singular values below this fraction of the largest count as zero
RANK_RTOL = 1e-9
#: relative finite-difference step (of the parameter's scale)
STEP_RTOL = 1e-6
#: a component of a null direction larger than this makes a parameter's uncertainty infinite
NULL_COMPONENT = 1e-6
#: rise of the cost, in noise variances, that excludes a shifted parameter value (1 sigma)
PROFILE_DELTA_CHI2 = 1.0


@dataclass(frozen=True)
class Uncertainty:
    """1-sigma uncertainties, correlations and determination of the free parameters.

    Attributes
    ----------
    sigma : (p,) float64
        1-sigma uncertainty of each free parameter (inf along directions the data do not see).
    correlation : (p, p) float64
        Correlation matrix (NaN where a variance is infinite).
    determined : (p,) bool
    singular_values : (p,) float64
        Of the column-scaled Jacobian, descending.
    rank : int
        Number of singular values above ``RANK_RTOL`` times the largest.
    noise_scale : float
        ``s`` (see the module docstring); NaN without degrees of freedom.
    """

    sigma: np.ndarray
    correlation: np.ndarray
    determined: np.ndarray
    singular_values: np.ndarray
    rank: int
    noise_scale: float


def _scales(problem: FitProblem, x: np.ndarray) -> np.ndarray:
    res = np.array([problem.free.model.spec(n).resolution for n in problem.free.names])
    return np.maximum(np.abs(x), res)


def jacobian(problem: FitProblem, x: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``∂r/∂x`` (m x p) at the native optimum ``x`` over the rows ``idx``."""
    free = problem.free
    r0 = problem.residuals(x, idx)
    if r0 is None:
        raise ValueError("the optimum is infeasible")
    steps = STEP_RTOL * _scales(problem, x)
    lo, hi = np.array(free.bounds()).T
    a = free.constraint_matrix()
    cols = []
    for j, h in enumerate(steps):
        e = np.zeros_like(x)
        e[j] = h

        def ok(y: np.ndarray) -> bool:
            inside = bool(np.all(y >= lo) and np.all(y <= hi))
            return inside and (a is None or float((a @ y)[0]) <= 1.0 + 1e-12)

        up, down = x + e, x - e
        r_up = problem.residuals(up, idx) if ok(up) else None
        r_down = problem.residuals(down, idx) if ok(down) else None
        if r_up is not None and r_down is not None:
            cols.append((r_up - r_down) / (2 * h))
        elif r_up is not None:
            cols.append((r_up - r0) / h)
        elif r_down is not None:
            cols.append((r0 - r_down) / h)
        else:
            cols.append(np.zeros_like(r0))
    return np.stack(cols, axis=1)


def estimate_uncertainty(problem: FitProblem, x: np.ndarray, idx: np.ndarray,
                         relative_tolerance: float) -> Uncertainty:
    """Uncertainties and determination at the optimum ``x`` from the rows ``idx``."""
    p = len(x)
    r = problem.residuals(x, idx)
    jac = jacobian(problem, x, idx)
    scale = _scales(problem, x)
    js = jac * scale[None, :]
    _, s, vt = np.linalg.svd(js, full_matrices=False)
    s_full = np.zeros(p)
    s_full[: len(s)] = s
    v = np.zeros((p, p))
    v[: len(s)] = vt
    if len(s) < p:  # fewer rows than parameters: complete the basis of the null space
        _, _, vt_all = np.linalg.svd(np.vstack([js, np.zeros((p - len(s), p))]))
        v = vt_all
    largest = s_full[0] if p else 0.0
    keep = s_full > RANK_RTOL * largest if largest > 0 else np.zeros(p, dtype=bool)
    rank = int(keep.sum())
    dof = len(idx) - p
    if problem.relative:
        noise = math.sqrt(float(np.sum(r * r)) / dof) if dof > 0 else math.nan
    else:
        noise = 1.0
    # covariance of the scaled parameters: V diag(1/s²) Vᵀ over the kept directions
    inv = np.where(keep, 1.0 / np.where(keep, s_full, 1.0) ** 2, 0.0)
    cov_s = (v.T * inv[None, :]) @ v
    null = np.any(np.abs(v[~keep]) > NULL_COMPONENT, axis=0) if (~keep).any() else \
        np.zeros(p, dtype=bool)
    var = np.diag(cov_s) * noise ** 2
    sigma = np.where(null, math.inf, np.sqrt(np.maximum(var, 0.0)) * scale)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.sqrt(np.diag(cov_s))
        corr = cov_s / np.outer(d, d)
    corr[null, :] = np.nan
    corr[:, null] = np.nan
    determined = np.isfinite(sigma) & (sigma <= relative_tolerance * scale)
    if np.isfinite(noise) and noise > 0:
        for j in np.flatnonzero(determined):
            determined[j] = _profile_excludes(problem, x, idx, j,
                                              relative_tolerance * scale[j], noise)
    else:  # no redundancy: nothing is known to be determined
        determined[:] = False
    return Uncertainty(sigma=sigma, correlation=corr, determined=determined,
                       singular_values=s_full, rank=rank, noise_scale=noise)


def _profile_excludes(problem: FitProblem, x: np.ndarray, idx: np.ndarray, j: int, shift: float,
                      noise: float) -> bool:
    """Whether pinning parameter ``j`` at ``x_j ± shift`` and refitting the others raises the
    cost by more than ``PROFILE_DELTA_CHI2`` noise variances on every side inside the bounds."""
    free = problem.free
    r0 = problem.residuals(x, idx)
    assert r0 is not None
    cost0 = float(np.sum(r0 * r0))
    name = free.names[j]
    lo, hi = free.bounds()[j]
    others = [k for k in range(len(x)) if k != j]
    for value in (x[j] - shift, x[j] + shift):
        if value < lo or value > hi:
            continue  # excluded by physics
        if not others:
            r = problem.residuals(np.array([value]), idx)
        else:
            try:
                pinned = FreeParameters(free.model, {**free.fixed, name: value})
            except InvalidInputError:
                continue  # the pinned value violates the sum constraint: excluded by physics
            sub = FitProblem(pinned, problem.table)
            x0 = pinned.clip(np.array([x[k] for k in others]))
            x_sub, _ = sub.refine(x0, idx, max_nfev=100 * len(others))
            r = sub.residuals(x_sub, idx)
        if r is None:
            continue
        if (float(np.sum(r * r)) - cost0) / noise ** 2 <= PROFILE_DELTA_CHI2:
            return False
    return True
