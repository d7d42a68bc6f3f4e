"""Extended inverse distance weighting of a goniometer table (peer paper, Section 4.2).

The AMCW ToF multipath paper (``amcw-tof-multipath-simulation-rsm``, Section 4.2) fills the
angles its goniometer could not reach (around retro-reflection, ``|β| <= 10°``, and beyond 80°
zenith) with a Shepard-type interpolation of the measured values ``f(ρ')``, eq. (16),

.. math::

    f(\\rho) = \\begin{cases} f(\\rho') & \\rho \\to \\rho' \\\\
               \\frac{1}{W} \\sum_{\\rho' \\in N(\\rho)} w(\\rho, \\rho') f(\\rho') & \\text{else}
               \\end{cases}, \\qquad W = \\sum_{\\rho' \\in N(\\rho)} w(\\rho, \\rho'),

with the weight of eq. (17) on the angular differences of both directions,

.. math::

    w(\\rho_1, \\rho_2) = \\big(\\arccos(l_1 \\cdot l_2) + \\arccos(d_1 \\cdot d_2)\\big)^{-u},
    \\qquad u = 5,

``l`` the direction to the light (``wi``) and ``d`` the direction to the detector (``wo``).

Conventions
-----------
Both configurations are compared in the goniometer's canonical frame
(:meth:`~sim_core.materials.goniometer.GoniometerTable.directions`): the light in the xz plane
(x >= 0), the detector on the side y >= 0. An isotropic material's configuration is defined by
``(θi, θr, Δφ)`` alone, so a query ``(wi, wo)`` is first rotated about the normal into that frame
(:func:`canonical_pairs`).

The neighbourhood ``N(ρ)``, which the paper leaves open, is the ``neighbours`` measured
configurations nearest to ``ρ`` by the Euclidean distance of the stacked unit vectors
``(l, d)`` in R^6 (a k-d tree; monotone in each of the two angles), weighted by eq. (17).

Numerics
--------
The angle ``arccos(a · b)`` of eq. (17) is computed as ``2 atan2(|a - b|, |a + b|)``: equal for
unit vectors, defined for every input (no clipping needed) and accurate near 0, where the
arccos of a rounded dot product is off by ~1e-8 rad. A distance below
``EXACT_DISTANCE_RAD`` is the case ``ρ -> ρ'`` of eq. (16) (the mean of the measurements there).
Weights are formed relative to the nearest neighbour, ``(δ_min / δ)^u`` in (0, 1], so that
neither ``δ^-u`` overflowing for tiny ``δ`` nor underflowing for large ``δ`` can give 0/0.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from sim_core.errors import InvalidInputError
from sim_core.materials.goniometer import GoniometerTable

__all__ = [
    "DEFAULT_NEIGHBOURS",
    "EXACT_DISTANCE_RAD",
    "IDW_EXPONENT",
    "angle_between",
    "canonical_pairs",
    "configuration_directions",
    "goniometer_measurement",
    "idw_interpolate",
    "pair_distance_rad",
]

#: the peer paper's exponent ``u`` of eq. (17), "determined experimentally"
IDW_EXPONENT = 5.0
#: size of the neighbourhood N(ρ) of eq. (16)
DEFAULT_NEIGHBOURS = 16
#: a configuration this close (eq. 17's distance, rad) to a measured one is that one
EXACT_DISTANCE_RAD = 1e-9


def _unit(w: np.ndarray, name: str) -> np.ndarray:
    w = np.asarray(w, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {w.shape}")
    norm = np.linalg.norm(w, axis=1, keepdims=True)
    # a zero vector has no direction: it stays 0 (and is far from every unit vector)
    return np.divide(w, norm, out=np.zeros_like(w), where=norm > 0.0)


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between unit vectors, rows of ``a`` and ``b`` (broadcast), in [0, π] [rad].

    ``2 atan2(|a - b|, |a + b|)``, which is ``arccos(a · b)`` for unit vectors.
    """
    return 2.0 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1))


