"""A goniometer table resampled onto the grid the tabulated material's kernels read.

The grid is the product of node angles in incidence zenith ``θi``, reflection zenith ``θr``
(both [0°, 90°]) and azimuth difference ``Δφ`` ([0°, 180°]): on each axis the distinct angles
the goniometer measured, plus the ends 0° and 90° (zenith) or 0° and 180° (azimuth). Nodes
the goniometer measured keep the measured value (the mean where a configuration was measured
more than once); the others, the gaps of the scan (around retro-reflection, beyond 80°
zenith, the ends), are filled by the peer paper's extended inverse distance weighting, eqs.
(16)-(17) (:mod:`sim_core.materials.idw`). Between nodes the kernels interpolate trilinearly
in ``(θi, θr, Δφ)``, so at every measured angle the material reproduces the table.

This module also derives what the kernels need beyond the values: the directional albedo of
every ``θr`` row (the material's ``albedo_bound``) and the importance-sampling tables (per
``θr`` row a piecewise-constant distribution over the ``(θi, Δφ)`` cells proportional to the
cell's ``∫ f cos θi dω``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from sim_core.errors import InvalidInputError
from sim_core.materials.goniometer import GoniometerTable
from sim_core.materials.idw import (
    configuration_directions,
    idw_interpolate,
    pair_distance_rad,
)

__all__ = [
    "MAX_COVERAGE_GAP_DEG",
    "MAX_GRID_NODES",
    "NODE_TOLERANCE_DEG",
    "SamplingTables",
    "TabulatedGrid",
    "albedo_per_row",
    "check_coverage",
    "grid_nodes",
    "resample",
    "sampling_tables",
]

#: measured angles closer than this are one grid node [deg]
NODE_TOLERANCE_DEG = 1e-6
#: largest grid (n_i n_r n_φ nodes) the material builds: ~4 MB of values per material, and as
#: much again of sampling tables, in every row of the renderer's material table
MAX_GRID_NODES = 500_000
#: every configuration (θi, θr, Δφ) must have a measurement within this distance (eq. 17's
#: arccos(l1·l2) + arccos(d1·d2)) [deg]: farther, the interpolation is a guess
MAX_COVERAGE_GAP_DEG = 45.0
#: Gauss–Legendre points per θi cell of the albedo quadrature (the integrand, a linear
#: function times cos θ sin θ, is smooth on a cell: 8 points are exact to rounding)
_ALBEDO_ORDER = 8
#: the probe configurations of the coverage check [deg]
_PROBE_ZENITH_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 89.0)
_PROBE_AZIMUTH_DEG = (0.0, 45.0, 90.0, 135.0, 180.0)


@dataclass(frozen=True)
class TabulatedGrid:
    """BRDF values on the product grid of node angles.

    Attributes
    ----------
    theta_i_deg, theta_r_deg : (n_i,), (n_r,) float64
        Increasing zenith nodes in [0, 90], the first 0.
    phi_deg : (n_φ,) float64
        Increasing azimuth-difference nodes in [0, 180], the first 0 and the last 180.
    values_per_sr : (n_r, n_i, n_φ) float64
        BRDF at the nodes [1/sr], indexed ``[θr, θi, Δφ]``.
    measured : (n_r, n_i, n_φ) bool
        Whether a node holds a measurement (else it was filled by eqs. 16-17).
    """

    theta_i_deg: np.ndarray = field(repr=False)
    theta_r_deg: np.ndarray = field(repr=False)
    phi_deg: np.ndarray = field(repr=False)
    values_per_sr: np.ndarray = field(repr=False)
    measured: np.ndarray = field(repr=False)

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(n_r, n_i, n_φ)``."""
        return self.values_per_sr.shape  # type: ignore[return-value]

    def scaled(self, factor: float) -> TabulatedGrid:
        """The same grid with every value times ``factor``."""
        return TabulatedGrid(self.theta_i_deg, self.theta_r_deg, self.phi_deg,
                             self.values_per_sr * factor, self.measured)


@dataclass(frozen=True)
class SamplingTables:
    """The importance-sampling tables of a grid (see :func:`sampling_tables`).

    Attributes
    ----------
    marginal_cdf : (n_r, n_i) float64
        Per θr row, the CDF over the θi cells (0 first, exactly 1 last).
    conditional_cdf : (n_r, n_i - 1, n_φ) float64
        Per θr row and θi cell, the CDF over the Δφ cells.
    density_per_sr : (n_r, n_i - 1, n_φ - 1) float64
        The sampler's solid-angle density in each cell [1/sr]: the cell's probability over its
        solid angle on both sides of the plane of ``wo``.
    """

    marginal_cdf: np.ndarray = field(repr=False)
    conditional_cdf: np.ndarray = field(repr=False)
    density_per_sr: np.ndarray = field(repr=False)


