"""The two BRDF slices from the sweep: measured over reference, per angle bin (issue 14, §2).

**Retro-reflection slice.** The camera's source sits at the camera, so each pixel of the plate
sees it at (nearly) the same direction as it sees the camera: ``θi ≈ θr`` and ``Δφ ≈ 0``, the
angle being the plate's tilt to the pixel's ray. The pixel's BRDF is its measured amplitude over
the twin's reference amplitude times ``rho / pi`` (:mod:`calibration.rig_material.reference`).

**Solar slice.** The solar simulator lights the plate from its fixed direction; the intensity
with it minus without it is its light alone, as long as SBI has not started: over the
reference's linear response it gives ``f_r`` as for the retro slice. Pixels whose measured
intensity comes within :data:`SBI_MARGIN` of the intensity at which SBI holds them carry no
(or a compressed) response and are left out: at a set level of 0.8 sun and the CamBoard's 500 us
exposure that is every pixel of a bright plate facing the solar simulator.

Each pixel's directions are exact (the twin's geometry; the source's offset from the camera
included) and converted to ``(θi, θr, Δφ)`` with :func:`sim_core.materials.goniometer.
angles_from_directions`. Pixels are grouped in bins of the view direction's projection on the
plate (``bin_deg`` wide): one table row per bin, with the mean BRDF, the pixels' mean angles and
the standard error from the frames' noise.

**Flat, uniform plate.** Within a bin the pixels should agree to within their noise once a
quadratic trend is removed; the spread over the noise is reported (:attr:`SliceCheck.
spread_over_noise`), and so is the measured range's offset from the twin's plate. Either beyond
its limit means the sample is not flat or not uniform, or not where the twin puts it, and the
result says so (:attr:`SliceCheck.warnings`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calibration.rig_material.reference import ReferenceView
from calibration.rig_material.sweep import SampleCaptures
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.errors import InvalidInputError
from sim_core.materials.goniometer import GoniometerTable, angles_from_directions

#: relative error of the twin's reference (the calibrated power and solar scale, the plate's
#: pose): the floor of every row's uncertainty in the table the fit sees, however many pixels
#: and frames the row averages
MODEL_ERROR_REL = 0.01
#: largest zenith angle (to the light or the camera) a pixel may have [deg]
MAX_ZENITH_DEG = 80.0
#: spread of a bin's pixels about their trend, over their noise, beyond which the plate is not
#: flat and uniform (1 for a perfect plate)
MAX_SPREAD_OVER_NOISE = 2.0
#: largest median offset of the measured range from the twin's plate [m]
MAX_RANGE_OFFSET_M = 0.005
#: a pixel's measured intensity with the solar simulator must stay below this share of the
#: intensity at which SBI holds it (SBI depends a little on the pixel's modulated light too)
SBI_MARGIN = 0.9
#: the reference's solar response (at the set level) must exceed the measurement's noise by this
MIN_SOLAR_SNR = 5.0


@dataclass(frozen=True)
class SliceRows:
    """Rows of one slice: the directions and BRDF of each bin.

    Attributes
    ----------
    slice_name : str
        ``"retro"`` or ``"solar"``.
    turntable_angle_deg : (n,) float64
        Reported angle of each row's view.
    incidence_zenith_deg, reflection_zenith_deg, azimuth_difference_deg : (n,) float64
    brdf_per_sr, brdf_std_per_sr : (n,) float64
    n_pixels : (n,) int
    """

    slice_name: str
    turntable_angle_deg: np.ndarray
    incidence_zenith_deg: np.ndarray
    reflection_zenith_deg: np.ndarray
    azimuth_difference_deg: np.ndarray
    brdf_per_sr: np.ndarray
    brdf_std_per_sr: np.ndarray
    n_pixels: np.ndarray

    def __len__(self) -> int:
        return len(self.brdf_per_sr)


@dataclass(frozen=True)
class SliceCheck:
    """How well the plate fits the flat, uniform assumption.

    Attributes
    ----------
    spread_over_noise : dict of str to float
        Per slice, the median over bins of the pixels' RMS deviation from the bin's quadratic
        trend over their noise (1 for a flat uniform plate; NaN without bins).
    range_offset_m : float
        Median over the views of the measured range minus the twin's on the plate [m].
    range_rms_m : float
        RMS of the measured minus the twin's range about that offset [m] (noise and shape).
    warnings : list of str
    """

    spread_over_noise: dict[str, float]
    range_offset_m: float
    range_rms_m: float
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"spread_over_noise": dict(self.spread_over_noise),
                "range_offset_m": self.range_offset_m, "range_rms_m": self.range_rms_m,
                "warnings": list(self.warnings)}


@dataclass(frozen=True)
class Slices:
    """The slices of a sweep, as rows and as one goniometer table, and their check."""

    retro: SliceRows
    solar: SliceRows | None
    check: SliceCheck

    @property
    def parts(self) -> list[SliceRows]:
        """The slices that have rows, retro first."""
        return [self.retro] + ([self.solar] if self.solar is not None and len(self.solar)
                               else [])

    def table(self, source: str = "rig slices", wavelength_nm: float | None = None,
              model_error_rel: float = MODEL_ERROR_REL) -> GoniometerTable:
        """Both slices as one :class:`GoniometerTable` (retro rows first).

        Each row's ``brdf_std_per_sr`` is its standard error from the frames combined with
        ``model_error_rel`` of its value (the twin's own error, :data:`MODEL_ERROR_REL`).
        """
        cat = {k: np.concatenate([getattr(p, k) for p in self.parts])
               for k in ("incidence_zenith_deg", "reflection_zenith_deg",
                         "azimuth_difference_deg", "brdf_per_sr", "brdf_std_per_sr")}
        cat["brdf_std_per_sr"] = np.hypot(cat["brdf_std_per_sr"],
                                          model_error_rel * np.abs(cat["brdf_per_sr"]))
        return GoniometerTable(**cat, wavelength_nm=wavelength_nm, source=source)

    def write_csv(self, path) -> None:
        """The rows as CSV: the goniometer table's columns plus ``slice``,
        ``turntable_angle_deg`` and ``n_pixels`` (``brdf_std_per_sr`` from the frames alone);
        :func:`sim_core.materials.goniometer.read_goniometer_csv` reads it back."""
        import csv
        import io

        from sim_core.files import atomic_write

        cols = ("incidence_zenith_deg", "reflection_zenith_deg", "azimuth_difference_deg",
                "brdf_per_sr", "brdf_std_per_sr", "turntable_angle_deg", "n_pixels")
        fh = io.StringIO(newline="")
        w = csv.writer(fh)
        w.writerow(("slice", *cols))
        for part in self.parts:
            for i in range(len(part)):
                w.writerow((part.slice_name, *(f"{getattr(part, c)[i]:.8g}" for c in cols)))
        atomic_write(path, fh.getvalue())


def extract_slices(captures: list[SampleCaptures], references: list[ReferenceView],
                   bin_deg: float, min_pixels_per_bin: int) -> Slices:
    """The retro and solar slices of a sweep (module docstring).

    Parameters
    ----------
    captures : list of SampleCaptures
        The sweep's captures, one per angle.
    references : list of ReferenceView
        The twin's reference at the same angles, in the same order.
    bin_deg : float
        Width of the bins [deg].
    min_pixels_per_bin : int
        Bins with fewer usable pixels are dropped.

    Raises
    ------
    InvalidInputError
        Mismatched inputs; no usable plate pixels in any view (the sample not in view, not lit,
        saturated); no retro-reflection rows at all.
    """
    if len(captures) != len(references) or not captures:
        raise InvalidInputError("captures", f"{len(captures)} captures and {len(references)} "
                                "references: one reference per captured angle is needed")
    retro, solar, spreads = [], [], {"retro": [], "solar": []}
    offsets, rms = [], []
    for cap, ref in zip(captures, references, strict=True):
        if cap.lamp.amplitude.shape != ref.amplitude_dn.shape:
            raise InvalidInputError("captures", f"image shape {cap.lamp.amplitude.shape} at "
                                    f"{cap.turntable_angle_deg:+g} deg differs from the "
                                    f"twin's {ref.amplitude_dn.shape}")
        rows, spread = _retro_view(cap, ref, bin_deg, min_pixels_per_bin)
        retro.append(rows)
        spreads["retro"] += spread
        if cap.solar is not None and ref.solar_slope_dn is not None:
            rows, spread = _solar_view(cap, ref, bin_deg, min_pixels_per_bin)
            solar.append(rows)
            spreads["solar"] += spread
        off = _range_offsets(cap, ref)
        if off.size:
            offsets.append(float(np.median(off)))
            rms.append(float(np.sqrt(np.mean((off - np.median(off)) ** 2))))
    n_plate = sum(int(r.geometry.mask.sum()) for r in references)
    if n_plate == 0:
        raise InvalidInputError("sample", "no pixel of the sample plate lies clear of its "
                                "outline in any view: is the plate in view and large enough "
                                "(size_m), and the edge margin small enough?")
    retro_rows = _stack("retro", retro)
    if len(retro_rows) == 0:
        raise InvalidInputError(
            "angles_deg", "no usable retro-reflection rows: at none of the angles does the "
                          "camera see the lit plate with a valid, unsaturated amplitude (are "
                          "the angles within +-80 deg of facing the camera?)")
    solar_rows = _stack("solar", solar) if solar else None
    spread = {k: float(np.median(v)) if v else float("nan") for k, v in spreads.items()
              if k == "retro" or solar_rows is not None}
    offset = float(np.median(offsets)) if offsets else float("nan")
    range_rms = float(np.sqrt(np.mean(np.square(rms)))) if rms else float("nan")
    warnings = [f"{k} slice: the plate's pixels scatter {v:.1f} times their noise about the "
                f"trend within a bin (limit {MAX_SPREAD_OVER_NOISE:g}): the sample is not flat "
                "and uniform, or the twin's geometry is off"
                for k, v in spread.items() if np.isfinite(v) and v > MAX_SPREAD_OVER_NOISE]
    if np.isfinite(offset) and abs(offset) > MAX_RANGE_OFFSET_M:
        warnings.append(f"the measured range on the plate is {offset * 1e3:+.1f} mm off the "
                        f"twin's plate (limit {MAX_RANGE_OFFSET_M * 1e3:g} mm): the sample does "
                        "not sit in its fixture's plane (thickness, mount), so the slices' "
                        "angles and distances are off")
    return Slices(retro_rows, solar_rows, SliceCheck(spread, offset, range_rms, warnings))


def _retro_view(cap: SampleCaptures, ref: ReferenceView, bin_deg: float, min_pixels: int):
    g = ref.geometry
    amp_ref = ref.amplitude_dn[g.mask]
    amp = cap.lamp.amplitude[g.mask]
    sem = cap.amplitude_sem_dn[g.mask]
    ok = (cap.lamp.valid[g.mask] & np.isfinite(amp) & np.isfinite(sem) & (amp_ref > 0.0)
          & (sem > 0.0) & _in_range(g.to_source) & _in_range(g.to_camera))
    scale = ref.albedo / np.pi
    f = np.where(ok, amp / np.where(ok, amp_ref, 1.0) * scale, np.nan)
    s = np.where(ok, sem / np.where(ok, amp_ref, 1.0) * scale, np.nan)
    # Retro-reflection is one-dimensional (isotropic materials): bin by the view's zenith.
    key = _zenith_deg(g.to_camera)[:, None]
    return _bin(cap.turntable_angle_deg, g.to_source, g.to_camera, f, s, ok, key, bin_deg,
                min_pixels)


def _solar_view(cap: SampleCaptures, ref: ReferenceView, bin_deg: float, min_pixels: int):
    g = ref.geometry
    if g.to_sun is None:
        return _empty(), []
    m = g.mask
    meas = cap.solar_dc_dn[m]
    sem = cap.solar_dc_sem_dn[m]
    slope = ref.solar_slope_dn[m]
    ok = (cap.lamp.valid[m] & cap.solar.valid[m] & np.isfinite(meas) & (sem > 0.0)
          & (slope > MIN_SOLAR_SNR * sem) & _in_range(g.to_sun) & _in_range(g.to_camera)
          & (cap.solar.intensity[m] < SBI_MARGIN * ref.sbi_intensity_dn[m]))
    scale = ref.albedo / np.pi
    safe = np.where(ok, slope, 1.0)
    f = np.where(ok, meas / safe * scale, np.nan)
    s = np.where(ok, sem / safe * scale, np.nan)
    # The sun's direction is one per view; the camera's varies over the plate in two dimensions.
    key = np.degrees(g.to_camera[:, :2])
    return _bin(cap.turntable_angle_deg, g.to_sun, g.to_camera, f, s, ok, key, bin_deg,
                min_pixels, "solar")


def _bin(angle: float, to_light: np.ndarray, to_camera: np.ndarray, f: np.ndarray,
         s: np.ndarray, ok: np.ndarray, key_deg: np.ndarray, bin_deg: float, min_pixels: int,
         name: str = "retro"):
    """Average the usable pixels per bin of ``key_deg``; rows and each bin's spread/noise."""
    if not ok.any():
        return _empty(name), []
    cells = np.floor(key_deg[ok] / bin_deg).astype(np.int64)
    _, inverse, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    ti_px, tr_px, dp_px = angles_from_directions(to_light[ok], to_camera[ok])
    fv, sv, kv = f[ok], s[ok], key_deg[ok]
    rows: dict[str, list[float]] = {k: [] for k in ("ti", "tr", "dp", "f", "s", "n")}
    spreads = []
    for b in np.flatnonzero(counts >= min_pixels):
        sel = inverse == b
        n = int(sel.sum())
        # The pixels' mean angles, not the angles of their mean direction: a bin near the
        # normal is a ring about it, whose mean direction is the normal itself.
        rows["ti"].append(float(ti_px[sel].mean()))
        rows["tr"].append(float(tr_px[sel].mean()))
        rows["dp"].append(float(dp_px[sel].mean()))
        rows["f"].append(float(fv[sel].mean()))
        rows["s"].append(float(np.sqrt(np.sum(sv[sel] ** 2)) / n))
        rows["n"].append(n)
        spreads.append(_spread_over_noise(kv[sel], fv[sel], sv[sel]))
    n_rows = len(rows["f"])
    table = SliceRows(name, np.full(n_rows, float(angle)), *(np.asarray(rows[k]) for k in
                                                           ("ti", "tr", "dp", "f", "s")),
                      np.asarray(rows["n"], dtype=np.int64))
    return table, [v for v in spreads if np.isfinite(v)]


def _spread_over_noise(key: np.ndarray, f: np.ndarray, s: np.ndarray) -> float:
    """RMS of the residuals about a quadratic trend in ``key`` over the bin's pooled noise
    (NaN if too few pixels). The noise is pooled over the bin's pixels: a pixel's own standard
    error from a few frames is too uncertain to divide by."""
    k = key - key.mean(axis=0)
    cols = [np.ones(len(f))] + [k[:, i] for i in range(k.shape[1])]
    cols += [k[:, i] * k[:, j] for i in range(k.shape[1]) for j in range(i, k.shape[1])]
    a = np.column_stack(cols)
    if len(f) <= a.shape[1] + 1:
        return float("nan")
    coef, *_ = np.linalg.lstsq(a, f, rcond=None)
    r = f - a @ coef
    noise = float(np.sqrt(np.mean(s**2)))
    return float(np.sqrt(np.sum(r**2) / (len(f) - a.shape[1])) / noise)


def _range_offsets(cap: SampleCaptures, ref: ReferenceView) -> np.ndarray:
    """Measured minus the twin's range on the plate's valid pixels [m] (phase wrapped)."""
    m = ref.geometry.mask & cap.lamp.valid & np.isfinite(ref.range_m)
    if not m.any():
        return np.zeros(0)
    f0 = float(cap.lamp.frequencies_hz[0])
    unambiguous = SPEED_OF_LIGHT_M_S / (2.0 * f0)
    measured = cap.lamp.phase_rad[0][m] * SPEED_OF_LIGHT_M_S / (4.0 * np.pi * f0)
    d = measured - ref.range_m[m]
    return d - unambiguous * np.round(d / unambiguous)


def _in_range(w: np.ndarray) -> np.ndarray:
    return _zenith_deg(w) < MAX_ZENITH_DEG


def _zenith_deg(w: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(w[:, 2], -1.0, 1.0)))


def _empty(name: str = "retro") -> SliceRows:
    z = np.zeros(0)
    return SliceRows(name, z, z, z, z, z, z, np.zeros(0, dtype=np.int64))


def _stack(name: str, parts: list[SliceRows]) -> SliceRows:
    if not parts:
        return _empty(name)
    return SliceRows(name, *(np.concatenate([getattr(p, k) for p in parts]) for k in
                             ("turntable_angle_deg", "incidence_zenith_deg",
                              "reflection_zenith_deg", "azimuth_difference_deg", "brdf_per_sr",
                              "brdf_std_per_sr", "n_pixels")))