def canonical_pairs(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(wi, wo)`` rotated about the normal into the goniometer's frame, unit length.

    ``wi`` goes into the xz plane with x >= 0, ``wo`` to y >= 0: the directions
    :meth:`GoniometerTable.directions` gives for the same ``(θi, θr, Δφ)``. Rotations about the
    normal and the mirror y -> -y do not change an isotropic BRDF. A zenith ``wi`` has no
    azimuth: ``wo`` then goes into the xz plane (``Δφ = 0``, the table's convention).
    """
    wi, wo = _unit(wi, "wi"), _unit(wo, "wo")
    if wi.shape != wo.shape:
        raise ValueError(f"wi and wo must have the same shape, got {wi.shape} and {wo.shape}")
    rho_i = np.hypot(wi[:, 0], wi[:, 1])
    zenith = rho_i == 0.0
    safe = np.where(zenith, 1.0, rho_i)
    c = np.where(zenith, 1.0, wi[:, 0] / safe)  # cos and sin of wi's azimuth
    s = np.where(zenith, 0.0, wi[:, 1] / safe)
    x = wo[:, 0] * c + wo[:, 1] * s  # wo rotated by -azimuth(wi)
    y = -wo[:, 0] * s + wo[:, 1] * c
    y = np.where(zenith, 0.0, y)
    x = np.where(zenith, np.hypot(wo[:, 0], wo[:, 1]), x)
    l_can = np.stack([rho_i, np.zeros_like(rho_i), wi[:, 2]], axis=1)
    d_can = np.stack([x, np.abs(y), wo[:, 2]], axis=1)
    return l_can, d_can


def configuration_directions(
    theta_i_deg: np.ndarray, theta_r_deg: np.ndarray, phi_deg: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Canonical ``(wi, wo)`` of configurations ``(θi, θr, Δφ)`` [deg], each (n, 3).

    The formula of :meth:`GoniometerTable.directions`, for any angles (a grid reaches 90°).
    """
    ti, tr, ph = (np.radians(np.asarray(a, dtype=np.float64).ravel())
                  for a in (theta_i_deg, theta_r_deg, phi_deg))
    wi = np.stack([np.sin(ti), np.zeros_like(ti), np.cos(ti)], axis=1)
    wo = np.stack([np.sin(tr) * np.cos(ph), np.sin(tr) * np.sin(ph), np.cos(tr)], axis=1)
    return wi, wo


def goniometer_measurement(material, step_deg: float, *, retro_gap_deg: float = 10.0,
                           max_zenith_deg: float = 80.0, source: str = "") -> GoniometerTable:
    """A material as a goniometer measures it: ``material.eval_local`` on a (θi, θr, Δφ) grid
    of ``step_deg`` up to ``max_zenith_deg``, without the configurations within
    ``retro_gap_deg`` of retro-reflection (where the detector would shade the light): the
    blind spots the interpolation (eqs. 16-17) has to fill."""
    z = np.arange(0.0, max_zenith_deg + 1e-9, step_deg)
    ti, tr, ph = np.meshgrid(z, z, np.arange(0.0, 180.0 + 1e-9, step_deg), indexing="ij")
    ti, tr, ph = ti.ravel(), tr.ravel(), ph.ravel()
    wi, wo = configuration_directions(ti, tr, ph)
    beta = np.degrees(np.arccos(np.clip(np.sum(wi * wo, axis=1), -1.0, 1.0)))
    keep = beta > retro_gap_deg
    f = material.eval_local(wi, wo)
    return GoniometerTable(ti[keep], tr[keep], ph[keep], f[keep], source=source)


def pair_distance_rad(
    l1: np.ndarray, d1: np.ndarray, l2: np.ndarray, d2: np.ndarray
) -> np.ndarray:
    """Eq. (17)'s distance ``arccos(l1·l2) + arccos(d1·d2)`` of canonical pairs [rad]."""
    return angle_between(l1, l2) + angle_between(d1, d2)


def idw_interpolate(
    table: GoniometerTable,
    wi: np.ndarray,
    wo: np.ndarray,
    u: float = IDW_EXPONENT,
    neighbours: int = DEFAULT_NEIGHBOURS,
) -> np.ndarray:
    """BRDF values [1/sr] at ``(wi, wo)`` interpolated from ``table``, eqs. (16)-(17).

    Parameters
    ----------
    table : GoniometerTable
        The measurements ``f(ρ')``.
    wi, wo : (n, 3) float
        Shading-frame directions to the light and to the viewer (any length; normalised, and
        rotated into the goniometer's frame, see :func:`canonical_pairs`). No horizon masking:
        the result is the interpolant wherever the directions are.
    u : float, default 5
        Exponent of eq. (17), > 0.
    neighbours : int, default 16
        Size of the neighbourhood ``N(ρ)`` (at most the table's rows are used).

    Returns
    -------
    (n,) float64
        The measured value (the mean of those measured there) where ``(wi, wo)`` is within
        ``EXACT_DISTANCE_RAD`` of a measured configuration, else the weighted mean of eq. (16):
        a convex combination of the neighbours' values, so within their extremes.

    Raises
    ------
    InvalidInputError
        For ``u`` not a positive finite number or ``neighbours`` not a positive integer.
    """
    if isinstance(u, bool) or not (isinstance(u, (int, float)) and math.isfinite(u) and u > 0):
        raise InvalidInputError("u", f"u = {u!r} must be a positive finite number (eq. 17)")
    if isinstance(neighbours, bool) or not isinstance(neighbours, (int, np.integer)) \
            or neighbours < 1:
        raise InvalidInputError(
            "neighbours", f"neighbours = {neighbours!r} must be a positive integer")
    l_q, d_q = canonical_pairs(wi, wo)
    n = l_q.shape[0]
    if n == 0:
        return np.zeros(0)
    l_m, d_m = table.directions()
    values = table.brdf_per_sr
    k = int(min(neighbours, len(table)))
    tree = cKDTree(np.hstack([l_m, d_m]))
    _, idx = tree.query(np.hstack([l_q, d_q]), k=k)
    idx = np.asarray(idx).reshape(n, k)
    dist = pair_distance_rad(l_q[:, None, :], d_q[:, None, :], l_m[idx], d_m[idx])  # (n, k)
    f = values[idx]
    exact = dist <= EXACT_DISTANCE_RAD
    has_exact = exact.any(axis=1)
    d_min = dist.min(axis=1, keepdims=True)
    # (δ_min / δ)^u in (0, 1]; the nearest neighbour has weight 1, so W >= 1 (no 0/0)
    ratio = np.divide(d_min, dist, out=np.ones_like(dist), where=dist > 0.0)
    w = ratio**u
    shepard = np.sum(w * f, axis=1) / np.sum(w, axis=1)
    n_exact = np.maximum(exact.sum(axis=1), 1)
    at_measured = np.sum(np.where(exact, f, 0.0), axis=1) / n_exact
    return np.where(has_exact, at_measured, shepard)