def grid_nodes(angles_deg: np.ndarray, ends_deg: tuple[float, float]) -> np.ndarray:
    """The distinct angles of ``angles_deg`` and the two ends, increasing; angles closer than
    ``NODE_TOLERANCE_DEG`` merged into the smallest of them."""
    v = np.unique(np.concatenate([np.asarray(angles_deg, dtype=np.float64).ravel(),
                                  np.asarray(ends_deg, dtype=np.float64)]))
    keep = np.concatenate([[True], np.diff(v) > NODE_TOLERANCE_DEG])
    return v[keep]


def _node_index(nodes: np.ndarray, angles_deg: np.ndarray) -> np.ndarray:
    """Index of the node each angle was merged into (the last node at or below it, within the
    tolerance)."""
    return np.searchsorted(nodes, angles_deg + NODE_TOLERANCE_DEG, side="right") - 1


def check_coverage(table: GoniometerTable) -> float:
    """Refuse a table that leaves part of the (θi, θr, Δφ) space without a measurement nearby.

    Probes configurations over the whole space (zeniths 0° to 89°, azimuths 0° to 180°) and
    finds each one's nearest measurement by eq. (17)'s distance. Returns the largest such
    distance [deg].

    Raises
    ------
    InvalidInputError
        (field ``table``) if a probe is farther than ``MAX_COVERAGE_GAP_DEG`` from every
        measurement, naming the probe: too few rows, or all at one incidence angle, cannot
        stand for the hemisphere.
    """
    ti, tr, ph = np.meshgrid(_PROBE_ZENITH_DEG, _PROBE_ZENITH_DEG, _PROBE_AZIMUTH_DEG,
                             indexing="ij")
    l_p, d_p = configuration_directions(ti, tr, ph)
    l_m, d_m = table.directions()
    k = min(8, len(table))
    _, idx = cKDTree(np.hstack([l_m, d_m])).query(np.hstack([l_p, d_p]), k=k)
    idx = np.asarray(idx).reshape(len(l_p), k)
    gap = np.degrees(
        pair_distance_rad(l_p[:, None, :], d_p[:, None, :], l_m[idx], d_m[idx]).min(axis=1))
    worst = int(np.argmax(gap))
    if gap[worst] > MAX_COVERAGE_GAP_DEG:
        raise InvalidInputError(
            "table",
            f"{table.source}: {len(table)} row(s) do not cover the hemisphere: the configuration "
            f"(θi, θr, Δφ) = ({ti.ravel()[worst]:g}, {tr.ravel()[worst]:g}, "
            f"{ph.ravel()[worst]:g}) deg is {gap[worst]:.1f} deg (eq. 17's distance) from the "
            f"nearest measurement; at most {MAX_COVERAGE_GAP_DEG:g} deg allowed: measure more "
            f"incidence and reflection angles")
    return float(gap.max())


def resample(
    table: GoniometerTable, u: float, neighbours: int
) -> TabulatedGrid:
    """The table on its grid: measured nodes as measured, the others by eqs. (16)-(17).

    Raises
    ------
    InvalidInputError
        (field ``table``) for a grid of more than ``MAX_GRID_NODES`` nodes: the table's angles
        are not a lattice (e.g. a scan in the goniometer's own axes, converted); resample it
        onto (θi, θr, Δφ) steps first.
    """
    t_i = grid_nodes(table.incidence_zenith_deg, (0.0, 90.0))
    t_r = grid_nodes(table.reflection_zenith_deg, (0.0, 90.0))
    ph = grid_nodes(table.azimuth_difference_deg, (0.0, 180.0))
    n_nodes = t_i.size * t_r.size * ph.size
    if n_nodes > MAX_GRID_NODES:
        raise InvalidInputError(
            "table",
            f"{table.source}: {t_i.size} incidence x {t_r.size} reflection x {ph.size} azimuth "
            f"angles make {n_nodes} grid nodes, more than {MAX_GRID_NODES}: the measured angles "
            f"are not a lattice; resample the table onto steps of (θi, θr, Δφ) first")
    shape = (t_r.size, t_i.size, ph.size)
    r = _node_index(t_r, table.reflection_zenith_deg)
    i = _node_index(t_i, table.incidence_zenith_deg)
    p = _node_index(ph, table.azimuth_difference_deg)
    sums = np.zeros(shape)
    counts = np.zeros(shape)
    np.add.at(sums, (r, i, p), table.brdf_per_sr)
    np.add.at(counts, (r, i, p), 1.0)
    measured = counts > 0
    values = np.divide(sums, counts, out=np.zeros(shape), where=measured)
    rr, ii, pp = np.nonzero(~measured)
    if rr.size:
        wi, wo = configuration_directions(t_i[ii], t_r[rr], ph[pp])
        values[rr, ii, pp] = idw_interpolate(table, wi, wo, u=u, neighbours=neighbours)
    for a in (t_i, t_r, ph, values, measured):
        a.setflags(write=False)
    return TabulatedGrid(t_i, t_r, ph, values, measured)


