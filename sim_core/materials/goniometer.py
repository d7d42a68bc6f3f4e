"""Goniometer BRDF tables: the measured data materials are fitted to (or tabulated from).

A table is one row per measured direction pair, read from a CSV with the columns

``incidence_zenith_deg, reflection_zenith_deg, azimuth_difference_deg, brdf_per_sr``

and optionally ``wavelength_nm`` and ``brdf_std_per_sr`` (the measurement's standard deviation).
The incidence zenith ``θi`` is the angle between the surface normal and the direction to the
light, the reflection zenith ``θr`` that to the viewer; the azimuth difference ``Δφ`` is the angle
between the two directions' projections onto the surface, both pointing away from the surface:
180 deg is the plane of mirror reflection with the viewer opposite the light, 0 deg puts the
viewer on the light's side (retro-reflection at ``θi = θr``). Materials are isotropic, so
``Δφ`` and ``360 - Δφ`` are the same configuration; the table folds ``Δφ`` into [0, 180].

In the shading frame of :mod:`sim_core.materials.base` (normal +z) the light lies in the xz
plane: ``wi = (sin θi, 0, cos θi)`` and ``wo = (sin θr cos Δφ, sin θr sin Δφ, cos θr)``, so that
``Δφ = 180`` with ``θr = θi`` puts ``wo`` at the mirror direction of ``wi`` and ``Δφ = 0`` at
``wi`` itself (see :meth:`GoniometerTable.directions`).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim_core.errors import InvalidInputError

__all__ = [
    "OPTIONAL_COLUMNS",
    "REQUIRED_COLUMNS",
    "GoniometerTable",
    "angles_from_directions",
    "read_goniometer_csv",
]

#: columns every goniometer CSV has
REQUIRED_COLUMNS = (
    "incidence_zenith_deg",
    "reflection_zenith_deg",
    "azimuth_difference_deg",
    "brdf_per_sr",
)
#: columns a goniometer CSV may have
OPTIONAL_COLUMNS = ("wavelength_nm", "brdf_std_per_sr")

#: zenith angles must lie in [0, ZENITH_MAX_DEG): at 90 deg a direction grazes the surface
ZENITH_MAX_DEG = 90.0
#: two wavelengths closer than this are the same band [nm]
WAVELENGTH_TOLERANCE_NM = 0.5


@dataclass(frozen=True)
class GoniometerTable:
    """Measured BRDF values, one entry per direction pair.

    Attributes
    ----------
    incidence_zenith_deg, reflection_zenith_deg : (n,) float64
        ``θi`` (to the light) and ``θr`` (to the viewer), in [0, 90).
    azimuth_difference_deg : (n,) float64
        ``Δφ`` folded into [0, 180]; 180 = mirror plane, viewer opposite the light.
    brdf_per_sr : (n,) float64
        Measured BRDF [1/sr], >= 0.
    brdf_std_per_sr : (n,) float64 or None
        Standard deviation of each measurement [1/sr], > 0, when the file gives it.
    wavelength_nm : float or None
        The band the values belong to, when the file says.
    source : str
        Where the table came from (a path), for messages and reports.
    """

    incidence_zenith_deg: np.ndarray = field(repr=False)
    reflection_zenith_deg: np.ndarray = field(repr=False)
    azimuth_difference_deg: np.ndarray = field(repr=False)
    brdf_per_sr: np.ndarray = field(repr=False)
    brdf_std_per_sr: np.ndarray | None = field(default=None, repr=False)
    wavelength_nm: float | None = None
    source: str = "table"

    def __post_init__(self) -> None:
        arrays = {}
        for name in ("incidence_zenith_deg", "reflection_zenith_deg", "azimuth_difference_deg",
                     "brdf_per_sr", "brdf_std_per_sr"):
            value = getattr(self, name)
            if value is None:
                continue
            a = np.array(value, dtype=np.float64).reshape(-1)
            a.setflags(write=False)
            object.__setattr__(self, name, a)
            arrays[name] = a
        n = len(self.brdf_per_sr)
        if n == 0:
            raise InvalidInputError(self.source, "the table has no rows")
        for name, a in arrays.items():
            if len(a) != n:
                raise InvalidInputError(name, f"has {len(a)} values, brdf_per_sr has {n}")
        _check_range(self.incidence_zenith_deg, "incidence_zenith_deg", 0.0, ZENITH_MAX_DEG,
                     self.source, upper_open=True)
        _check_range(self.reflection_zenith_deg, "reflection_zenith_deg", 0.0, ZENITH_MAX_DEG,
                     self.source, upper_open=True)
        _check_range(self.azimuth_difference_deg, "azimuth_difference_deg", 0.0, 360.0,
                     self.source)
        _check_range(self.brdf_per_sr, "brdf_per_sr", 0.0, math.inf, self.source)
        if self.brdf_std_per_sr is not None:
            _check_range(self.brdf_std_per_sr, "brdf_std_per_sr", 0.0, math.inf, self.source,
                         lower_open=True)
        folded = np.where(self.azimuth_difference_deg > 180.0,
                          360.0 - self.azimuth_difference_deg, self.azimuth_difference_deg)
        folded.setflags(write=False)
        object.__setattr__(self, "azimuth_difference_deg", folded)

    def __len__(self) -> int:
        return len(self.brdf_per_sr)

    def directions(self) -> tuple[np.ndarray, np.ndarray]:
        """``(wi, wo)``, each ``(n, 3)`` unit vectors in the shading frame (normal +z).

        >>> t = GoniometerTable([30.0], [30.0], [180.0], [0.5])
        >>> wi, wo = t.directions()
        >>> np.round(wi, 3).tolist(), np.round(wo, 3).tolist()
        ([[0.5, 0.0, 0.866]], [[-0.5, 0.0, 0.866]])
        """
        ti = np.radians(self.incidence_zenith_deg)
        tr = np.radians(self.reflection_zenith_deg)
        phi = np.radians(self.azimuth_difference_deg)
        wi = np.stack([np.sin(ti), np.zeros_like(ti), np.cos(ti)], axis=1)
        wo = np.stack([np.sin(tr) * np.cos(phi), np.sin(tr) * np.sin(phi), np.cos(tr)], axis=1)
        return wi, wo

    def subset(self, keep: np.ndarray) -> GoniometerTable:
        """The rows where the boolean mask ``keep`` is true."""
        keep = np.asarray(keep, dtype=bool)
        std = None if self.brdf_std_per_sr is None else self.brdf_std_per_sr[keep]
        return GoniometerTable(self.incidence_zenith_deg[keep], self.reflection_zenith_deg[keep],
                               self.azimuth_difference_deg[keep], self.brdf_per_sr[keep], std,
                               self.wavelength_nm, self.source)


def angles_from_directions(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, ...]:
    """``(θi, θr, Δφ)`` in degrees of shading-frame directions: the inverse of ``directions``.

    ``Δφ`` is in [0, 180] (180 = mirror plane). Directions need not be unit length; a zenith
    direction has no azimuth and gets ``Δφ = 0``.
    """
    wi = np.asarray(wi, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64)
    ni = np.linalg.norm(wi, axis=1)
    no = np.linalg.norm(wo, axis=1)
    ti = np.degrees(np.arccos(np.clip(wi[:, 2] / np.maximum(ni, 1e-300), -1.0, 1.0)))
    tr = np.degrees(np.arccos(np.clip(wo[:, 2] / np.maximum(no, 1e-300), -1.0, 1.0)))
    # Δφ is the angle between the two projections (0 = same side as the light).
    dot = wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1]
    cross = wi[:, 0] * wo[:, 1] - wi[:, 1] * wo[:, 0]
    between = np.degrees(np.abs(np.arctan2(cross, dot)))  # in [0, 180]; atan2(0, 0) = 0
    return ti, tr, between


def _check_range(a: np.ndarray, name: str, lo: float, hi: float, source: str,
                 upper_open: bool = False, lower_open: bool = False) -> None:
    bad_finite = ~np.isfinite(a)
    too_low = a <= lo if lower_open else a < lo
    too_high = a >= hi if upper_open else a > hi
    bad = bad_finite | too_low | too_high
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        left = "(" if lower_open else "["
        right = ")" if upper_open else "]"
        allowed = f"{left}{lo:g}, {hi:g}{right}"
        raise InvalidInputError(
            name, f"{source}: row {i + 1} has {name} = {a[i]!r}; allowed: finite values in "
                  f"{allowed} ({int(bad.sum())} row(s) out of range)")


def read_goniometer_csv(path: str | Path, wavelength_nm: float | None = None) -> GoniometerTable:
    """Read a goniometer CSV (see the module docstring for the columns).

    Parameters
    ----------
    path : path
        The CSV file; a header row names the columns (any order, extra columns are ignored).
    wavelength_nm : float, optional
        Keep only the rows of this band. Required when the file's ``wavelength_nm`` column holds
        more than one band; without the column, the table's band is unknown (None).

    Raises
    ------
    InvalidInputError
        Naming the column (or ``wavelength_nm``) for a missing file or column, a value that is
        not a number, non-finite, negative or outside its range (with the row), or a band the
        file does not hold (listing those it does).
    """
    p = Path(path)
    if not p.is_file():
        raise InvalidInputError("path", f"goniometer file '{p}' does not exist")
    with p.open(newline="", encoding="utf-8-sig") as fh:
        reader = csv.DictReader(fh)
        header = [h.strip() for h in (reader.fieldnames or [])]
        missing = [c for c in REQUIRED_COLUMNS if c not in header]
        if missing:
            raise InvalidInputError(
                missing[0], f"{p}: missing column(s) {', '.join(missing)}; required: "
                            f"{', '.join(REQUIRED_COLUMNS)} (optional: "
                            f"{', '.join(OPTIONAL_COLUMNS)}); found: {', '.join(header) or 'none'}")
        columns = [c for c in (*REQUIRED_COLUMNS, *OPTIONAL_COLUMNS) if c in header]
        values: dict[str, list[float]] = {c: [] for c in columns}
        for row_no, row in enumerate(reader, start=2):  # row 1 is the header
            row = {(k or "").strip(): v for k, v in row.items()}
            for c in columns:
                text = (row.get(c) or "").strip()
                try:
                    values[c].append(float(text))
                except ValueError:
                    raise InvalidInputError(
                        c, f"{p}: line {row_no} has {c} = {text!r}, not a number") from None
    data = {c: np.asarray(v, dtype=np.float64) for c, v in values.items()}
    if len(data["brdf_per_sr"]) == 0:
        raise InvalidInputError("path", f"{p}: the table has no rows")
    band = None
    if "wavelength_nm" in data:
        wl = data["wavelength_nm"]
        _check_range(wl, "wavelength_nm", 0.0, math.inf, str(p), lower_open=True)
        bands = _bands(wl)
        if wavelength_nm is None:
            if len(bands) > 1:
                raise InvalidInputError(
                    "wavelength_nm", f"{p} holds {len(bands)} bands "
                                     f"({', '.join(f'{b:g}' for b in bands)} nm); choose one")
            wavelength_nm = bands[0]
        keep = np.abs(wl - wavelength_nm) <= WAVELENGTH_TOLERANCE_NM
        if not keep.any():
            raise InvalidInputError(
                "wavelength_nm", f"{p} has no rows at {wavelength_nm:g} nm; it holds "
                                 f"{', '.join(f'{b:g}' for b in bands)} nm")
        data = {c: v[keep] for c, v in data.items()}
        band = float(wavelength_nm)
    elif wavelength_nm is not None:
        band = float(wavelength_nm)  # the caller vouches for the file's band
    return GoniometerTable(
        incidence_zenith_deg=data["incidence_zenith_deg"],
        reflection_zenith_deg=data["reflection_zenith_deg"],
        azimuth_difference_deg=data["azimuth_difference_deg"],
        brdf_per_sr=data["brdf_per_sr"],
        brdf_std_per_sr=data.get("brdf_std_per_sr"),
        wavelength_nm=band,
        source=str(p),
    )


def _bands(wavelengths_nm: np.ndarray) -> list[float]:
    """The distinct bands of a wavelength column (values within the tolerance merged)."""
    bands: list[float] = []
    for w in np.unique(wavelengths_nm):
        if not bands or w - bands[-1] > WAVELENGTH_TOLERANCE_NM:
            bands.append(float(w))
    return bands
