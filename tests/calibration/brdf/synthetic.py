"""Synthetic goniometer measurements drawn as a goniometer would take them.

Four incidence angles (10, 30, 50, 70 deg) with 50 samples each: reflection zeniths 0-80 deg
in and out of the plane of mirror reflection, and half of them concentrated near the feature
the material shows (the specular peak for microfacet models, the opposition direction for
Hapke). Measurements carry multiplicative log-normal noise (``NOISE_RELATIVE`` = 5 %, a
goniometer's typical repeatability) and ``OUTLIER_FRACTION`` = 10 % gross outliers at random
rows: the true value times a factor log-uniform in [2, 5] or in [1/5, 1/2] (a shutter that
stuck, a stray reflection, a lost sync). Like a real instrument, the campaign records no value
below its detection limit (``DETECTION_LIMIT_PER_SR``, 5 decades below a bright specular peak):
such directions are replaced by further ones of the same plan, so that every incidence angle
keeps 50 recorded samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_core.materials import material_preset
from sim_core.materials.base import Material
from sim_core.materials.goniometer import GoniometerTable

INCIDENCE_DEG = (10.0, 30.0, 50.0, 70.0)
PER_INCIDENCE = 50
NOISE_RELATIVE = 0.05
OUTLIER_FRACTION = 0.10
OUTLIER_FACTOR = (2.0, 5.0)
DETECTION_LIMIT_PER_SR = 1e-4


@dataclass(frozen=True)
class Synthetic:
    table: GoniometerTable
    truth: np.ndarray  # true BRDF at each row [1/sr]
    outlier: np.ndarray  # rows given a gross error


def goniometer_angles(rng: np.random.Generator, near: str = "specular",
                      incidence_deg: tuple[float, ...] = INCIDENCE_DEG
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(θi, θr, Δφ)`` [deg] of one measurement campaign (50 rows per incidence angle)."""
    ti, tr, dphi = [], [], []
    for inc in incidence_deg:
        k = PER_INCIDENCE
        # 15 in the plane, 10 out of it, spread over the hemisphere
        r_in = rng.uniform(0.0, 80.0, 15)
        r_out = rng.uniform(0.0, 80.0, 10)
        # 25 near the feature: within a few degrees of the mirror (or opposition) direction
        r_near = np.clip(inc + rng.normal(0.0, 4.0, 25), 0.0, 85.0)
        az_near = np.abs(rng.normal(0.0, 6.0, 25))
        az_near = 180.0 - az_near if near == "specular" else az_near
        tr += [r_in, r_out, r_near]
        dphi += [np.full(15, 180.0), rng.uniform(0.0, 180.0, 10), az_near]
        ti.append(np.full(k, inc))
    return np.concatenate(ti), np.concatenate(tr), np.concatenate(dphi)


def measure(material: Material | str, seed: int, near: str = "specular",
            noise: float = NOISE_RELATIVE, outlier_fraction: float = OUTLIER_FRACTION,
            incidence_deg: tuple[float, ...] = INCIDENCE_DEG) -> Synthetic:
    """A noisy campaign of ``material`` (a Material or a preset name) at ``incidence_deg``."""
    if isinstance(material, str):
        material = material_preset(material)
    rng = np.random.default_rng(seed)
    rows: list[tuple[np.ndarray, ...]] = []
    for _ in range(20):  # plans until every incidence angle has its samples above the limit
        ti, tr, dphi = goniometer_angles(rng, near, incidence_deg)
        f = material.eval_local(*GoniometerTable(ti, tr, dphi, np.ones_like(ti)).directions())
        keep = f >= DETECTION_LIMIT_PER_SR
        rows.append((ti[keep], tr[keep], dphi[keep], f[keep]))
        ti, tr, dphi, truth = (np.concatenate(c) for c in zip(*rows, strict=True))
        if all(np.sum(ti == inc) >= PER_INCIDENCE for inc in incidence_deg):
            break
    pick = np.concatenate([np.flatnonzero(ti == inc)[:PER_INCIDENCE] for inc in incidence_deg])
    ti, tr, dphi, truth = ti[pick], tr[pick], dphi[pick], truth[pick]
    y = truth * np.exp(rng.normal(0.0, noise, len(truth)))
    n_out = round(outlier_fraction * len(y))
    bad = rng.choice(len(y), n_out, replace=False)
    factor = np.exp(rng.uniform(np.log(OUTLIER_FACTOR[0]), np.log(OUTLIER_FACTOR[1]), n_out))
    factor = np.where(rng.random(n_out) < 0.5, factor, 1.0 / factor)
    y[bad] *= factor
    outlier = np.zeros(len(y), dtype=bool)
    outlier[bad] = True
    return Synthetic(GoniometerTable(ti, tr, dphi, y, source=f"synthetic seed {seed}"), truth,
                     outlier)