def _cell_cos_integrals(grid: TabulatedGrid) -> tuple[np.ndarray, np.ndarray]:
    """Per (θi, Δφ) cell: ``∫ cos θi dω`` and the solid angle ``Ω``, both sides of the plane.

    ``μ = cos θi``: ``∫ cos dω = Δφ (μ_a² - μ_{a+1}²)``, ``Ω = 2 Δφ (μ_a - μ_{a+1})``.
    """
    mu = np.cos(np.radians(grid.theta_i_deg))
    dphi = np.diff(np.radians(grid.phi_deg))
    cos_int = (mu[:-1] ** 2 - mu[1:] ** 2)[:, None] * dphi[None, :]
    solid = 2.0 * (mu[:-1] - mu[1:])[:, None] * dphi[None, :]
    return cos_int, solid


def albedo_per_row(grid: TabulatedGrid) -> np.ndarray:
    """Directional albedo ``a(θr) = ∫ f cos θi dωi`` at every θr node, (n_r,).

    Of the interpolant the kernels evaluate (trilinear in θi, θr, Δφ), integrated exactly in
    Δφ (linear) and by Gauss–Legendre in θi. Between θr nodes ``f`` is a convex combination of
    two rows, so the albedo is too: the largest row albedo bounds every ``wo``.
    """
    t = np.radians(grid.theta_i_deg)
    dphi = np.diff(np.radians(grid.phi_deg))
    x, wx = np.polynomial.legendre.leggauss(_ALBEDO_ORDER)
    s = 0.5 * (x + 1.0)  # fraction across a θi cell
    h = np.diff(t)
    theta = t[:-1, None] + h[:, None] * s[None, :]  # (n_i - 1, order)
    kern = np.cos(theta) * np.sin(theta) * (0.5 * wx)[None, :] * h[:, None]
    i0 = np.sum(kern * (1.0 - s)[None, :], axis=1)  # ∫ (1 - s) cos sin dθ per cell
    i1 = np.sum(kern * s[None, :], axis=1)  # ∫ s cos sin dθ
    v = grid.values_per_sr
    g = 0.5 * (v[:, :, :-1] + v[:, :, 1:]) * dphi[None, None, :]  # ∫ f dΔφ per Δφ cell
    per_cell = i0[None, :, None] * g[:, :-1, :] + i1[None, :, None] * g[:, 1:, :]
    return 2.0 * per_cell.sum(axis=(1, 2))  # both sides of the plane of wo


def _cdf(weights: np.ndarray) -> np.ndarray:
    """CDFs along the last axis of non-negative weights with a positive sum: 0 first, 1 last."""
    c = np.cumsum(weights, axis=-1)
    c = c / c[..., -1:]
    c[..., -1] = 1.0
    return np.concatenate([np.zeros((*c.shape[:-1], 1)), c], axis=-1)


def sampling_tables(grid: TabulatedGrid) -> SamplingTables:
    """Per θr row, a piecewise-constant density over the (θi, Δφ) cells.

    A cell's probability is proportional to ``f̄ ∫ cos θi dω``, ``f̄`` the mean of its four
    corner values in that row (so cells where the interpolant is zero get none); within a cell
    the density is uniform in solid angle (uniform in ``cos θi`` and ``Δφ``). A row whose
    values are all zero falls back to ``∫ cos θi dω`` alone. The density is computed from the
    stored CDFs, so that it is exactly the probability the sampler gives each cell.
    """
    v = grid.values_per_sr
    cos_int, solid = _cell_cos_integrals(grid)
    f_bar = 0.25 * (v[:, :-1, :-1] + v[:, 1:, :-1] + v[:, :-1, 1:] + v[:, 1:, 1:])
    w = f_bar * cos_int[None]
    empty = w.sum(axis=(1, 2)) <= 0.0
    w[empty] = cos_int[None]
    marginal = _cdf(w.sum(axis=2))
    row_w = w.sum(axis=2, keepdims=True)
    # a θi cell of zero probability is never chosen; it still gets a valid (uniform) CDF
    cond_w = np.where(row_w > 0.0, w, 1.0)
    conditional = _cdf(cond_w)
    p_cell = np.diff(marginal, axis=1)[:, :, None] * np.diff(conditional, axis=2)
    density = p_cell / solid[None]  # solid > 0: nodes strictly increase
    return SamplingTables(marginal, conditional, density)
