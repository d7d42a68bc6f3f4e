"""RANSAC outlier rejection for BRDF fits (relay-wall paper, Section 3; Fischler & Bolles 1981).

Each trial fits the model to a random *minimal* subset (as many distinct direction pairs as
free parameters): the subset's best of a fixed set of quasi-random starting points inside the
bounds, refined by least squares. The trial's consensus set is every sample whose residual is
within the threshold (a relative error, :mod:`calibration.brdf.problem`); trials are scored by
the truncated squared residual (MSAC, Torr & Zisserman 2000), which prefers the hypothesis
that fits its inliers best among those with equally many. A new best hypothesis is locally
optimised (LO-RANSAC, Chum et al. 2003): refitted to its consensus set with a soft-L1 loss and
re-scored, twice. Minimal subsets of a narrow specular lobe rarely pin it down; the local
optimisation is what turns a hypothesis that explains the diffuse part and a few peak samples
into one that explains the whole lobe.

The number of trials adapts to the best inlier ratio found (confidence ``confidence`` that one
trial drew only inliers), between ``min_trials`` and ``max_trials``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import qmc

from calibration.brdf.problem import FitProblem

__all__ = ["RansacResult", "ransac"]

#: quasi-random starting points per trial (the best on the subset is refined)
N_STARTS = 16
#: local-optimisation rounds after a new best hypothesis
LO_ROUNDS = 2


@dataclass(frozen=True)
class RansacResult:
    """The best hypothesis: its parameters (native vector), consensus set and the trials run."""

    x: np.ndarray
    inlier: np.ndarray
    trials: int


def _starts(problem: FitProblem, rng: np.random.Generator) -> np.ndarray:
    """Quasi-random native starting points inside the bounds and the constraint."""
    free = problem.free
    lo, hi = free.internal_bounds()
    u = qmc.scale(qmc.Sobol(len(free), scramble=True, seed=rng).random(N_STARTS), lo, hi)
    return np.array([free.clip(free.from_internal(ui)) for ui in u])


def _score(r: np.ndarray | None, threshold: float) -> tuple[float, np.ndarray]:
    if r is None:
        return math.inf, np.zeros(0, dtype=bool)
    inlier = np.abs(r) <= threshold
    return float(np.sum(np.minimum(r * r, threshold * threshold))), inlier


def ransac(problem: FitProblem, threshold: float, rng: np.random.Generator, *,
           min_trials: int, max_trials: int, confidence: float) -> RansacResult:
    """Run RANSAC; see the module docstring.

    Parameters
    ----------
    problem : FitProblem
    threshold : float
        Largest residual of an inlier (a relative error, or a number of standard deviations).
    rng : numpy Generator
    min_trials, max_trials : int
    confidence : float
        Probability, in (0, 1), that at least one trial drew an outlier-free subset.
    """
    n, p = problem.n, len(problem.free)
    starts = _starts(problem, rng)
    keys = np.round(np.stack([problem.table.incidence_zenith_deg,
                              problem.table.reflection_zenith_deg,
                              problem.table.azimuth_difference_deg], axis=1) * 100).astype(int)
    best_cost, best_x, best_inlier = math.inf, starts[0], np.zeros(n, dtype=bool)
    needed, trials = max_trials, 0
    while trials < max(min_trials, min(needed, max_trials)):
        trials += 1
        idx = _minimal_subset(keys, p, rng)
        costs = [np.sum(r * r) if (r := problem.residuals(x0, idx)) is not None else math.inf
                 for x0 in starts]
        x, _ = problem.refine(starts[int(np.argmin(costs))], idx, max_nfev=50 * (p + 1))
        cost, inlier = _score(problem.residuals(x), threshold)
        if cost >= best_cost:
            continue
        for _ in range(LO_ROUNDS):  # local optimisation on the consensus set
            if inlier.sum() <= p:
                break
            x_lo, _ = problem.refine(x, np.flatnonzero(inlier), loss="soft_l1",
                                     f_scale=threshold, max_nfev=100 * (p + 1))
            cost_lo, inlier_lo = _score(problem.residuals(x_lo), threshold)
            if cost_lo >= cost:
                break
            x, cost, inlier = x_lo, cost_lo, inlier_lo
        best_cost, best_x, best_inlier = cost, x, inlier
        ratio = inlier.mean()
        if ratio >= 1.0:
            needed = 0
        elif ratio > 0.0:
            needed = math.ceil(math.log(1.0 - confidence) / math.log(1.0 - ratio ** p))
    return RansacResult(x=best_x, inlier=best_inlier, trials=trials)


def _minimal_subset(keys: np.ndarray, p: int, rng: np.random.Generator) -> np.ndarray:
    """``p`` rows with distinct direction pairs (fewer only if the table has fewer)."""
    order = rng.permutation(len(keys))
    chosen: list[int] = []
    seen: set[tuple[int, ...]] = set()
    for i in order:
        k = tuple(keys[i])
        if k not in seen:
            seen.add(k)
            chosen.append(int(i))
            if len(chosen) == p:
                break
    return np.array(chosen)
