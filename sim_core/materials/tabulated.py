"""The measured (tabulated) material: a goniometer table used as the BRDF itself.

The peer paper's way (``amcw-tof-multipath-simulation-rsm``, Section 4): no analytic model is
fitted; the simulator reads the measured BRDF, interpolated by the extended inverse distance
weighting of its eqs. (16)-(17) where the goniometer could not measure. A lab can thus use data
no analytic model fits.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from sim_core.errors import InvalidInputError
from sim_core.materials.base import Material
from sim_core.materials.goniometer import GoniometerTable, read_goniometer_csv
from sim_core.materials.idw import DEFAULT_NEIGHBOURS, IDW_EXPONENT
from sim_core.materials.kernels import KIND_TABULATED, tabulated_params
from sim_core.materials.microfacet import check_parameter
from sim_core.materials.tabulated_grid import (
    TabulatedGrid,
    albedo_per_row,
    check_coverage,
    resample,
    sampling_tables,
)

__all__ = ["ALBEDO_TOLERANCE", "DEFAULT_COSINE_PROBABILITY", "Tabulated"]

_MODEL = "tabulated"

#: measured data whose directional albedo exceeds 1 by at most this are accepted (measurement
#: noise) and scaled down to albedo 1; beyond, they are refused
ALBEDO_TOLERANCE = 0.02
#: relative rounding of the albedo quadrature: an albedo of 1 computed as 1 + 2e-16 is 1
_ALBEDO_ROUNDING = 1e-9
#: probability of cosine-hemisphere sampling in the sampling mixture
DEFAULT_COSINE_PROBABILITY = 0.1


@dataclass(frozen=True, eq=False)
class Tabulated(Material):
    """A measured BRDF: the goniometer table, resampled onto a grid and interpolated.

    Parameters
    ----------
    table : GoniometerTable or path
        The measurements, or a goniometer CSV (:func:`~sim_core.materials.goniometer.
        read_goniometer_csv`; a relative path is relative to the working directory, scene files
        resolve it against their own folder).
    wavelength_nm : float, optional
        The band to read from a CSV that holds several.
    u : float, default 5
        Exponent of the inverse distance weighting, eq. (17), > 0 (the paper's 5).
    neighbours : int, default 16
        Size of the IDW neighbourhood ``N(ρ)`` of eq. (16), >= 1.
    cosine_probability : float, default 0.1
        Share of cosine-hemisphere sampling in the sampling mixture, in [0.01, 1].

    Model
    -----
    The table is resampled onto the product grid of its own measured angles in ``θi``, ``θr``
    and ``Δφ`` plus the ends (0° and 90° zenith, 0° and 180° azimuth); nodes it did not measure
    are filled by eqs. (16)-(17) (:mod:`~sim_core.materials.tabulated_grid`). The BRDF is the
    trilinear interpolation of the nodes in ``(θi, θr, Δφ)``: exactly the measured value at
    every measured configuration. Zero at and below the horizon. Not made reciprocal: the data
    say what they say.

    Sampling
    --------
    With probability ``cosine_probability`` the cosine hemisphere, otherwise the table: in the
    θr row nearest to ``wo``, a (θi, Δφ) cell with probability proportional to its
    ``f̄ ∫ cos θi dω`` and a direction uniform in solid angle within it, on either side of the
    plane of ``wo``. ``pdf`` is that exact mixture, positive wherever ``f`` is.

    Energy
    ------
    ``albedo_bound`` is the largest directional albedo of the interpolant over the θr rows
    (exact: between rows the albedo interpolates linearly). A table whose albedo exceeds 1 by
    more than ``ALBEDO_TOLERANCE`` is refused; up to that, all values are scaled by
    ``1 / albedo`` (``albedo_scale``).

    Raises
    ------
    InvalidInputError
        For a parameter out of range, an unreadable CSV, a table that does not cover the
        hemisphere (:func:`~sim_core.materials.tabulated_grid.check_coverage`), one whose
        angles are not a lattice, or one reflecting more than it receives.

    Kernel
    ------
    ``kernels.tabulated_eval``, ``tabulated_pdf``, ``tabulated_sample_direction``; parameters
    ``kernels.tabulated_params`` (a header and the grid, its values and sampling tables).
    """

    table: GoniometerTable | str | Path
    wavelength_nm: float | None = None
    u: float = IDW_EXPONENT
    neighbours: int = DEFAULT_NEIGHBOURS
    cosine_probability: float = DEFAULT_COSINE_PROBABILITY

    name: ClassVar[str] = _MODEL
    kernel_kind: ClassVar[int] = KIND_TABULATED

    def __post_init__(self) -> None:
        table = self.table
        if isinstance(table, (str, Path)):
            try:
                table = read_goniometer_csv(table, self.wavelength_nm)
            except InvalidInputError as exc:  # named as the material's parameter
                field = "table" if exc.field == "path" else f"table.{exc.field}"
                raise InvalidInputError(field, exc.message) from None
        elif not isinstance(table, GoniometerTable):
            raise InvalidInputError(
                "table", f"table = {table!r} is neither a goniometer table nor a CSV path "
                         f"({_MODEL})")
        object.__setattr__(self, "table", table)
        u = check_parameter("u", self.u, 1e-3, 100.0, model=_MODEL)
        object.__setattr__(self, "u", u)
        k = self.neighbours
        if isinstance(k, bool) or not isinstance(k, numbers.Real) or k != int(k) or k < 1:
            raise InvalidInputError(
                "neighbours", f"neighbours = {k!r} is not a positive integer ({_MODEL})")
        object.__setattr__(self, "neighbours", int(k))
        p_cos = check_parameter("cosine_probability", self.cosine_probability, 0.01, 1.0,
                                model=_MODEL)
        object.__setattr__(self, "cosine_probability", p_cos)

        check_coverage(table)
        grid = resample(table, u, int(k))
        albedo = albedo_per_row(grid)
        worst = int(np.argmax(albedo))
        a_max = float(albedo[worst])
        if a_max > 1.0 + ALBEDO_TOLERANCE:
            raise InvalidInputError(
                "table",
                f"{table.source}: the directional albedo reaches {a_max:.4f} at θr = "
                f"{grid.theta_r_deg[worst]:g} deg, above 1 + {ALBEDO_TOLERANCE:g}: the table "
                f"reflects more than it receives (check its normalisation) ({_MODEL})")
        scale = 1.0 / a_max if a_max > 1.0 + _ALBEDO_ROUNDING else 1.0
        if scale != 1.0:
            grid = grid.scaled(scale)
            albedo = albedo * scale
        object.__setattr__(self, "_grid", grid)
        object.__setattr__(self, "_albedo_scale", scale)
        # the interpolant's albedo is exact up to rounding of the quadrature
        object.__setattr__(self, "_albedo_bound",
                           min(1.0, float(albedo.max()) * (1 + _ALBEDO_ROUNDING)))
        tabs = sampling_tables(grid)
        params = tabulated_params(
            np.radians(grid.theta_i_deg), np.radians(grid.theta_r_deg), np.radians(grid.phi_deg),
            grid.values_per_sr, tabs.marginal_cdf, tabs.conditional_cdf, tabs.density_per_sr,
            p_cos)
        params.setflags(write=False)
        object.__setattr__(self, "_params", params)

    @property
    def grid(self) -> TabulatedGrid:
        """The resampled table the kernels interpolate."""
        return self._grid  # type: ignore[attr-defined]

    @property
    def albedo_scale(self) -> float:
        """Factor applied to the table's values (1 unless its albedo slightly exceeded 1)."""
        return self._albedo_scale  # type: ignore[attr-defined]

    @property
    def albedo_bound(self) -> float:
        return self._albedo_bound  # type: ignore[attr-defined]

    def kernel_params(self) -> np.ndarray:
        return self._params  # type: ignore[attr-defined]
