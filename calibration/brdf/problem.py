"""The data and the residuals of one BRDF fit, and the local least-squares step every stage uses.

Residuals
---------
Without a measurement uncertainty the residual of sample ``i`` is its logarithmic relative
error ``r_i = ln(f_model,i / f_measured,i)`` (``≈ (f_model - f_measured) / f_measured`` for small
errors): goniometer noise is multiplicative (a fraction of the signal, from the detector's gain
and the reference panel), for which this is the maximum-likelihood residual; unlike the plain
relative error it stays finite and symmetric for values spanning many decades (the tail of a
narrow specular lobe), and the outlier threshold, a relative error ``t``, becomes
``|r| <= ln(1 + t)`` (the measured value within a factor ``1 + t`` of the model). Model values
are floored at ``MODEL_FLOOR_PER_SR`` so that the logarithm stays finite. With a
``brdf_std_per_sr`` column the residual is ``(f_model - f_measured) / std`` (chi).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from calibration.brdf.models import FreeParameters
from sim_core.errors import InvalidInputError
from sim_core.materials.goniometer import GoniometerTable

__all__ = ["INFEASIBLE_RESIDUAL", "MODEL_FLOOR_PER_SR", "FitProblem", "distinct_configurations"]

#: residual given to every sample by a parameter set the material rejects (the least-squares
#: step needs finite values; the trust region then shrinks back into the feasible set)
INFEASIBLE_RESIDUAL = 1e3
#: smallest model value in a logarithmic residual [1/sr] (underflow of a far lobe tail)
MODEL_FLOOR_PER_SR = 1e-300
#: angles closer than this are one configuration when counting distinct direction pairs [deg]
CONFIGURATION_TOLERANCE_DEG = 0.01


def distinct_configurations(table: GoniometerTable, keep: np.ndarray | None = None) -> int:
    """Number of distinct ``(θi, θr, Δφ)`` among the rows (``keep``: a boolean mask)."""
    angles = np.stack([table.incidence_zenith_deg, table.reflection_zenith_deg,
                       table.azimuth_difference_deg], axis=1)
    if keep is not None:
        angles = angles[np.asarray(keep, dtype=bool)]
    keys = np.round(angles / CONFIGURATION_TOLERANCE_DEG).astype(np.int64)
    return len(np.unique(keys, axis=0))


class FitProblem:
    """A goniometer table and the free parameters of a model: residuals and local fits.

    Raises
    ------
    InvalidInputError
        ``brdf_per_sr``: a measured value is 0 and the table gives no ``brdf_std_per_sr``
        (a relative error needs a positive measurement).
    """

    def __init__(self, free: FreeParameters, table: GoniometerTable) -> None:
        self.free = free
        self.table = table
        self.wi, self.wo = table.directions()
        self.measured = np.asarray(table.brdf_per_sr, dtype=np.float64)
        self.relative = table.brdf_std_per_sr is None
        if self.relative:
            zero = np.flatnonzero(self.measured <= 0.0)
            if len(zero):
                raise InvalidInputError(
                    "brdf_per_sr", f"{table.source}: row {zero[0] + 1} has brdf_per_sr = 0; the "
                                   f"fit works in relative errors and needs values > 0 (or give "
                                   f"brdf_std_per_sr); {len(zero)} row(s) are 0")
            self.scale = self.measured
        else:
            self.scale = np.asarray(table.brdf_std_per_sr, dtype=np.float64)
        self.n = len(self.measured)

    def predict(self, x: np.ndarray, idx: np.ndarray | None = None) -> np.ndarray | None:
        """Model BRDF [1/sr] at the rows ``idx`` (all by default); None if the material
        rejects the parameters."""
        wi, wo = (self.wi, self.wo) if idx is None else (self.wi[idx], self.wo[idx])
        try:
            return self.free.build(x).eval_local(wi, wo)
        except InvalidInputError:
            return None

    def residuals(self, x: np.ndarray, idx: np.ndarray | None = None) -> np.ndarray | None:
        """Residuals (module docstring) at the rows ``idx``; None if infeasible."""
        f = self.predict(x, idx)
        if f is None:
            return None
        sl = slice(None) if idx is None else idx
        if self.relative:
            return np.log(np.maximum(f, MODEL_FLOOR_PER_SR) / self.measured[sl])
        return (f - self.measured[sl]) / self.scale[sl]

    def threshold(self, relative_error: float, sigmas: float) -> float:
        """The inlier threshold on :meth:`residuals`: ``ln(1 + relative_error)`` for
        logarithmic residuals, ``sigmas`` for chi."""
        return float(np.log1p(relative_error)) if self.relative else float(sigmas)

    def refine(self, x0: np.ndarray, idx: np.ndarray, *, loss: str = "linear",
               f_scale: float = 1.0, max_nfev: int | None = None) -> tuple[np.ndarray,
                                                                            OptimizeResult]:
        """Least-squares fit of the rows ``idx`` from ``x0`` (scipy ``least_squares``, trf),
        inside the bounds and the sum constraint (internal coordinates, module
        :mod:`calibration.brdf.models`). Returns the native optimum and scipy's result."""
        free = self.free
        m = len(idx)

        def fun(u: np.ndarray) -> np.ndarray:
            r = self.residuals(free.clip(free.from_internal(u)), idx)
            return np.full(m, INFEASIBLE_RESIDUAL) if r is None else r

        lo, hi = free.internal_bounds()
        u0 = np.clip(free.to_internal(free.clip(x0)), lo, hi)
        res = least_squares(fun, u0, bounds=(lo, hi), method="trf", loss=loss, f_scale=f_scale,
                            x_scale="jac", max_nfev=max_nfev)
        return free.clip(free.from_internal(res.x)), res
